"""The nominal Section II model as a plant: eqs. (1)-(6) integrated in ``(xi, xi', eta, eta')``.

The model the controllers are designed on (``plant.model = "nominal"``), for checking them against
their own assumptions; the simulator's default is the coupled plant of :mod:`.plant`. Same inputs
and read-outs as that plant under ``actuation = "wrench"``, and the same machinery: the parameters
and held inputs are the layouts :data:`.equations.PLANT` and :data:`.equations.INPUTS` (of which the
model reads the mass, gravity, the principal moments of inertia, ground contact, the wrench and the
disturbances: no centre-of-mass offset, products of inertia, drag or wind), the one integrator is
:func:`.equations.rk4_of` (of :func:`nominal_derivative`), and the equations below are
kernels (:mod:`quadcommon.kernel`), compiled with numba or run as Python as the coupled plant's
are. Pure: no clocks, no I/O.

The state (layout :data:`NOMINAL_STATE`, 12 floats): the position ``xi`` and velocity ``xi'`` of
the body (world), the ZYX Euler angles ``eta = (phi, theta, psi)`` and their rates ``eta'``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from quadcommon.config import VehicleConfig
from quadcommon.kernel import borrowed, kernel
from quadcommon.layout import Field, layout, values, vector_at
from quadcommon.rigid_body import (
    body_rates_from_euler_rates,
    coriolis_times,
    euler_rates_from_body_rates,
    euler_torque_from_body_torque,
    inertia_matrix,
    quaternion_from_euler,
    rotation_matrix,
    solve3,
    transpose_times,
)

from .equations import INPUTS, PLANT, TruthState, rk4_of
from .plant import ZERO3, Plant, PlantEntries, Vector3, warmed_entries

NOMINAL_STATE = layout("NominalState", (
    Field("position", 3, unit="m", doc="xi, world"),
    Field("velocity", 3, unit="m/s", doc="xi', world"),
    Field("euler", 3, unit="rad", doc="eta = (phi, theta, psi), ZYX"),
    Field("euler_rates", 3, unit="rad/s", doc="eta'"),
))  # fmt: skip

# Resting on the ground: at z = 0 and not moving vertically, within this (m, m/s).
RESTING_TOLERANCE = 1e-9


@kernel
def nominal_derivative(s, out, P, u) -> None:
    """``out = ds/dt`` with the inputs ``u`` held: eq. (2) for the translation, eq. (4) (the
    Euler-Lagrange form with its inertia and Coriolis matrices) for the rotation, the body torque
    entering as ``W_eta^T tau_body``."""
    m, g = P[PLANT.mass], P[PLANT.gravity]
    J = PLANT.inertia  # row-major: the principal moments on its diagonal
    inertia = (P[J], P[J + 4], P[J + 8])
    eta = vector_at(s, NOMINAL_STATE.euler)
    phi, theta, psi = eta
    eta_dot = vector_at(s, NOMINAL_STATE.euler_rates)
    U1 = u[INPUTS.thrust]
    f = INPUTS.disturbance_force
    # eq. (2): m xi'' = R e3 U1 + F_d - m g e3 (R e3: the last column of R)
    R = rotation_matrix(phi, theta, psi)
    x, v = NOMINAL_STATE.position, NOMINAL_STATE.velocity
    out[x], out[x + 1], out[x + 2] = s[v], s[v + 1], s[v + 2]
    out[v] = (R[0][2] * U1 + u[f]) / m
    out[v + 1] = (R[1][2] * U1 + u[f + 1]) / m
    out[v + 2] = -g + (R[2][2] * U1 + u[f + 2]) / m
    # eq. (4): M eta'' + C eta' = tau_eta_a + tau_eta_d
    t, d = INPUTS.torque, INPUTS.disturbance_torque
    tau = euler_torque_from_body_torque(phi, theta, (u[t], u[t + 1], u[t + 2]))
    c = coriolis_times(inertia, eta, eta_dot, eta_dot)
    rhs = (tau[0] + u[d] - c[0], tau[1] + u[d + 1] - c[1], tau[2] + u[d + 2] - c[2])
    eta_ddot = solve3(inertia_matrix(inertia, phi, theta), rhs)
    e, r = NOMINAL_STATE.euler, NOMINAL_STATE.euler_rates
    out[e], out[e + 1], out[e + 2] = eta_dot[0], eta_dot[1], eta_dot[2]
    out[r], out[r + 1], out[r + 2] = eta_ddot[0], eta_ddot[1], eta_ddot[2]


nominal_rk4 = rk4_of(nominal_derivative)  # the one integrator, on eqs. (2) and (4)


@kernel
def nominal_physics_steps(work, P, inputs, h: float) -> None:
    """One RK4 step (:data:`nominal_rk4`) of ``h`` of ``work[0]`` per ``INPUTS.size`` block of
    ``inputs`` (held over that step); with ground contact on, a body at or below z = 0 and moving
    down is put to rest there, level at its heading."""
    work, P, inputs = borrowed(work), borrowed(P), borrowed(inputs)  # the caller's: no counting per call
    s = work[0]
    for j in range(len(inputs) // INPUTS.size):
        u = inputs[j * INPUTS.size : (j + 1) * INPUTS.size]
        nominal_rk4(s, work[1], work[2], work[3], work[4], work[5], P, u, h)
        x, v = NOMINAL_STATE.position, NOMINAL_STATE.velocity
        e, r = NOMINAL_STATE.euler, NOMINAL_STATE.euler_rates
        if P[PLANT.ground] != 0.0 and s[x + 2] <= 0.0 and s[v + 2] <= 0.0:
            s[x + 2], s[v], s[v + 1], s[v + 2] = 0.0, 0.0, 0.0, 0.0
            s[e], s[e + 1] = 0.0, 0.0  # level, at its heading
            s[r], s[r + 1], s[r + 2] = 0.0, 0.0, 0.0


@kernel
def nominal_on_ground(s, P) -> bool:
    """Resting on the ground: contact on, at z = 0 and not moving vertically."""
    height, climb = s[NOMINAL_STATE.position + 2], s[NOMINAL_STATE.velocity + 2]
    return P[PLANT.ground] != 0.0 and height <= RESTING_TOLERANCE and abs(climb) < RESTING_TOLERANCE


@kernel
def nominal_truth(work, P, u) -> tuple:
    """The ground truth of ``work[0]`` with the inputs ``u`` held, a :class:`~.equations.TruthState`:
    pose, velocities, the body rates of eq. (3), the acceleration (one derivative evaluation, into
    ``work[1]``) and the specific force an ideal IMU would read."""
    work, P, u = borrowed(work), borrowed(P), borrowed(u)  # the caller's: no counting per call
    s, ds = work[0], work[1]
    nominal_derivative(s, ds, P, u)
    euler = vector_at(s, NOMINAL_STATE.euler)
    eta_dot = vector_at(s, NOMINAL_STATE.euler_rates)
    R = rotation_matrix(euler[0], euler[1], euler[2])
    w = body_rates_from_euler_rates(euler[0], euler[1], eta_dot)  # eq. (3)
    grounded = nominal_on_ground(s, P)
    acc = (0.0, 0.0, 0.0) if grounded else vector_at(ds, NOMINAL_STATE.velocity)
    specific = transpose_times(R, (acc[0], acc[1], acc[2] + P[PLANT.gravity]))
    q = quaternion_from_euler(euler[0], euler[1], euler[2])
    t = INPUTS.torque
    torque = (u[t], u[t + 1], u[t + 2])
    position, velocity = vector_at(s, NOMINAL_STATE.position), vector_at(s, NOMINAL_STATE.velocity)
    return TruthState(position, velocity, acc, q, euler, w, eta_dot, specific,
                      (0.0, 0.0, 0.0, 0.0), u[INPUTS.thrust], torque, grounded)  # fmt: skip


@kernel
def nominal_advance(work, P, inputs, h: float) -> tuple:
    """A lockstep frame in one call: :func:`nominal_physics_steps`, then the :func:`nominal_truth`
    of the result with the last step's inputs held, as a plain tuple of its fields."""
    nominal_physics_steps(work, P, inputs, h)
    return nominal_truth(work, P, inputs[len(inputs) - INPUTS.size :])[:]


@kernel
def nominal_truth_fields(work, P, u) -> tuple:
    """:func:`nominal_truth` as a plain tuple of its fields, for Python (``TruthState._make``)."""
    return nominal_truth(work, P, u)[:]


class NominalPlant(Plant):
    """The Section II model, eqs. (1)-(6), integrated in ``(xi, xi', eta, eta')`` by RK4: a
    :class:`~.plant.Plant` (the same inputs, saturation, :meth:`advance`, :meth:`step` and
    :meth:`truth`) on the nominal model's equations.

    Inputs are those of :class:`~.plant.Plant` under ``actuation = "wrench"``: thrust and a body
    torque, whose generalised torque on the Euler coordinates is ``W_eta^T tau_body``.
    """

    model = "nominal"

    def __init__(self, vehicle: VehicleConfig, physics_dt_s: float) -> None:
        if vehicle.actuation.mode != "wrench":
            raise ValueError("the nominal Section II plant takes actuation = 'wrench' only")
        super().__init__(vehicle, physics_dt_s)

    @staticmethod
    def _make_entries() -> PlantEntries:
        return _nominal_entries()

    def reset(
        self,
        position_m: Vector3,
        euler_rad: Vector3,
        velocity_m_s: Vector3 = ZERO3,
        body_rates_rad_s: Vector3 = ZERO3,
    ) -> None:
        """Put the body at ``position_m`` (m), ``euler_rad`` (ZYX), with ``velocity_m_s`` (world) and
        ``body_rates_rad_s`` (FLU; stored as the Euler rates of eq. (3))."""
        self._truth = None
        eta_dot = euler_rates_from_body_rates(euler_rad[0], euler_rad[1], body_rates_rad_s)
        self.state = list(values(NOMINAL_STATE, position=position_m, velocity=velocity_m_s, euler=euler_rad,
                                 euler_rates=eta_dot))  # fmt: skip

    def set_rotor_commands(self, speeds_rad_s: tuple[float, float, float, float]) -> None:
        """Refused: the nominal plant is actuated by its wrench only (ValueError)."""
        raise ValueError("the nominal plant has no rotors")

    def set_rotor_fault(self, rotor: int, fault) -> None:  # noqa: ANN001 - a RotorFault
        """Refused: the nominal plant has no rotors to fail (ValueError)."""
        raise ValueError("the nominal plant has no rotors")

    def faults_due(self, table, row: int, t: float) -> int:  # noqa: ANN001 - a fault table
        """``row`` when the table has no rows left; a row to apply is refused (ValueError): the
        nominal plant has no rotors to fail."""
        if row < len(table):
            raise ValueError("the nominal plant has no rotors")
        return row


def nominal_kernels() -> tuple[Callable[..., object], ...]:
    """The kernels :class:`NominalPlant` calls, in the order of :class:`~.plant.PlantEntries`."""
    return (nominal_physics_steps, nominal_advance, nominal_truth_fields)


@functools.cache
def _nominal_entries() -> PlantEntries:
    """The entries, made once per process when the first nominal plant is built
    (:func:`~.plant.warmed_entries`, as the coupled plant's)."""
    return warmed_entries(nominal_kernels(), NOMINAL_STATE.size, _nominal_scratch)


def _nominal_scratch(work: np.ndarray, P: np.ndarray) -> None:
    P[PLANT.mass] = P[PLANT.inertia] = P[PLANT.inertia + 4] = P[PLANT.inertia + 8] = 1.0
