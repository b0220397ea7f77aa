"""The coupled plant's equations (CONTROL.md, "the more accurate plant"), written once as kernels.

Every function here is a kernel (:mod:`quadcommon.kernel`): :class:`~.plant.Plant` calls them
through compiled entries when numba is there and as plain Python otherwise (``QUADSITL_PURE_PYTHON=1``),
and the campaign's batch engine compiles them into its flights: one source for all three.

The state ``s`` (13 floats, 17 with rotors): position and velocity of the centre of mass G
(world), the attitude quaternion ``(w, x, y, z)`` (body to world), the body rates ``(p, q, r)``,
then the four rotor speeds. Newton-Euler is written about G, where it is exact and decoupled; the
coupling enters where thrust and control torques act, at the geometric centre O (``r_G`` from O
to G, body frame), and where O's motion is read out: ``p_O = p_G - R r_G``,
``v_O = v_G - R (omega x r_G)``.

Numbers sit in flat float vectors (what numba takes): ``P`` the plant's parameters (layout
``P_*``, :meth:`~.plant.Plant.parameters`), ``u`` the inputs held over one physics step (layout
``U_*``); a frame's steps take their inputs as consecutive ``U_SIZE`` blocks of one vector.
``work`` holds the state (row 0) and the RK4 scratch (rows 1-5).

Actuator faults live in ``P`` too (a flight's own copy): per rotor its effectiveness (thrust and
reaction torque scaled), and what its speed does (``P_FAULT_MODE``: follows the command, stuck at
the speed it had, or off: the motor unpowered, the rotor spinning down with its time constant).
:func:`set_rotor_fault` sets them, at a command (the simulator's failure injection) or at a time
(:func:`rotor_faults_due` over a table of rows ``RF_*`` sorted by onset: a scenario's or a
campaign run's faults). On the ideal-wrench vehicle a rotor fails through the allocation's
equation (:mod:`quadcommon.rotor_geometry`): the commanded wrench is split into the rotors' shares,
the faults act on the shares, and the shares make the applied wrench (:func:`faulted_wrench`).
"""

from __future__ import annotations

import math

from quadcommon.kernel import borrowed, kernel
from quadcommon.rigid_body import (
    body_torque_from_euler_torque_sincos,
    cross,
    euler_from_rotation,
    euler_rates_from_body_rates,
    matrix_times,
    quaternion_from_euler,
    quaternion_multiply,
    quaternion_normalised,
    rotation_from_quaternion,
    transpose_times,
)
from quadcommon.rotor_geometry import squared_speed_parts, wrench_from_squares

# -- parameters P (read off a simulator.dynamics.plant.Plant) -------------------------------------
P_MASS = 0
P_GRAVITY = 1
P_J = 2  # 9 entries, inertia tensor about G, row-major
P_K = 11  # 9 entries, its inverse
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
P_HAS_DRAG = 39  # 1.0 when any drag coefficient is non-zero
P_GROUND_REACH = 40  # |r_G| + 1 mm: with G higher than this above z = 0, O is in the air
P_EFFECTIVENESS = 41  # 4: each rotor's effectiveness in [0, 1] (1 healthy)
P_FAULT_MODE = 45  # 4: what each rotor's speed does (ROTOR_FOLLOWS, ROTOR_STUCK, ROTOR_OFF)
P_HELD_SHARE = 49  # 4: wrench vehicle: a stuck rotor's share of the wrench (Omega^2, rad^2/s^2)
P_FAULTED = 53  # 1.0 while any rotor is not healthy (the healthy path skips the fault terms)
P_SIZE = 54

# -- actuator faults ----------------------------------------------------------------------------
ROTOR_FOLLOWS = 0.0  # the rotor follows its command (healthy, or at a loss of effectiveness)
ROTOR_STUCK = 1.0  # its speed is held where it was (wrench vehicle: its share of the wrench)
ROTOR_OFF = 2.0  # the motor is unpowered: no thrust, no torque, the rotor spins down
# A row of a fault table: from ONSET (s) rotor ROTOR (0-3, the plant's numbering) has MODE and
# EFFECTIVENESS. Rows sorted by onset.
RF_ONSET, RF_ROTOR, RF_MODE, RF_EFFECTIVENESS = 0, 1, 2, 3
RF_SIZE = 4

# -- inputs u held over a physics step (zero-order hold) ------------------------------------------
U_THRUST = 0  # wrench: U1 (saturated by Plant.set_wrench)
U_TAU = 1  # 3: body torque about O
U_ROTOR = 4  # 4: rotor speed commands (clipped by Plant.set_rotor_commands)
U_FORCE = 8  # 3: disturbance force, world, at G
U_TORQUE = 11  # 3: disturbance torque on the Euler coordinates (eq. 4)
U_WIND = 14  # 3: wind, world
U_SIZE = 17

# Ground contact: O within this of z = 0, and G's vertical speed below it, is resting.
ON_GROUND_TOLERANCE = 1e-6


@kernel
def matrix_at(P, i: int) -> tuple:
    """The 3x3 matrix stored row-major at ``P[i]`` (the inertia tensor, its inverse)."""
    return ((P[i], P[i + 1], P[i + 2]), (P[i + 3], P[i + 4], P[i + 5]), (P[i + 6], P[i + 7], P[i + 8]))


@kernel
def com_offset(P) -> tuple:
    """``r_G``."""
    return (P[P_COM], P[P_COM + 1], P[P_COM + 2])


@kernel
def rotor_wrench(P, s) -> tuple:
    """``(thrust, torque about O)`` of the rotors at the speeds of ``s``, + configuration (1 front,
    2 right, 3 rear, 4 left; 1 and 3 counter-clockwise seen from above): thrust ``e b Omega^2``,
    reaction torque ``e d Omega^2`` each (:func:`~quadcommon.rotor_geometry.wrench_from_squares`),
    ``e`` the rotor's effectiveness (``P_EFFECTIVENESS``: 1 healthy, 0 a motor that is off)."""
    e = P_EFFECTIVENESS
    s1, s2 = P[e] * s[13] * s[13], P[e + 1] * s[14] * s[14]
    s3, s4 = P[e + 2] * s[15] * s[15], P[e + 3] * s[16] * s[16]
    thrust, tx, ty, tz = wrench_from_squares(P[P_B], P[P_D], P[P_ARM], s1, s2, s3, s4)
    return thrust, (tx, ty, tz)


@kernel
def rotor_acceleration(P, i: int, command: float, speed: float, tau: float) -> float:
    """``dOmega/dt`` of rotor ``i`` (0-3): first order towards its command, held when stuck,
    towards 0 when off."""
    mode = P[P_FAULT_MODE + i]
    if mode == ROTOR_STUCK:
        return 0.0
    if mode == ROTOR_OFF:
        return -speed / tau
    return (command - speed) / tau


@kernel
def faulted_share(P, i: int, share: float) -> float:
    """Rotor ``i``'s share of the wrench (Omega^2) with its fault: scaled by its effectiveness,
    held when stuck, none when off."""
    mode = P[P_FAULT_MODE + i]
    if mode == ROTOR_STUCK:
        return P[P_HELD_SHARE + i]
    if mode == ROTOR_OFF:
        return 0.0
    return P[P_EFFECTIVENESS + i] * share


@kernel
def faulted_wrench(P, thrust: float, tx: float, ty: float, tz: float) -> tuple:
    """The wrench vehicle's applied ``(U1, tau)`` with its rotors' faults: the command split into
    the four rotors' shares by the allocation's equation, each share as its rotor's fault leaves
    it (:func:`faulted_share`), summed back. The ideal actuator's rotors have no limits of their
    own: a share may be of either sign (the wrench's limits act on the command, before)."""
    b, d, arm = P[P_B], P[P_D], P[P_ARM]
    base, rp, yaw = squared_speed_parts(b, d, arm, thrust, tx, ty, tz)
    s1 = faulted_share(P, 0, base + rp[0] + yaw[0])
    s2 = faulted_share(P, 1, base + rp[1] + yaw[1])
    s3 = faulted_share(P, 2, base + rp[2] + yaw[2])
    s4 = faulted_share(P, 3, base + rp[3] + yaw[3])
    return wrench_from_squares(b, d, arm, s1, s2, s3, s4)


@kernel
def set_rotor_fault(P, rotor: int, mode: float, effectiveness: float, u) -> None:
    """From now on rotor ``rotor`` (0-3) has ``mode`` (``ROTOR_*``) and ``effectiveness``; a new
    fault replaces the rotor's last one (``ROTOR_FOLLOWS`` at 1 is healthy again). A rotor stuck
    on the wrench vehicle holds its share of the wrench held in ``u`` (the command in force)."""
    P[P_EFFECTIVENESS + rotor] = effectiveness
    P[P_FAULT_MODE + rotor] = mode
    if mode == ROTOR_STUCK and P[P_ROTOR_MODE] == 0.0:
        base, rp, yaw = squared_speed_parts(P[P_B], P[P_D], P[P_ARM], u[U_THRUST], u[U_TAU], u[U_TAU + 1],
                                            u[U_TAU + 2])  # fmt: skip
        P[P_HELD_SHARE + rotor] = base + rp[rotor] + yaw[rotor]
    faulted = 0.0
    for i in range(4):
        if P[P_EFFECTIVENESS + i] != 1.0 or P[P_FAULT_MODE + i] != ROTOR_FOLLOWS:
            faulted = 1.0
    P[P_FAULTED] = faulted


@kernel
def rotor_faults_due(P, faults, row: int, t: float, u) -> int:
    """The rows of the fault table ``faults`` (``RF_*``, sorted by onset) from ``row`` on whose
    onset is at or before ``t``, set (:func:`set_rotor_fault`); returns the next row to wait for."""
    while row < faults.shape[0] and faults[row, RF_ONSET] <= t:
        set_rotor_fault(P, int(faults[row, RF_ROTOR]), faults[row, RF_MODE], faults[row, RF_EFFECTIVENESS], u)
        row += 1
    return row


@kernel
def derivative(s, out, P, u) -> None:
    """``out = ds/dt`` with the inputs ``u`` held: Newton-Euler about G, thrust and control
    torques at O, rotor lag and gyroscopic terms, disturbances, drag."""
    v = (s[3], s[4], s[5])
    q = (s[6], s[7], s[8], s[9])
    w = (s[10], s[11], s[12])
    R = rotation_from_quaternion(s[6], s[7], s[8], s[9])
    r_G = com_offset(P)

    # Actuators: thrust along body z at O and the control torque (body).
    dw1 = dw2 = dw3 = dw4 = 0.0
    if P[P_ROTOR_MODE] != 0.0:
        # First-order speed dynamics towards the command; gyroscopic moment J_r Omega_r (q, -p, 0)
        # with Omega_r = -Omega1 + Omega2 - Omega3 + Omega4, and the reaction to rotor
        # acceleration J_r dOmega_r/dt about z.
        tau_r, Jr = P[P_TAU], P[P_JR]
        if P[P_FAULTED] == 0.0:
            dw1, dw2 = (u[U_ROTOR] - s[13]) / tau_r, (u[U_ROTOR + 1] - s[14]) / tau_r
            dw3, dw4 = (u[U_ROTOR + 2] - s[15]) / tau_r, (u[U_ROTOR + 3] - s[16]) / tau_r
        else:
            dw1 = rotor_acceleration(P, 0, u[U_ROTOR], s[13], tau_r)
            dw2 = rotor_acceleration(P, 1, u[U_ROTOR + 1], s[14], tau_r)
            dw3 = rotor_acceleration(P, 2, u[U_ROTOR + 2], s[15], tau_r)
            dw4 = rotor_acceleration(P, 3, u[U_ROTOR + 3], s[16], tau_r)
        thrust, (tx, ty, tz) = rotor_wrench(P, s)
        omega_r = -s[13] + s[14] - s[15] + s[16]
        tx += Jr * omega_r * w[1]
        ty -= Jr * omega_r * w[0]
        tz += Jr * (-dw1 + dw2 - dw3 + dw4)
    else:
        thrust = u[U_THRUST]
        tx, ty, tz = u[U_TAU], u[U_TAU + 1], u[U_TAU + 2]
        if P[P_FAULTED] != 0.0:
            thrust, tx, ty, tz = faulted_wrench(P, thrust, tx, ty, tz)

    # Moment of the thrust (applied at O) about G: (-r_G) x (0, 0, T).
    tx -= r_G[1] * thrust
    ty += r_G[0] * thrust

    # Torque disturbance on the Euler coordinates -> body couple W_eta^-T tau_eta (eq. 4), with
    # the sines and cosines of phi and theta read off R.
    tau_eta = (u[U_TORQUE], u[U_TORQUE + 1], u[U_TORQUE + 2])
    if tau_eta[0] != 0.0 or tau_eta[1] != 0.0 or tau_eta[2] != 0.0:
        st = -R[2][0]
        ct = math.sqrt(max(1.0 - st * st, 1e-12))
        dx, dy, dz = body_torque_from_euler_torque_sincos(R[2][1] / ct, R[2][2] / ct, st, ct, tau_eta)
        tx += dx
        ty += dy
        tz += dz

    # Euler's equation about G: J w_dot = tau - w x J w.
    gyro = cross(w, matrix_times(matrix_at(P, P_J), w))
    dw = matrix_times(matrix_at(P, P_K), (tx - gyro[0], ty - gyro[1], tz - gyro[2]))

    # Newton's equation for G (world frame): thrust, the disturbance force, drag on O's
    # air-relative velocity v_G - R (w x r_G) - wind.
    fx = u[U_FORCE] + R[0][2] * thrust
    fy = u[U_FORCE + 1] + R[1][2] * thrust
    fz = u[U_FORCE + 2] + R[2][2] * thrust
    if P[P_HAS_DRAG] != 0.0:
        Rc = matrix_times(R, cross(w, r_G))
        fx -= P[P_DRAG] * (v[0] - Rc[0] - u[U_WIND])
        fy -= P[P_DRAG + 1] * (v[1] - Rc[1] - u[U_WIND + 1])
        fz -= P[P_DRAG + 2] * (v[2] - Rc[2] - u[U_WIND + 2])
    m = P[P_MASS]

    # Attitude kinematics q_dot = 1/2 q (x) (0, w).
    dq = quaternion_multiply(q, (0.0, w[0], w[1], w[2]))
    out[0], out[1], out[2] = v[0], v[1], v[2]
    out[3], out[4], out[5] = fx / m, fy / m, fz / m - P[P_GRAVITY]
    out[6], out[7], out[8], out[9] = 0.5 * dq[0], 0.5 * dq[1], 0.5 * dq[2], 0.5 * dq[3]
    out[10], out[11], out[12] = dw[0], dw[1], dw[2]
    if P[P_ROTOR_MODE] != 0.0:
        out[13], out[14], out[15], out[16] = dw1, dw2, dw3, dw4


@kernel
def rk4_step(s, k1, k2, k3, k4, tmp, P, u, h: float) -> None:
    """One classical RK4 step of ``s`` (in place) with the inputs ``u`` held, then the quaternion
    put back on the unit sphere (RK4 drifts off it by O(h^5) per step)."""
    n = len(s)
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
    s[6], s[7], s[8], s[9] = quaternion_normalised((s[6], s[7], s[8], s[9]))


@kernel
def motion_of_O(s, P) -> tuple:
    """``(R, p_O, v_O)``: the rotation, and the position and velocity of O (world)."""
    R = rotation_from_quaternion(s[6], s[7], s[8], s[9])
    r_G = com_offset(P)
    Rr = matrix_times(R, r_G)
    Rc = matrix_times(R, cross((s[10], s[11], s[12]), r_G))
    return R, (s[0] - Rr[0], s[1] - Rr[1], s[2] - Rr[2]), (s[3] - Rc[0], s[4] - Rc[1], s[5] - Rc[2])


@kernel
def ground_contact(s, P) -> bool:
    """The plane z = 0 under O: a vehicle at or below it and moving down is put to rest on it,
    level at its heading (in place). True when it acted."""
    R, p_O, v_O = motion_of_O(s, P)
    if p_O[2] > 0.0 or v_O[2] > 0.0:
        return False
    level = quaternion_from_euler(0.0, 0.0, math.atan2(R[1][0], R[0][0]))
    Rr = matrix_times(rotation_from_quaternion(level[0], level[1], level[2], level[3]), com_offset(P))
    s[0], s[1], s[2] = p_O[0] + Rr[0], p_O[1] + Rr[1], Rr[2]
    s[3], s[4], s[5] = 0.0, 0.0, 0.0
    s[6], s[7], s[8], s[9] = level[0], level[1], level[2], level[3]
    s[10], s[11], s[12] = 0.0, 0.0, 0.0
    return True


@kernel
def on_ground(s, P) -> bool:
    """Resting on the ground: contact on, O at z = 0 and G not moving vertically."""
    _, p_O, _ = motion_of_O(s, P)
    return P[P_GROUND] != 0.0 and p_O[2] <= ON_GROUND_TOLERANCE and abs(s[5]) < ON_GROUND_TOLERANCE


@kernel
def physics_steps(work, P, inputs, h: float) -> None:
    """One RK4 step of ``h`` of ``work[0]`` per ``U_SIZE`` block of ``inputs`` (held over that
    step), the ground contact resolved after each."""
    work, P, inputs = borrowed(work), borrowed(P), borrowed(inputs)  # the caller's: no counting per call
    s = work[0]
    for j in range(len(inputs) // U_SIZE):
        rk4_step(s, work[1], work[2], work[3], work[4], work[5], P, inputs[j * U_SIZE : (j + 1) * U_SIZE], h)
        if P[P_GROUND] != 0.0 and s[2] < P[P_GROUND_REACH]:  # O may be at the ground only then
            ground_contact(s, P)


@kernel
def truth(work, P, u) -> tuple:
    """The ground truth of ``work[0]`` with the inputs ``u`` held, in the fields' order of
    :class:`~.plant.TruthState`: O's position, velocity and acceleration, quaternion, Euler angles,
    body rates, Euler rates, specific force at O (body), rotor speeds, applied thrust and control
    torque about O, on the ground. One derivative evaluation (into ``work[1]``) gives the
    accelerations."""
    work, P, u = borrowed(work), borrowed(P), borrowed(u)  # the caller's: no counting per call
    s, ds = work[0], work[1]
    derivative(s, ds, P, u)
    R, p_O, v_O = motion_of_O(s, P)
    r_G = com_offset(P)
    w = (s[10], s[11], s[12])
    grounded = on_ground(s, P)
    if grounded:
        a_O = (0.0, 0.0, 0.0)
    else:
        # a_O = a_G - R (w_dot x r_G + w x (w x r_G))
        a1 = cross((ds[10], ds[11], ds[12]), r_G)
        a2 = cross(w, cross(w, r_G))
        Ra = matrix_times(R, (a1[0] + a2[0], a1[1] + a2[1], a1[2] + a2[2]))
        a_O = (ds[3] - Ra[0], ds[4] - Ra[1], ds[5] - Ra[2])
    specific = transpose_times(R, (a_O[0], a_O[1], a_O[2] + P[P_GRAVITY]))
    euler = euler_from_rotation(R)
    euler_rates = euler_rates_from_body_rates(euler[0], euler[1], w)
    if P[P_ROTOR_MODE] != 0.0:
        speeds = (s[13], s[14], s[15], s[16])
        thrust, torque = rotor_wrench(P, s)
    else:
        speeds = (0.0, 0.0, 0.0, 0.0)
        thrust, torque = u[U_THRUST], (u[U_TAU], u[U_TAU + 1], u[U_TAU + 2])
        if P[P_FAULTED] != 0.0:
            thrust, tx, ty, tz = faulted_wrench(P, u[U_THRUST], u[U_TAU], u[U_TAU + 1], u[U_TAU + 2])
            torque = (tx, ty, tz)
    return (p_O, v_O, a_O, (s[6], s[7], s[8], s[9]), euler, w, euler_rates, specific, speeds, thrust, torque,
            grounded)  # fmt: skip


@kernel
def advance(work, P, inputs, h: float) -> tuple:
    """A lockstep frame's physics in one call: :func:`physics_steps`, then the :func:`truth` of the
    result with the last step's inputs held."""
    physics_steps(work, P, inputs, h)
    return truth(work, P, inputs[len(inputs) - U_SIZE :])
