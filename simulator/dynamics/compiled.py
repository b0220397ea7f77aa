"""The plant's RK4 step compiled with numba (``cache=True``): what :class:`~.plant.Plant` runs per
physics step when numba is installed (the ``campaign`` extra), and what the Monte Carlo batch
engine (:mod:`sitl.campaign.kernels`) flies.

Why: the plant is the largest single cost of a lockstep frame in Python (two RK4 steps of four
derivative evaluations each, ~14 us per step); compiled, a step with the copies in and out costs
~2 us (measured: ``benchmarks/inprocess.py``). Without numba :class:`~.plant.Plant` integrates
in Python, the specification: every expression here is written in the same order of
floating-point operations, so the two agree bit for bit (``tests/simulator/test_compiled_plant.py``
proves it step by step; the campaign's agreement tests over whole flights).

Layout constants: where each number sits in the flat float64 arrays (numba wants arrays): ``P``
the plant's parameters (:func:`plant_array`), ``u`` the inputs held over a step. They live in this
file, next to the functions, because numba's cache is keyed on the file of the function: a changed
index here invalidates these kernels. (:mod:`sitl.campaign.kernels` calls into this file and clears
its own cache when this file changes, see there.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# -- plant (the true vehicle; read off a simulator.dynamics.plant.Plant instance) ------------------
P_MASS = 0
P_GRAVITY = 1
P_J = 2  # 9 entries, inertia tensor about G, row-major
P_K = 11  # 9 entries, its inverse (Plant.inertia_inv)
P_COM = 20  # 3: r_G, CoM from O in the body frame
P_DRAG = 23  # 3: linear drag per world axis
P_B = 26  # thrust coefficient b
P_D = 27  # reaction-torque coefficient d
P_ARM = 28
P_JR = 29  # rotor inertia
P_TAU = 30  # rotor time constant
P_WMIN = 31  # rotor speed limits
P_WMAX = 32
P_THRUST_MAX = 33
P_TORQUE_MAX = 34  # 3
P_ROTOR_MODE = 37  # 1.0 when actuation = "rotors"
P_GROUND = 38  # 1.0 when ground contact is on
P_HAS_DRAG = 39
P_SIZE = 40

# Held plant inputs (zero-order hold over a physics step).
U_THRUST = 0  # wrench: U1 (already saturated by the plant's set_wrench)
U_TAU = 1  # 3: body torque
U_ROTOR = 4  # 4: rotor speed commands (clipped)
U_FORCE = 8  # 3: disturbance force, world
U_TORQUE = 11  # 3: disturbance torque on the Euler coordinates (eq. 4)
U_WIND = 14  # 3
U_SIZE = 17
# CompiledStep.step fills u with one tuple in this order.
assert (U_THRUST, U_TAU, U_ROTOR, U_FORCE, U_TORQUE, U_WIND, U_SIZE) == (0, 1, 4, 8, 11, 14, 17)


@njit(cache=True, error_model="numpy")
def _max(a: float, b: float) -> float:
    """Python's ``max(a, b)``."""
    return b if b > a else a


@njit(cache=True, error_model="numpy")
def _min(a: float, b: float) -> float:
    """Python's ``min(a, b)``."""
    return b if b < a else a


@njit(cache=True, error_model="numpy")
def rotation_from_quaternion(w: float, x: float, y: float, z: float) -> tuple[float, ...]:
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),
        2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),
        2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy),
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def euler_from_rotation(
    R00: float, R10: float, R20: float, R21: float, R22: float
) -> tuple[float, float, float]:
    """ZYX Euler angles; theta in [-pi/2, pi/2] (eq. 2's R)."""
    sin_theta = -R20
    sin_theta = 1.0 if sin_theta > 1.0 else (-1.0 if sin_theta < -1.0 else sin_theta)
    return (math.atan2(R21, R22), math.asin(sin_theta), math.atan2(R10, R00))


@njit(cache=True, error_model="numpy")
def quaternion_from_euler(phi: float, theta: float, psi: float) -> tuple[float, float, float, float]:
    cf, sf = math.cos(0.5 * phi), math.sin(0.5 * phi)
    ct, st = math.cos(0.5 * theta), math.sin(0.5 * theta)
    cp, sp = math.cos(0.5 * psi), math.sin(0.5 * psi)
    w = cf * ct * cp + sf * st * sp
    x = sf * ct * cp - cf * st * sp
    y = cf * st * cp + sf * ct * sp
    z = cf * ct * sp - sf * st * cp
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    return (w, x, y, z)


@njit(cache=True, error_model="numpy")
def derivative(s: np.ndarray, out: np.ndarray, P: np.ndarray, u: np.ndarray) -> None:
    """``state_dot`` of the coupled plant: Newton-Euler about G, thrust and torques at O."""
    vx, vy, vz = s[3], s[4], s[5]
    qw, qx, qy, qz = s[6], s[7], s[8], s[9]
    p, q, r = s[10], s[11], s[12]
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = rotation_from_quaternion(qw, qx, qy, qz)
    rotor_mode = P[P_ROTOR_MODE] != 0.0
    dw1 = dw2 = dw3 = dw4 = 0.0
    if rotor_mode:
        b, d, arm, Jr, tau_r = P[P_B], P[P_D], P[P_ARM], P[P_JR], P[P_TAU]
        w1, w2, w3, w4 = s[13], s[14], s[15], s[16]
        c1, c2, c3, c4 = u[U_ROTOR], u[U_ROTOR + 1], u[U_ROTOR + 2], u[U_ROTOR + 3]
        dw1, dw2 = (c1 - w1) / tau_r, (c2 - w2) / tau_r
        dw3, dw4 = (c3 - w3) / tau_r, (c4 - w4) / tau_r
        s1, s2, s3, s4 = w1 * w1, w2 * w2, w3 * w3, w4 * w4
        thrust = b * (s1 + s2 + s3 + s4)
        omega_r = -w1 + w2 - w3 + w4
        tx = arm * b * (s4 - s2) + Jr * omega_r * q
        ty = arm * b * (s3 - s1) - Jr * omega_r * p
        tz = d * (-s1 + s2 - s3 + s4) + Jr * (-dw1 + dw2 - dw3 + dw4)
    else:
        thrust = u[U_THRUST]
        tx, ty, tz = u[U_TAU], u[U_TAU + 1], u[U_TAU + 2]

    rx, ry, rz = P[P_COM], P[P_COM + 1], P[P_COM + 2]
    tx -= ry * thrust
    ty += rx * thrust

    ap, aq, ar = u[U_TORQUE], u[U_TORQUE + 1], u[U_TORQUE + 2]
    if ap != 0.0 or aq != 0.0 or ar != 0.0:
        st = -R20
        ct = math.sqrt(_max(1.0 - st * st, 1e-12))
        sf, cf = R21 / ct, R22 / ct
        rhs = (ar + st * ap) / ct
        tx += ap
        ty += cf * aq + sf * rhs
        tz += -sf * aq + cf * rhs

    J00, J01, J02, J10, J11, J12, J20, J21, J22 = (
        P[P_J], P[P_J + 1], P[P_J + 2], P[P_J + 3], P[P_J + 4], P[P_J + 5], P[P_J + 6], P[P_J + 7], P[P_J + 8]
    )  # fmt: skip
    hx = J00 * p + J01 * q + J02 * r
    hy = J10 * p + J11 * q + J12 * r
    hz = J20 * p + J21 * q + J22 * r
    ex = tx - (q * hz - r * hy)
    ey = ty - (r * hx - p * hz)
    ez = tz - (p * hy - q * hx)
    K00, K01, K02, K10, K11, K12, K20, K21, K22 = (
        P[P_K], P[P_K + 1], P[P_K + 2], P[P_K + 3], P[P_K + 4], P[P_K + 5], P[P_K + 6], P[P_K + 7], P[P_K + 8]
    )  # fmt: skip
    dp = K00 * ex + K01 * ey + K02 * ez
    dq = K10 * ex + K11 * ey + K12 * ez
    dr = K20 * ex + K21 * ey + K22 * ez

    fx, fy, fz = u[U_FORCE], u[U_FORCE + 1], u[U_FORCE + 2]
    fx += R02 * thrust
    fy += R12 * thrust
    fz += R22 * thrust
    if P[P_HAS_DRAG] != 0.0:
        kdx, kdy, kdz = P[P_DRAG], P[P_DRAG + 1], P[P_DRAG + 2]
        cx, cy, cz = q * rz - r * ry, r * rx - p * rz, p * ry - q * rx
        wnx, wny, wnz = u[U_WIND], u[U_WIND + 1], u[U_WIND + 2]
        fx -= kdx * (vx - (R00 * cx + R01 * cy + R02 * cz) - wnx)
        fy -= kdy * (vy - (R10 * cx + R11 * cy + R12 * cz) - wny)
        fz -= kdz * (vz - (R20 * cx + R21 * cy + R22 * cz) - wnz)
    m, g = P[P_MASS], P[P_GRAVITY]
    out[0], out[1], out[2] = vx, vy, vz
    out[3], out[4], out[5] = fx / m, fy / m, fz / m - g
    out[6] = -0.5 * (qx * p + qy * q + qz * r)
    out[7] = 0.5 * (qw * p + qy * r - qz * q)
    out[8] = 0.5 * (qw * q + qz * p - qx * r)
    out[9] = 0.5 * (qw * r + qx * q - qy * p)
    out[10], out[11], out[12] = dp, dq, dr
    if rotor_mode:
        out[13], out[14], out[15], out[16] = dw1, dw2, dw3, dw4


@njit(cache=True, error_model="numpy")
def rk4_step(
    s: np.ndarray,
    k1: np.ndarray,
    k2: np.ndarray,
    k3: np.ndarray,
    k4: np.ndarray,
    tmp: np.ndarray,
    P: np.ndarray,
    u: np.ndarray,
    h: float,
) -> None:
    """One classical RK4 step with the inputs held, then the quaternion renormalised."""
    n = s.shape[0]
    h2 = 0.5 * h
    derivative(s, k1, P, u)
    for i in range(n):
        tmp[i] = s[i] + h2 * k1[i]
    derivative(tmp, k2, P, u)
    for i in range(n):
        tmp[i] = s[i] + h2 * k2[i]
    derivative(tmp, k3, P, u)
    for i in range(n):
        tmp[i] = s[i] + h * k3[i]
    derivative(tmp, k4, P, u)
    h6 = h / 6.0
    for i in range(n):
        s[i] = s[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
    qw, qx, qy, qz = s[6], s[7], s[8], s[9]
    nq = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    s[6], s[7], s[8], s[9] = qw * nq, qx * nq, qy * nq, qz * nq


@njit(cache=True, error_model="numpy")
def ground_contact(s: np.ndarray, P: np.ndarray) -> bool:
    """Keep O on or above z = 0 (``Plant._resolve_ground_contact``); True when it acted."""
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = rotation_from_quaternion(s[6], s[7], s[8], s[9])
    rx, ry, rz = P[P_COM], P[P_COM + 1], P[P_COM + 2]
    z_O = s[2] - (R20 * rx + R21 * ry + R22 * rz)
    if z_O > 0.0:
        return False
    p, q, r = s[10], s[11], s[12]
    cx, cy, cz = q * rz - r * ry, r * rx - p * rz, p * ry - q * rx
    vz_O = s[5] - (R20 * cx + R21 * cy + R22 * cz)
    if vz_O > 0.0:
        return False
    psi = math.atan2(R10, R00)
    qw, qx, qy, qz = quaternion_from_euler(0.0, 0.0, psi)
    L00, L01, L02, L10, L11, L12, L20, L21, L22 = rotation_from_quaternion(qw, qx, qy, qz)
    x_O = s[0] - (R00 * rx + R01 * ry + R02 * rz)
    y_O = s[1] - (R10 * rx + R11 * ry + R12 * rz)
    s[0] = x_O + L00 * rx + L01 * ry + L02 * rz
    s[1] = y_O + L10 * rx + L11 * ry + L12 * rz
    s[2] = L20 * rx + L21 * ry + L22 * rz
    s[3], s[4], s[5] = 0.0, 0.0, 0.0
    s[6], s[7], s[8], s[9] = qw, qx, qy, qz
    s[10], s[11], s[12] = 0.0, 0.0, 0.0
    return True


@njit(cache=True, error_model="numpy")
def truth_of_O(s: np.ndarray, P: np.ndarray) -> tuple:
    """Position and velocity of O, quaternion, body rates (``Plant.kinematics`` / ``truth``)."""
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = rotation_from_quaternion(s[6], s[7], s[8], s[9])
    rx, ry, rz = P[P_COM], P[P_COM + 1], P[P_COM + 2]
    p, q, r = s[10], s[11], s[12]
    cx, cy, cz = q * rz - r * ry, r * rx - p * rz, p * ry - q * rx
    pos = (
        s[0] - (R00 * rx + R01 * ry + R02 * rz),
        s[1] - (R10 * rx + R11 * ry + R12 * rz),
        s[2] - (R20 * rx + R21 * ry + R22 * rz),
    )
    vel = (
        s[3] - (R00 * cx + R01 * cy + R02 * cz),
        s[4] - (R10 * cx + R11 * cy + R12 * cz),
        s[5] - (R20 * cx + R21 * cy + R22 * cz),
    )
    euler = euler_from_rotation(R00, R10, R20, R21, R22)
    return pos, vel, euler, R22


@njit(cache=True, error_model="numpy")
def truth_kernel(s: np.ndarray, ds: np.ndarray, P: np.ndarray, u: np.ndarray) -> tuple:
    """``Plant.truth``'s kinematics of O, its operations in the same order: position, velocity,
    acceleration (world), ZYX Euler angles, their rates, the specific force (body), on-ground
    flag (1.0 / 0.0); one derivative evaluation with the inputs ``u`` held (``ds`` its scratch)."""
    derivative(s, ds, P, u)
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = rotation_from_quaternion(s[6], s[7], s[8], s[9])
    rx, ry, rz = P[P_COM], P[P_COM + 1], P[P_COM + 2]
    p, qr, r = s[10], s[11], s[12]
    dp, dq, dr = ds[10], ds[11], ds[12]
    cx, cy, cz = qr * rz - r * ry, r * rx - p * rz, p * ry - qr * rx
    ax_ = dq * rz - dr * ry + (qr * cz - r * cy)
    ay_ = dr * rx - dp * rz + (r * cx - p * cz)
    az_ = dp * ry - dq * rx + (p * cy - qr * cx)
    px = s[0] - (R00 * rx + R01 * ry + R02 * rz)
    py = s[1] - (R10 * rx + R11 * ry + R12 * rz)
    pz = s[2] - (R20 * rx + R21 * ry + R22 * rz)
    vx = s[3] - (R00 * cx + R01 * cy + R02 * cz)
    vy = s[4] - (R10 * cx + R11 * cy + R12 * cz)
    vz = s[5] - (R20 * cx + R21 * cy + R22 * cz)
    on_ground = P[P_GROUND] == 1.0 and pz <= 1e-6 and abs(s[5]) < 1e-6
    if on_ground:
        accx, accy, accz = 0.0, 0.0, 0.0
    else:
        accx = ds[3] - (R00 * ax_ + R01 * ay_ + R02 * az_)
        accy = ds[4] - (R10 * ax_ + R11 * ay_ + R12 * az_)
        accz = ds[5] - (R20 * ax_ + R21 * ay_ + R22 * az_)
    fx, fy, fz = accx, accy, accz + P[P_GRAVITY]
    phi, theta, psi = euler_from_rotation(R00, R10, R20, R21, R22)
    sf, cf = math.sin(phi), math.cos(phi)
    ct, tt = math.cos(theta), math.tan(theta)
    return (
        (px, py, pz), (vx, vy, vz), (accx, accy, accz), (phi, theta, psi),
        (p + sf * tt * qr + cf * tt * r, cf * qr - sf * r, (sf * qr + cf * r) / ct),
        (R00 * fx + R10 * fy + R20 * fz, R01 * fx + R11 * fy + R21 * fz, R02 * fx + R12 * fy + R22 * fz),
        on_ground,
    )  # fmt: skip


@njit(cache=True, error_model="numpy")
def advance_kernel(work: np.ndarray, P: np.ndarray, U: np.ndarray, h: float, reach: float) -> tuple:
    """``Plant.advance``: one RK4 step per row of ``U`` (the inputs held over that step), the
    ground contact resolved after each as ``Plant.step`` does, then the truth read-out at the end
    (:func:`truth_kernel`, inputs of the last step held): a lockstep frame's plant in one call.
    ``work``'s rows: the state (in and out), then the RK4 scratch k1..k4 and tmp (one array: each
    array argument costs its own unboxing per call)."""
    s, k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4], work[5]
    ground = P[P_GROUND] != 0.0
    for j in range(U.shape[0]):
        rk4_step(s, k1, k2, k3, k4, tmp, P, U[j], h)
        if ground and s[2] < reach:  # O may be at the ground only then
            ground_contact(s, P)
    return truth_kernel(s, k1, P, U[U.shape[0] - 1])


def plant_array(plant) -> np.ndarray:
    """The parameter array ``P`` of a :class:`~.plant.Plant` (the true vehicle)."""
    P = np.zeros(P_SIZE)
    P[P_MASS] = plant.mass
    P[P_GRAVITY] = plant.gravity
    P[P_J : P_J + 9] = np.array(plant.inertia, dtype=float).ravel()
    P[P_K : P_K + 9] = np.array(plant.inertia_inv, dtype=float).ravel()
    P[P_COM : P_COM + 3] = plant.com_offset
    P[P_DRAG : P_DRAG + 3] = plant.drag
    P[P_B], P[P_D], P[P_ARM] = plant.b, plant.d, plant.arm
    P[P_JR], P[P_TAU] = plant.rotor_inertia, plant.rotor_tau
    P[P_WMIN], P[P_WMAX] = plant.speed_min, plant.speed_max
    P[P_THRUST_MAX] = plant.thrust_max
    P[P_TORQUE_MAX : P_TORQUE_MAX + 3] = plant.torque_max
    P[P_ROTOR_MODE] = 1.0 if plant.rotor_mode else 0.0
    P[P_GROUND] = 1.0 if plant.ground_contact else 0.0
    P[P_HAS_DRAG] = 1.0 if tuple(plant.drag) != (0.0, 0.0, 0.0) else 0.0
    return P


class CompiledStep:
    """One plant's buffers for :func:`rk4_step` (allocated once): :meth:`step` takes the plant's
    state list and held inputs, steps, and writes the state list back (``Plant.step``'s contract)."""

    def __init__(self, plant) -> None:
        n = len(plant.state)
        self.P = plant_array(plant)
        self.s = np.zeros(n)
        self.k1, self.k2, self.k3, self.k4, self.tmp = (np.zeros(n) for _ in range(5))
        self.u = np.zeros(U_SIZE)
        self.reach = plant._ground_reach
        # Load (or compile) the kernels now, on scratch buffers: their first call costs ~1 s (more
        # when compiling), which in the middle of lockstep the autopilot would see as a simulator
        # stall (COM_SIM_LOSS_T), and ground_contact is first called at touchdown.
        scratch = np.array(plant.state, dtype=float)
        rk4_step(scratch, self.k1, self.k2, self.k3, self.k4, self.tmp, self.P, self.u, plant.dt)
        ground_contact(scratch, self.P)
        self._rows = np.zeros((1, U_SIZE))
        self._rows_flat = self._rows.reshape(-1)
        self._work = np.zeros((6, n))  # advance_kernel's state and scratch
        self._work[0] = scratch
        advance_kernel(self._work, self.P, self._rows, plant.dt, self.reach)

    def step(self, plant) -> None:
        s = self.s
        s[:] = plant.state
        # The held inputs in one conversion (five slice assignments cost ~2 us), in the U_* order.
        if plant.rotor_mode:
            self.u[:] = (0.0, 0.0, 0.0, 0.0, *plant.rotor_cmd, *plant.force_dist, *plant.torque_dist_eta,
                         *plant.wind)  # fmt: skip
        else:
            self.u[:] = (plant.thrust_cmd, *plant.torque_cmd, 0.0, 0.0, 0.0, 0.0, *plant.force_dist,
                         *plant.torque_dist_eta, *plant.wind)  # fmt: skip
        rk4_step(s, self.k1, self.k2, self.k3, self.k4, self.tmp, self.P, self.u, plant.dt)
        if plant.ground_contact and s[2] < self.reach:  # O may be at the ground only then
            ground_contact(s, self.P)
        plant.state = s.tolist()

    def advance(self, plant, disturbances) -> tuple:
        """``Plant.advance``: the steps and the truth read-out in one :func:`advance_kernel` call
        (the state and all held inputs in one conversion each); the state list written back."""
        s = self._work[0]
        s[:] = plant.state
        if plant.rotor_mode:
            held = (0.0, 0.0, 0.0, 0.0, *plant.rotor_cmd)
        else:
            held = (plant.thrust_cmd, *plant.torque_cmd, 0.0, 0.0, 0.0, 0.0)
        flat: list[float] = []
        for force, torque, wind in disturbances:
            flat += (*held, *force, *torque, *wind)
        if self._rows.shape[0] != len(disturbances):
            self._rows = np.zeros((len(disturbances), U_SIZE))
            self._rows_flat = self._rows.reshape(-1)  # a view: filled in one conversion
        self._rows_flat[:] = flat
        truth = advance_kernel(self._work, self.P, self._rows, plant.dt, self.reach)
        plant.state = s.tolist()
        return truth
