"""The coupled plant's equations (CONTROL.md, "the more accurate plant"), written once as kernels.

Every function here is a kernel (:mod:`quadcommon.kernel`): :class:`~.plant.Plant` calls them
through compiled entries when numba is there and as plain Python otherwise (``QUADSITL_PURE_PYTHON=1``),
and the campaign's batch engine compiles them into its flights: one source for all three.

The state ``s`` (layout :data:`STATE`: 13 floats, 17 with rotors): position and velocity of the
centre of mass G (world), the attitude quaternion ``(w, x, y, z)`` (body to world), the body rates
``(p, q, r)``, then the four rotor speeds. Newton-Euler is written about G, where it is exact and
decoupled; the coupling enters where thrust and control torques act, at the geometric centre O (``r_G`` from O
to G, body frame), and where O's motion is read out: ``p_O = p_G - R r_G``,
``v_O = v_G - R (omega x r_G)``.

Numbers sit in flat float vectors (what numba takes): ``P`` the plant's parameters (layout
:data:`PLANT`, :meth:`~.plant.Plant.parameters`), ``u`` the inputs held over one physics step (layout
:data:`INPUTS`); a frame's steps take their inputs as consecutive ``INPUTS.size`` blocks of one vector.
``work`` holds the state (row 0) and the RK4 scratch (rows 1-5).

Actuator faults live in ``P`` too (a flight's own copy): per rotor its effectiveness (thrust and
reaction torque scaled), and what its speed does (``PLANT.fault_mode``: follows the command, stuck at
the speed it had, or off: the motor unpowered, the rotor spinning down with its time constant).
:func:`set_rotor_fault` sets them, at a command (the simulator's failure injection) or at a time
(:func:`rotor_faults_due` over a table of :data:`ROTOR_FAULT` rows sorted by onset: a scenario's or a
campaign run's faults). On the ideal-wrench vehicle a rotor fails through the allocation's
equation (:mod:`quadcommon.rotor_geometry`): the commanded wrench is split into the rotors' shares,
the faults act on the shares, and the shares make the applied wrench (:func:`faulted_wrench`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from quadcommon.kernel import borrowed, inlined_kernel, kernel
from quadcommon.layout import Field, layout, quaternion_at, set_quaternion_at, vector_at
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
PLANT = layout("PlantParameters", (
    Field("mass", unit="kg"),
    Field("gravity", unit="m/s^2"),
    Field("inertia", 9, unit="kg m^2", doc="inertia tensor about G, row-major"),
    Field("inertia_inverse", 9, unit="1/(kg m^2)", doc="its inverse, row-major"),
    Field("com", 3, unit="m", doc="r_G: the centre of mass from O, body frame"),
    Field("drag", 3, unit="N s/m", doc="linear drag per world axis"),
    Field("thrust_coefficient", unit="N s^2", doc="b"),
    Field("torque_coefficient", unit="N m s^2", doc="d: reaction torque"),
    Field("arm", unit="m"),
    Field("rotor_inertia", unit="kg m^2"),
    Field("rotor_time_constant", unit="s"),
    Field("rotor_speed_min", unit="rad/s"),
    Field("rotor_speed_max", unit="rad/s"),
    Field("thrust_max", unit="N"),
    Field("torque_max", 3, unit="N m"),
    Field("rotor_mode", doc="1.0 when actuation = 'rotors'"),
    Field("ground", doc="1.0 when ground contact is on"),
    Field("has_drag", doc="1.0 when any drag coefficient is non-zero"),
    Field("ground_reach", unit="m", doc="|r_G| + 1 mm: with G higher than this above z = 0, O is in the air"),
    Field("effectiveness", 4, doc="each rotor's effectiveness in [0, 1] (1 healthy)"),
    Field("fault_mode", 4, doc="what each rotor's speed does (ROTOR_FOLLOWS, ROTOR_STUCK, ROTOR_OFF)"),
    Field("held_share", 4, unit="rad^2/s^2", doc="wrench vehicle: a stuck rotor's share of the wrench"),
    Field("faulted", doc="1.0 while any rotor is not healthy (the healthy path skips the fault terms)"),
))  # fmt: skip

# -- actuator faults ----------------------------------------------------------------------------
ROTOR_FOLLOWS = 0.0  # the rotor follows its command (healthy, or at a loss of effectiveness)
ROTOR_STUCK = 1.0  # its speed is held where it was (wrench vehicle: its share of the wrench)
ROTOR_OFF = 2.0  # the motor is unpowered: no thrust, no torque, the rotor spins down
# A row of a fault table (rows sorted by onset).
ROTOR_FAULT = layout("RotorFault", (
    Field("onset", unit="s", doc="from this time on ..."),
    Field("rotor", doc="... rotor 0-3 (the plant's numbering) ..."),
    Field("mode", doc="... has this mode (ROTOR_*) ..."),
    Field("effectiveness", doc="... and this effectiveness in [0, 1]"),
))  # fmt: skip

# -- inputs u held over a physics step (zero-order hold) ------------------------------------------
INPUTS = layout("PlantInputs", (
    Field("thrust", unit="N", doc="wrench: U1 (saturated by Plant.set_wrench)"),
    Field("torque", 3, unit="N m", doc="body torque about O"),
    Field("rotor_commands", 4, unit="rad/s", doc="commanded (clipped by Plant.set_rotor_commands)"),
    Field("disturbance_force", 3, unit="N", doc="world, at G"),
    Field("disturbance_torque", 3, unit="N m", doc="on the Euler coordinates (eq. 4)"),
    Field("wind", 3, unit="m/s", doc="world"),
))  # fmt: skip

# -- the state s (row 0 of ``work``) ----------------------------------------------------------------
STATE = layout("PlantState", (
    Field("position", 3, unit="m", doc="of the centre of mass G, world"),
    Field("velocity", 3, unit="m/s", doc="of G, world"),
    Field("attitude", 4, doc="quaternion (w, x, y, z), body to world"),
    Field("body_rates", 3, unit="rad/s", doc="(p, q, r), body"),
    Field("rotor_speeds", 4, unit="rad/s", doc="with actuation = 'rotors' only: a wrench vehicle's "
          "state ends before them"),
))  # fmt: skip
WRENCH_STATE_SIZE = STATE.rotor_speeds  # the ideal-wrench vehicle's state: no rotor speeds


@kernel
def state_rotor_speeds(s) -> tuple:
    """The state's four rotor speeds (rad/s; a rotor vehicle's only)."""
    r = STATE.rotor_speeds
    return (s[r], s[r + 1], s[r + 2], s[r + 3])


class TruthState(NamedTuple):
    """Ground truth of the plant at one instant, in the paper's frames (SI units).

    Position, velocity and acceleration are those of the geometric centre O (where the vehicle's
    position is defined), in the world frame. ``specific_force_body`` is what an ideal
    accelerometer at O reads (body frame, m/s^2; +g upward at rest).

    (A NamedTuple, immutable: built once per frame, where a frozen dataclass's 12 fields cost
    1.4 us against 0.5 us.)
    """

    position_m: tuple[float, float, float]
    velocity_m_s: tuple[float, float, float]
    acceleration_m_s2: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]  # (w, x, y, z), body to world
    euler_rad: tuple[float, float, float]
    body_rates_rad_s: tuple[float, float, float]
    euler_rates_rad_s: tuple[float, float, float]
    specific_force_body_m_s2: tuple[float, float, float]
    rotor_speeds_rad_s: tuple[float, float, float, float]
    thrust_n: float  # applied (saturated) total thrust
    torque_body_n_m: tuple[float, float, float]  # applied (saturated) control torque about O, body frame
    on_ground: bool


# Ground contact: O within this of z = 0, and G's vertical speed below it, is resting.
ON_GROUND_TOLERANCE = 1e-6


@kernel
def matrix_at(P, i: int) -> tuple:
    """The 3x3 matrix stored row-major at ``P[i]`` (the inertia tensor, its inverse)."""
    return ((P[i], P[i + 1], P[i + 2]), (P[i + 3], P[i + 4], P[i + 5]), (P[i + 6], P[i + 7], P[i + 8]))


@kernel
def com_offset(P) -> tuple:
    """``r_G``."""
    return (P[PLANT.com], P[PLANT.com + 1], P[PLANT.com + 2])


@kernel
def rotor_wrench(P, s) -> tuple:
    """``(thrust, torque about O)`` of the rotors at the speeds of ``s``, + configuration (1 front,
    2 right, 3 rear, 4 left; 1 and 3 counter-clockwise seen from above): thrust ``e b Omega^2``,
    reaction torque ``e d Omega^2`` each (:func:`~quadcommon.rotor_geometry.wrench_from_squares`),
    ``e`` the rotor's effectiveness (``PLANT.effectiveness``: 1 healthy, 0 a motor that is off)."""
    e = PLANT.effectiveness
    w1, w2, w3, w4 = state_rotor_speeds(s)
    s1, s2 = P[e] * w1 * w1, P[e + 1] * w2 * w2
    s3, s4 = P[e + 2] * w3 * w3, P[e + 3] * w4 * w4
    b, d, arm = P[PLANT.thrust_coefficient], P[PLANT.torque_coefficient], P[PLANT.arm]
    thrust, tx, ty, tz = wrench_from_squares(b, d, arm, s1, s2, s3, s4)
    return thrust, (tx, ty, tz)


@kernel
def rotor_acceleration(P, i: int, command: float, speed: float, tau: float) -> float:
    """``dOmega/dt`` of rotor ``i`` (0-3): first order towards its command, held when stuck,
    towards 0 when off."""
    mode = P[PLANT.fault_mode + i]
    if mode == ROTOR_STUCK:
        return 0.0
    if mode == ROTOR_OFF:
        return -speed / tau
    return (command - speed) / tau


@kernel
def faulted_share(P, i: int, share: float) -> float:
    """Rotor ``i``'s share of the wrench (Omega^2) with its fault: scaled by its effectiveness,
    held when stuck, none when off."""
    mode = P[PLANT.fault_mode + i]
    if mode == ROTOR_STUCK:
        return P[PLANT.held_share + i]
    if mode == ROTOR_OFF:
        return 0.0
    return P[PLANT.effectiveness + i] * share


@kernel
def faulted_wrench(P, thrust: float, tx: float, ty: float, tz: float) -> tuple:
    """The wrench vehicle's applied ``(U1, tau)`` with its rotors' faults: the command split into
    the four rotors' shares by the allocation's equation, each share as its rotor's fault leaves
    it (:func:`faulted_share`), summed back. The ideal actuator's rotors have no limits of their
    own: a share may be of either sign (the wrench's limits act on the command, before)."""
    b, d, arm = P[PLANT.thrust_coefficient], P[PLANT.torque_coefficient], P[PLANT.arm]
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
    P[PLANT.effectiveness + rotor] = effectiveness
    P[PLANT.fault_mode + rotor] = mode
    if mode == ROTOR_STUCK and P[PLANT.rotor_mode] == 0.0:
        b, d, arm, tau = P[PLANT.thrust_coefficient], P[PLANT.torque_coefficient], P[PLANT.arm], INPUTS.torque
        base, rp, yaw = squared_speed_parts(b, d, arm, u[INPUTS.thrust], u[tau], u[tau + 1], u[tau + 2])
        P[PLANT.held_share + rotor] = base + rp[rotor] + yaw[rotor]
    faulted = 0.0
    for i in range(4):
        if P[PLANT.effectiveness + i] != 1.0 or P[PLANT.fault_mode + i] != ROTOR_FOLLOWS:
            faulted = 1.0
    P[PLANT.faulted] = faulted


@kernel
def rotor_faults_due(P, faults, row: int, t: float, u) -> int:
    """The rows of the fault table ``faults`` (:data:`ROTOR_FAULT`, sorted by onset) from ``row`` on whose
    onset is at or before ``t``, set (:func:`set_rotor_fault`); returns the next row to wait for."""
    while row < faults.shape[0] and faults[row, ROTOR_FAULT.onset] <= t:
        rotor, mode = int(faults[row, ROTOR_FAULT.rotor]), faults[row, ROTOR_FAULT.mode]
        set_rotor_fault(P, rotor, mode, faults[row, ROTOR_FAULT.effectiveness], u)
        row += 1
    return row


@kernel
def derivative(s, out, P, u) -> None:
    """``out = ds/dt`` with the inputs ``u`` held: Newton-Euler about G, thrust and control
    torques at O, rotor lag and gyroscopic terms, disturbances, drag."""
    v = vector_at(s, STATE.velocity)
    q = quaternion_at(s, STATE.attitude)
    w = vector_at(s, STATE.body_rates)
    R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    r_G = com_offset(P)

    # Actuators: thrust along body z at O and the control torque (body).
    dw1 = dw2 = dw3 = dw4 = 0.0
    if P[PLANT.rotor_mode] != 0.0:
        # First-order speed dynamics towards the command; gyroscopic moment J_r Omega_r (q, -p, 0)
        # with Omega_r = -Omega1 + Omega2 - Omega3 + Omega4, and the reaction to rotor
        # acceleration J_r dOmega_r/dt about z.
        tau_r, Jr = P[PLANT.rotor_time_constant], P[PLANT.rotor_inertia]
        o1, o2, o3, o4 = state_rotor_speeds(s)
        if P[PLANT.faulted] == 0.0:
            c = INPUTS.rotor_commands
            dw1, dw2 = (u[c] - o1) / tau_r, (u[c + 1] - o2) / tau_r
            dw3, dw4 = (u[c + 2] - o3) / tau_r, (u[c + 3] - o4) / tau_r
        else:
            dw1 = rotor_acceleration(P, 0, u[INPUTS.rotor_commands], o1, tau_r)
            dw2 = rotor_acceleration(P, 1, u[INPUTS.rotor_commands + 1], o2, tau_r)
            dw3 = rotor_acceleration(P, 2, u[INPUTS.rotor_commands + 2], o3, tau_r)
            dw4 = rotor_acceleration(P, 3, u[INPUTS.rotor_commands + 3], o4, tau_r)
        thrust, (tx, ty, tz) = rotor_wrench(P, s)
        omega_r = -o1 + o2 - o3 + o4
        tx += Jr * omega_r * w[1]
        ty -= Jr * omega_r * w[0]
        tz += Jr * (-dw1 + dw2 - dw3 + dw4)
    else:
        thrust = u[INPUTS.thrust]
        tx, ty, tz = u[INPUTS.torque], u[INPUTS.torque + 1], u[INPUTS.torque + 2]
        if P[PLANT.faulted] != 0.0:
            thrust, tx, ty, tz = faulted_wrench(P, thrust, tx, ty, tz)

    # Moment of the thrust (applied at O) about G: (-r_G) x (0, 0, T).
    tx -= r_G[1] * thrust
    ty += r_G[0] * thrust

    # Torque disturbance on the Euler coordinates -> body couple W_eta^-T tau_eta (eq. 4), with
    # the sines and cosines of phi and theta read off R.
    t = INPUTS.disturbance_torque
    tau_eta = (u[t], u[t + 1], u[t + 2])
    if tau_eta[0] != 0.0 or tau_eta[1] != 0.0 or tau_eta[2] != 0.0:
        st = -R[2][0]
        ct = math.sqrt(max(1.0 - st * st, 1e-12))
        dx, dy, dz = body_torque_from_euler_torque_sincos(R[2][1] / ct, R[2][2] / ct, st, ct, tau_eta)
        tx += dx
        ty += dy
        tz += dz

    # Euler's equation about G: J w_dot = tau - w x J w.
    gyro = cross(w, matrix_times(matrix_at(P, PLANT.inertia), w))
    dw = matrix_times(matrix_at(P, PLANT.inertia_inverse), (tx - gyro[0], ty - gyro[1], tz - gyro[2]))

    # Newton's equation for G (world frame): thrust, the disturbance force, drag on O's
    # air-relative velocity v_G - R (w x r_G) - wind.
    fx = u[INPUTS.disturbance_force] + R[0][2] * thrust
    fy = u[INPUTS.disturbance_force + 1] + R[1][2] * thrust
    fz = u[INPUTS.disturbance_force + 2] + R[2][2] * thrust
    if P[PLANT.has_drag] != 0.0:
        Rc = matrix_times(R, cross(w, r_G))
        fx -= P[PLANT.drag] * (v[0] - Rc[0] - u[INPUTS.wind])
        fy -= P[PLANT.drag + 1] * (v[1] - Rc[1] - u[INPUTS.wind + 1])
        fz -= P[PLANT.drag + 2] * (v[2] - Rc[2] - u[INPUTS.wind + 2])
    m = P[PLANT.mass]

    # Attitude kinematics q_dot = 1/2 q (x) (0, w).
    dq = quaternion_multiply(q, (0.0, w[0], w[1], w[2]))
    x, v_dot, a, w_dot = STATE.position, STATE.velocity, STATE.attitude, STATE.body_rates
    out[x], out[x + 1], out[x + 2] = v[0], v[1], v[2]
    out[v_dot], out[v_dot + 1], out[v_dot + 2] = fx / m, fy / m, fz / m - P[PLANT.gravity]
    out[a], out[a + 1], out[a + 2], out[a + 3] = 0.5 * dq[0], 0.5 * dq[1], 0.5 * dq[2], 0.5 * dq[3]
    out[w_dot], out[w_dot + 1], out[w_dot + 2] = dw[0], dw[1], dw[2]
    if P[PLANT.rotor_mode] != 0.0:
        r = STATE.rotor_speeds
        out[r], out[r + 1], out[r + 2], out[r + 3] = dw1, dw2, dw3, dw4


def rk4_of(derivative_of: Callable[..., None]) -> Callable[..., None]:
    """The one integrator: a kernel ``rk4(s, k1, k2, k3, k4, tmp, P, u, h)`` taking one classical
    RK4 step of ``h`` of ``s`` (in place) under ``ds/dt = derivative_of(s, out, P, u)`` (a kernel
    writing the derivative into ``out``) with the inputs ``u`` held; ``k1`` .. ``k4`` and ``tmp``
    are scratch of ``s``'s length. One per plant (this one's :data:`rk4_coupled`, the nominal
    model's in :mod:`.nominal_plant`), inlined where it is called (:func:`~quadcommon.kernel.inlined_kernel`:
    as a call of its own it costs ~15 % of a plant step, ``benchmarks/engine_choice.py``)."""

    def rk4(s, k1, k2, k3, k4, tmp, P, u, h: float) -> None:
        n = len(s)
        h2 = 0.5 * h
        derivative_of(s, k1, P, u)
        for i in range(n):
            tmp[i] = s[i] + h2 * k1[i]
        derivative_of(tmp, k2, P, u)
        for i in range(n):
            tmp[i] = s[i] + h2 * k2[i]
        derivative_of(tmp, k3, P, u)
        for i in range(n):
            tmp[i] = s[i] + h * k3[i]
        derivative_of(tmp, k4, P, u)
        h6 = h / 6.0
        for i in range(n):
            s[i] = s[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])

    rk4.__name__ = rk4.__qualname__ = f"rk4_of_{derivative_of.__name__}"
    rk4.__doc__ = f"One RK4 step under :func:`{derivative_of.__name__}` (:func:`rk4_of`)."
    return inlined_kernel(rk4)


rk4_coupled = rk4_of(derivative)


@kernel
def rk4_step(s, k1, k2, k3, k4, tmp, P, u, h: float) -> None:
    """One RK4 step of the coupled plant's :func:`derivative` (:data:`rk4_coupled`), then the
    quaternion put back on the unit sphere (RK4 drifts off it by O(h^5) per step)."""
    rk4_coupled(s, k1, k2, k3, k4, tmp, P, u, h)
    set_quaternion_at(s, STATE.attitude, quaternion_normalised(quaternion_at(s, STATE.attitude)))


@kernel
def motion_of_O(s, P) -> tuple:
    """``(R, p_O, v_O)``: the rotation, and the position and velocity of O (world)."""
    q = quaternion_at(s, STATE.attitude)
    R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    r_G = com_offset(P)
    Rr = matrix_times(R, r_G)
    Rc = matrix_times(R, cross(vector_at(s, STATE.body_rates), r_G))
    p_G, v_G = vector_at(s, STATE.position), vector_at(s, STATE.velocity)
    p_O = (p_G[0] - Rr[0], p_G[1] - Rr[1], p_G[2] - Rr[2])
    return R, p_O, (v_G[0] - Rc[0], v_G[1] - Rc[1], v_G[2] - Rc[2])


@kernel
def ground_contact(s, P) -> bool:
    """The plane z = 0 under O: a vehicle at or below it and moving down is put to rest on it,
    level at its heading (in place). True when it acted."""
    R, p_O, v_O = motion_of_O(s, P)
    if p_O[2] > 0.0 or v_O[2] > 0.0:
        return False
    level = quaternion_from_euler(0.0, 0.0, math.atan2(R[1][0], R[0][0]))
    Rr = matrix_times(rotation_from_quaternion(level[0], level[1], level[2], level[3]), com_offset(P))
    x, v, a, w = STATE.position, STATE.velocity, STATE.attitude, STATE.body_rates
    s[x], s[x + 1], s[x + 2] = p_O[0] + Rr[0], p_O[1] + Rr[1], Rr[2]
    s[v], s[v + 1], s[v + 2] = 0.0, 0.0, 0.0
    s[a], s[a + 1], s[a + 2], s[a + 3] = level[0], level[1], level[2], level[3]
    s[w], s[w + 1], s[w + 2] = 0.0, 0.0, 0.0
    return True


@kernel
def on_ground(s, P) -> bool:
    """Resting on the ground: contact on, O at z = 0 and G not moving vertically."""
    _, p_O, _ = motion_of_O(s, P)
    climb = s[STATE.velocity + 2]
    return P[PLANT.ground] != 0.0 and p_O[2] <= ON_GROUND_TOLERANCE and abs(climb) < ON_GROUND_TOLERANCE


@kernel
def physics_steps(work, P, inputs, h: float) -> None:
    """One RK4 step of ``h`` of ``work[0]`` per ``INPUTS.size`` block of ``inputs`` (held over that
    step), the ground contact resolved after each."""
    work, P, inputs = borrowed(work), borrowed(P), borrowed(inputs)  # the caller's: no counting per call
    s = work[0]
    for j in range(len(inputs) // INPUTS.size):
        u = inputs[j * INPUTS.size : (j + 1) * INPUTS.size]
        rk4_step(s, work[1], work[2], work[3], work[4], work[5], P, u, h)
        # O may be at the ground only when G is this low
        if P[PLANT.ground] != 0.0 and s[STATE.position + 2] < P[PLANT.ground_reach]:
            ground_contact(s, P)


@kernel
def truth(work, P, u) -> tuple:
    """The ground truth of ``work[0]`` with the inputs ``u`` held, a :class:`TruthState`. One
    derivative evaluation (into ``work[1]``) gives the accelerations."""
    work, P, u = borrowed(work), borrowed(P), borrowed(u)  # the caller's: no counting per call
    s, ds = work[0], work[1]
    derivative(s, ds, P, u)
    R, p_O, v_O = motion_of_O(s, P)
    r_G = com_offset(P)
    w = vector_at(s, STATE.body_rates)
    grounded = on_ground(s, P)
    if grounded:
        a_O = (0.0, 0.0, 0.0)
    else:
        # a_O = a_G - R (w_dot x r_G + w x (w x r_G))
        a1 = cross(vector_at(ds, STATE.body_rates), r_G)
        a2 = cross(w, cross(w, r_G))
        Ra = matrix_times(R, (a1[0] + a2[0], a1[1] + a2[1], a1[2] + a2[2]))
        a_G = vector_at(ds, STATE.velocity)  # the velocity's derivative
        a_O = (a_G[0] - Ra[0], a_G[1] - Ra[1], a_G[2] - Ra[2])
    specific = transpose_times(R, (a_O[0], a_O[1], a_O[2] + P[PLANT.gravity]))
    euler = euler_from_rotation(R)
    euler_rates = euler_rates_from_body_rates(euler[0], euler[1], w)
    if P[PLANT.rotor_mode] != 0.0:
        speeds = state_rotor_speeds(s)
        thrust, torque = rotor_wrench(P, s)
    else:
        speeds = (0.0, 0.0, 0.0, 0.0)
        thrust, torque = u[INPUTS.thrust], (u[INPUTS.torque], u[INPUTS.torque + 1], u[INPUTS.torque + 2])
        if P[PLANT.faulted] != 0.0:
            tau = INPUTS.torque
            thrust, tx, ty, tz = faulted_wrench(P, u[INPUTS.thrust], u[tau], u[tau + 1], u[tau + 2])
            torque = (tx, ty, tz)
    q = quaternion_at(s, STATE.attitude)
    return TruthState(p_O, v_O, a_O, q, euler, w, euler_rates, specific, speeds, thrust, torque, grounded)


@kernel
def advance(work, P, inputs, h: float) -> tuple:
    """A lockstep frame's physics in one call: :func:`physics_steps`, then the :func:`truth` of the
    result with the last step's inputs held, as a plain tuple of its fields (``TruthState._make``:
    compiled code boxes a named tuple for Python at several times the cost of a tuple)."""
    physics_steps(work, P, inputs, h)
    return truth(work, P, inputs[len(inputs) - INPUTS.size :])[:]


@kernel
def truth_fields(work, P, u) -> tuple:
    """:func:`truth` as a plain tuple of its fields, for Python (``TruthState._make``)."""
    return truth(work, P, u)[:]
