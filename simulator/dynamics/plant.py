"""The simulated quadrotor: the paper's "more accurate model" and the nominal Section II model.

Pure: no clocks, no I/O. The caller owns time; :meth:`Plant.step` advances one physics step by
fixed-step RK4 with the actuator inputs and the disturbance held constant over the step (zero-
order hold between control steps).

Coupled plant (``plant.model = "coupled"``, CONTROL.md "The more accurate plant"):

* rigid body of mass ``m`` whose centre of mass G sits at ``r_G`` (body frame) from the geometric
  centre O, where thrust and control torques act and where position is reported; full inertia
  tensor about G with products of inertia. Newton-Euler is written about G (exact and decoupled
  there) and the coupling appears where forces act at O and where O's motion is read out:
  ``p_O = p_G - R r_G``, ``v_O = v_G - R (omega x r_G)``; thrust at O adds ``-r_G x F`` about G;
* ``actuation = "wrench"``: ``U1 in [0, U1_max]`` and body torques ``|tau_i| <= tau_max``
  applied directly (the idealised actuator the paper's experiment needs);
* ``actuation = "rotors"``: four rotors in + configuration (1 front, 2 right, 3 rear, 4 left;
  1 and 3 spin counter-clockwise seen from above, :data:`ROTOR_POSITIONS`), thrust
  ``e b Omega^2``, reaction torque ``e d Omega^2`` with each rotor's effectiveness ``e`` (1
  healthy), first-order speed dynamics towards the command, speed limits, gyroscopic moment
  ``J_r Omega_r (q, -p, 0)`` with ``Omega_r = -Omega1 + Omega2 - Omega3 + Omega4`` and the
  reaction to rotor acceleration ``J_r dOmega_r/dt`` about z;
* disturbances: a force in the world frame applied at G (the ``[Ax, Ay, Az]`` of eq. 1), torques
  on the Euler coordinates as in eq. (4), applied as the equivalent body couple
  ``W_eta^-T [Ap, Aq, Ar]``; wind enters through linear drag ``-k (v_O - wind)`` at G;
* ground contact (optional): the plane z = 0 under O; a vehicle pressed against it rests level;
* actuator faults (:meth:`Plant.set_rotor_fault`, :class:`RotorFault`): per rotor a loss of
  effectiveness (thrust and reaction torque scaled by ``e`` in [0, 1]), a rotor stuck at its
  speed, a rotor off (unpowered: no thrust, no torque, spinning down); on the wrench vehicle
  through the allocation's equation (each rotor's share of the wrench, see
  :func:`.equations.faulted_wrench`).

Nominal plant (``plant.model = "nominal"``, :mod:`.nominal_plant`): eqs. (1)-(6) integrated in
``(xi, eta)``: the model the controllers are designed on, for checking them against their own
assumptions.

The equations are in :mod:`.equations`, written once: this class holds the vehicle's parameters
and the held inputs, and calls those kernels, compiled with numba (loaded or compiled when the
first plant is built, never in the middle of a flight), or as plain Python where nothing compiles
(``QUADSITL_PURE_PYTHON=1``: the same source, slower).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Sequence
from typing import NamedTuple

import numpy as np

from quadcommon.config import VehicleConfig
from quadcommon.failures import ALL_INSTANCES, PX4_MOTOR_POSITIONS, ActuatorFault, Type
from quadcommon.kernel import compiled, compiling, freeze, vector
from quadcommon.layout import fields_of, values
from quadcommon.rigid_body import cross, matrix_times, quaternion_from_euler, rotation_from_quaternion, solve3

from . import equations
from .equations import (  # noqa: F401 - TruthState is part of this module's interface
    INPUTS,
    PLANT,
    ROTOR_FAULT,
    ROTOR_FOLLOWS,
    ROTOR_OFF,
    ROTOR_STUCK,
    STATE,
    WRENCH_STATE_SIZE,
    TruthState,
)

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)
ROTOR_POSITIONS = ("front", "right", "rear", "left")  # rotors 1-4 of the plant (and of the allocation)


def rotor_of_motor(motor: int) -> int:
    """The plant's rotor (1-4, :data:`ROTOR_POSITIONS`) of PX4's motor ``motor`` (1-4, quadrotor +:
    :data:`quadcommon.failures.PX4_MOTOR_POSITIONS`): the same position."""
    return ROTOR_POSITIONS.index(PX4_MOTOR_POSITIONS[motor - 1]) + 1


class RotorFault(NamedTuple):
    """What a rotor's failure (:mod:`quadcommon.failures`, unit ``motor``) does in the plant's terms:
    its speed's ``mode`` (``ROTOR_FOLLOWS``, ``ROTOR_STUCK``, ``ROTOR_OFF``) and ``effectiveness``."""

    mode: float
    effectiveness: float

    @classmethod
    def of(cls, failure_type: int, effectiveness: float = 1.0) -> RotorFault:
        """The plant's fault for a FAILURE_TYPE: ``ok`` healthy, ``off`` unpowered (effectiveness
        0), ``stuck`` held at its speed (effectiveness 1), ``wrong`` a loss of effectiveness
        (``effectiveness`` left, in [0, 1]). ValueError for another type or effectiveness."""
        if failure_type == Type.ok:
            return cls(ROTOR_FOLLOWS, 1.0)
        if failure_type == Type.off:
            return cls(ROTOR_OFF, 0.0)
        if failure_type == Type.stuck:
            return cls(ROTOR_STUCK, 1.0)
        if failure_type == Type.wrong:
            if not 0.0 <= effectiveness <= 1.0:
                raise ValueError(f"rotor effectiveness {effectiveness!r} outside [0, 1]")
            return cls(ROTOR_FOLLOWS, float(effectiveness))
        raise ValueError(f"failure type {failure_type} is not a rotor's (ok, off, stuck, wrong)")

    @property
    def failure_type(self) -> Type:
        """The FAILURE_TYPE this fault is (``ok`` for a healthy rotor)."""
        if self.mode == ROTOR_OFF:
            return Type.off
        if self.mode == ROTOR_STUCK:
            return Type.stuck
        return Type.ok if self.effectiveness == 1.0 else Type.wrong


HEALTHY = RotorFault(ROTOR_FOLLOWS, 1.0)


class ScheduledFault(NamedTuple):
    """A rotor fault at a time: from ``onset_s`` (the first frame at or after it) rotor ``rotor``
    (1-4, the plant's numbering) has ``fault``."""

    onset_s: float
    rotor: int
    fault: RotorFault


def fault_table(faults: Iterable[ScheduledFault]) -> np.ndarray:
    """``ScheduledFault`` rows as the kernels' table (rows of :data:`.equations.ROTOR_FAULT`), sorted
    by onset (faults at the same time keep their order)."""
    rows = sorted(faults, key=lambda f: f.onset_s)
    table = np.zeros((len(rows), ROTOR_FAULT.size))
    for i, f in enumerate(rows):
        table[i] = (f.onset_s, f.rotor - 1, f.fault.mode, f.fault.effectiveness)
    return table


def schedule(faults: Iterable[ActuatorFault]) -> tuple[list[tuple[ActuatorFault, int]], np.ndarray]:
    """Motor failures at a time (a scenario's ``[[actuator_faults]]``, a campaign run's) as the
    plant applies them: one ``(fault, PX4 motor)`` per motor addressed (motor 0: all four), by
    onset, and their table for :func:`.equations.rotor_faults_due` (one row each, the same order)."""
    rows = sorted(((f, m) for f in faults for m in motors_of(f.motor)), key=lambda item: item[0].start_s)
    table = fault_table(
        ScheduledFault(f.start_s, rotor_of_motor(m), RotorFault.of(f.failure_type, f.effectiveness))
        for f, m in rows
    )
    return rows, table


def motors_of(instance: int) -> tuple[int, ...]:
    """PX4's motors a failure's instance addresses: the one, or all four for 0."""
    return (1, 2, 3, 4) if instance == ALL_INSTANCES else (instance,)


class Plant:
    """Coupled quadrotor integrated by RK4 at a fixed physics step."""

    model = "coupled"  # the plant.model whose equations it integrates

    def __init__(self, vehicle: VehicleConfig, physics_dt_s: float) -> None:
        if vehicle.plant.model != self.model:
            raise ValueError(f"{type(self).__name__} integrates the {self.model!r} model, not "
                             f"{vehicle.plant.model!r} (make_plant builds the one it asks for)")  # fmt: skip
        self.vehicle = vehicle
        self.dt = physics_dt_s
        plant, act, rot = vehicle.plant, vehicle.actuation, vehicle.rotors
        self.mass = plant.mass_kg
        self.gravity = vehicle.nominal.gravity_m_s2
        self.rotor_mode = act.mode == "rotors"
        Ixx, Iyy, Izz = plant.inertia_kg_m2
        Ixy, Ixz, Iyz = plant.products_of_inertia_kg_m2
        # Inertia tensor about G (positive products in the config mean J = [[Ixx, -Ixy, ...]]).
        self.inertia = ((Ixx, -Ixy, -Ixz), (-Ixy, Iyy, -Iyz), (-Ixz, -Iyz, Izz))
        columns = [solve3(self.inertia, e) for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]
        self.inertia_inv = tuple(tuple(column[i] for column in columns) for i in range(3))
        self.com_offset = plant.com_offset_m
        self.drag = plant.drag_coefficient_n_s_m
        self.ground_contact = plant.ground_contact
        self.thrust_max = act.thrust_max_n
        self.torque_max = act.torque_max_n_m
        self.arm = vehicle.nominal.arm_length_m
        self.b, self.d = rot.thrust_coefficient_n_s2, rot.drag_coefficient_n_m_s2
        self.rotor_inertia = rot.inertia_kg_m2
        self.rotor_tau = rot.time_constant_s
        self.speed_min, self.speed_max = rot.speed_min_rad_s, rot.speed_max_rad_s
        # Inputs held over the step.
        self.thrust_cmd = 0.0
        self.torque_cmd: Vector3 = ZERO3
        self.rotor_cmd = (0.0, 0.0, 0.0, 0.0)
        self.force_dist: Vector3 = ZERO3
        self.torque_dist_eta: Vector3 = ZERO3
        self.wind: Vector3 = ZERO3
        self.state: list[float] = []
        self.reset(ZERO3, ZERO3)
        # The kernels' buffers: parameters, state and RK4 scratch, one step's inputs, a frame's.
        self._P = vector(self.parameters())
        self._work = _rows(6, len(self.state))
        self._s = self._work[0]
        self._u = vector(INPUTS.size)
        self._frame_u = vector(2 * INPUTS.size)
        self._entries = self._make_entries()
        self._truth: tuple[list[float], TruthState] | None = None  # (the state it is of, truth)

    @staticmethod
    def _make_entries() -> PlantEntries:
        """The compiled entries of this plant's equations (made once per process)."""
        return _entries()

    def parameters(self) -> list[float]:
        """The parameter vector the equations read (:data:`.equations.PLANT`, filled by name; healthy
        rotors)."""
        return list(values(
            PLANT, mass=self.mass, gravity=self.gravity, inertia=[x for row in self.inertia for x in row],
            inertia_inverse=[x for row in self.inertia_inv for x in row], com=self.com_offset,
            drag=self.drag, thrust_coefficient=self.b, torque_coefficient=self.d, arm=self.arm,
            rotor_inertia=self.rotor_inertia, rotor_time_constant=self.rotor_tau,
            rotor_speed_min=self.speed_min, rotor_speed_max=self.speed_max, thrust_max=self.thrust_max,
            torque_max=self.torque_max, rotor_mode=1.0 if self.rotor_mode else 0.0,
            ground=1.0 if self.ground_contact else 0.0,
            has_drag=1.0 if any(k != 0.0 for k in self.drag) else 0.0,
            ground_reach=math.sqrt(sum(c * c for c in self.com_offset)) + 1e-3,
            effectiveness=(1.0, 1.0, 1.0, 1.0), fault_mode=(0.0, 0.0, 0.0, 0.0),
            held_share=(0.0, 0.0, 0.0, 0.0), faulted=0.0,
        ))  # fmt: skip

    # -- actuator faults --------------------------------------------------------------------------
    def set_rotor_fault(self, rotor: int, fault: RotorFault) -> None:
        """Rotor ``rotor`` (1-4, :data:`ROTOR_POSITIONS`) has ``fault`` from the next step on
        (:func:`.equations.set_rotor_fault`; :data:`HEALTHY` ends it); on the wrench vehicle a
        stuck rotor holds its share of the wrench commanded now."""
        if not 1 <= rotor <= 4:
            raise ValueError(f"rotor {rotor!r}: the rotors are 1-4")
        self._truth = None
        equations.set_rotor_fault(self._P, rotor - 1, fault.mode, fault.effectiveness, self._held_inputs())

    def faults_due(self, table, row: int, t: float) -> int:
        """The rows of a fault table (:func:`fault_table`) from ``row`` on whose onset is at or
        before ``t`` (s), set (:func:`.equations.rotor_faults_due`); the next row to wait for."""
        self._truth = None
        return equations.rotor_faults_due(self._P, table, row, t, self._held_inputs())

    def rotor_fault(self, rotor: int) -> RotorFault:
        """Rotor ``rotor``'s (1-4) fault now (:data:`HEALTHY` when it has none)."""
        P = self._P
        return RotorFault(float(P[PLANT.fault_mode + rotor - 1]), float(P[PLANT.effectiveness + rotor - 1]))

    @property
    def rotor_effectiveness(self) -> list[float]:
        """Rotors 1-4: each one's effectiveness (1 healthy, 0 off)."""
        return [float(e) for e in self._P[PLANT.effectiveness : PLANT.effectiveness + 4]]

    # -- state ------------------------------------------------------------------------------------
    def reset(
        self,
        position_m: Vector3,
        euler_rad: Vector3,
        velocity_m_s: Vector3 = ZERO3,
        body_rates_rad_s: Vector3 = ZERO3,
    ) -> None:
        """Place O at ``position_m`` with the given attitude and motion; rotors at rest."""
        self._truth = None
        q = quaternion_from_euler(*euler_rad)
        R = rotation_from_quaternion(*q)
        Rr = matrix_times(R, self.com_offset)
        Rwxr = matrix_times(R, cross(body_rates_rad_s, self.com_offset))
        p_G = [position_m[i] + Rr[i] for i in range(3)]
        v_G = [velocity_m_s[i] + Rwxr[i] for i in range(3)]
        state = values(STATE, position=p_G, velocity=v_G, attitude=q, body_rates=body_rates_rad_s,
                       rotor_speeds=(0.0, 0.0, 0.0, 0.0))  # fmt: skip
        self.state = list(state if self.rotor_mode else state[:WRENCH_STATE_SIZE])

    def set_wrench(self, thrust_n: float, torque_body_n_m: Vector3) -> None:
        """Actuation "wrench": total thrust and body torque about O, saturated here."""
        self._truth = None
        tmax = self.torque_max
        self.thrust_cmd = _clip(thrust_n, 0.0, self.thrust_max)
        self.torque_cmd = (
            _clip(torque_body_n_m[0], -tmax[0], tmax[0]),
            _clip(torque_body_n_m[1], -tmax[1], tmax[1]),
            _clip(torque_body_n_m[2], -tmax[2], tmax[2]),
        )

    def set_rotor_commands(self, speeds_rad_s: tuple[float, float, float, float]) -> None:
        """Actuation "rotors": commanded rotor speeds, clipped to the speed limits."""
        self._truth = None
        lo, hi = self.speed_min, self.speed_max
        self.rotor_cmd = tuple(_clip(s, lo, hi) for s in speeds_rad_s)  # type: ignore[assignment]

    def set_actuator_controls(self, controls: tuple[float, ...]) -> None:
        """Normalised actuator controls as they arrive in ``HIL_ACTUATOR_CONTROLS``.

        ``actuation = "wrench"``:
        ``(U1 / U1_max, tau_x / tau_max, tau_y / tau_max, tau_z / tau_max)``
        (body torques, paper frames). ``"rotors"``: ``Omega_i / Omega_max`` for rotors 1-4.
        """
        if self.rotor_mode:
            top = self.speed_max
            self.set_rotor_commands(tuple(c * top for c in controls[:4]))  # type: ignore[arg-type]
        else:
            tm = self.torque_max
            self.set_wrench(
                controls[0] * self.thrust_max,
                (controls[1] * tm[0], controls[2] * tm[1], controls[3] * tm[2]),
            )

    def set_disturbance(
        self, force_world_n: Vector3, torque_euler_n_m: Vector3, wind_world_m_s: Vector3 = ZERO3
    ) -> None:
        """External inputs held over the next step (eqs. 1 and 4 disturbances, and wind)."""
        self._truth = None
        self.force_dist = force_world_n
        self.torque_dist_eta = torque_euler_n_m
        self.wind = wind_world_m_s

    # -- dynamics ---------------------------------------------------------------------------------
    def advance(self, disturbances: Sequence[tuple[Vector3, Vector3, Vector3]]) -> None:
        """One physics step per ``(force, torque, wind)`` of ``disturbances``, each held over its
        step (as :meth:`set_disturbance` then :meth:`step` would): a lockstep frame's physics, and
        the truth read-out that the next frame asks for, in one call of the equations;
        :meth:`truth` then returns it until the state or an input changes."""
        held = self._held_actuators()
        inputs: list[float] = []
        for force, torque, wind in disturbances:
            inputs += (*held, *force, *torque, *wind)  # the INPUTS layout, one block per step
        frame_u = self._frame_u
        if len(frame_u) != len(inputs):
            frame_u = self._frame_u = vector(len(inputs))
        frame_u[:] = inputs  # one conversion
        s = self._s
        s[:] = self.state
        truth = TruthState._make(self._entries.advance(self._work, self._P, frame_u, self.dt))
        self.force_dist, self.torque_dist_eta, self.wind = disturbances[-1]
        self.state = _listed(s)
        self._truth = (list(self.state), truth)  # a copy: an in-place change of the state misses it

    def step(self) -> None:
        """Advance one physics step (classical RK4, inputs held), then the ground contact."""
        self._truth = None
        s = self._s
        s[:] = self.state
        self._u[:] = self._held_inputs()
        self._entries.physics_steps(self._work, self._P, self._u, self.dt)
        self.state = _listed(s)

    def _held_actuators(self) -> tuple[float, ...]:
        """The actuator part of the held inputs (``INPUTS.thrust`` .. ``INPUTS.disturbance_force``)."""
        if self.rotor_mode:
            return (0.0, 0.0, 0.0, 0.0, *self.rotor_cmd)
        return (self.thrust_cmd, *self.torque_cmd, 0.0, 0.0, 0.0, 0.0)

    def _held_inputs(self) -> tuple[float, ...]:
        """The inputs held over the next step (:data:`.equations.INPUTS`)."""
        return (*self._held_actuators(), *self.force_dist, *self.torque_dist_eta, *self.wind)

    # -- read-out ---------------------------------------------------------------------------------
    def on_ground(self) -> bool:
        """Resting on the ground (the truth's ``on_ground``)."""
        return self.truth().on_ground

    def kinematics(self) -> tuple[Vector3, Vector3, Vector3, Vector3]:
        """``(position, velocity, euler, euler_rates)`` of O: what a controller with perfect state
        knowledge reads."""
        truth = self.truth()
        return truth.position_m, truth.velocity_m_s, truth.euler_rad, truth.euler_rates_rad_s

    def truth(self) -> TruthState:
        """Ground truth now (one derivative evaluation gives the accelerations), kept until the
        state or an input changes (after :meth:`advance`, the read-out it made)."""
        cached = self._truth
        if cached is not None and cached[0] == self.state:
            return cached[1]
        state = list(self.state)  # a copy: an in-place change of the state misses the cache
        self._s[:] = state
        self._u[:] = self._held_inputs()
        truth = TruthState._make(self._entries.truth_fields(self._work, self._P, self._u))
        self._truth = (state, truth)
        return truth


def make_plant(vehicle: VehicleConfig, physics_dt_s: float):
    """The plant the vehicle config asks for (``plant.model``): this one, or the Section II model
    (:class:`.nominal_plant.NominalPlant`)."""
    if vehicle.plant.model == "nominal":
        from .nominal_plant import NominalPlant

        return NominalPlant(vehicle, physics_dt_s)
    return Plant(vehicle, physics_dt_s)


class PlantEntries(NamedTuple):
    """What :class:`Plant` calls: the equations' entries (:func:`quadcommon.kernel.compiled`); a
    :class:`~.nominal_plant.NominalPlant` has its own."""

    physics_steps: Callable[..., None]
    advance: Callable[..., tuple]
    truth_fields: Callable[..., tuple]


def plant_kernels() -> tuple:
    """The equations' kernels the plant calls (what ``quadsitl compile`` compiles for it)."""
    return tuple(getattr(equations, name) for name in PlantEntries._fields)


def warmed_entries(kernels: Iterable[Callable[..., object]], state_size: int,
                   scratch: Callable[[np.ndarray, np.ndarray], None]) -> PlantEntries:  # fmt: skip
    """A plant's entries (``kernels`` in :class:`PlantEntries`' order). Compiled, each is called
    once now on scratch buffers (``state_size`` floats of state; ``scratch(work, P)`` makes them a
    plant that can step) so it is loaded from numba's cache, or compiled (~1 s or more, which in
    the middle of lockstep the autopilot would see as a simulator stall), and frozen: nothing
    compiles mid-flight."""
    entries = PlantEntries(*(compiled(fn) for fn in kernels))
    if compiling():
        work, P, u = np.zeros((6, state_size)), np.zeros(PLANT.size), np.zeros(INPUTS.size)
        scratch(work, P)
        entries.physics_steps(work, P, u, 0.001)
        entries.advance(work, P, u, 0.001)
        entries.truth_fields(work, P, u)
        for entry in entries:
            freeze(entry)
    return entries


def _coupled_scratch(work: np.ndarray, P: np.ndarray) -> None:
    work[0, STATE.attitude] = P[PLANT.mass] = P[PLANT.rotor_time_constant] = 1.0


@functools.cache
def _entries() -> PlantEntries:
    """The coupled plant's entries, made once per process (:func:`warmed_entries`)."""
    return warmed_entries(plant_kernels(), STATE.size, _coupled_scratch)


# _held_inputs and advance build the held-input blocks in the layout's field order (a tuple per
# frame is cheaper than writes by offset): the order they build, named, is the layout's.
assert [f.name for f in fields_of(INPUTS)] == [
    "thrust", "torque", "rotor_commands", "disturbance_force", "disturbance_torque", "wind"
]  # fmt: skip


# -- small helpers (off the equations) ------------------------------------------------------------
def _rows(count: int, width: int):
    """``count`` float buffers of ``width`` for the kernels: one 2-D array where they compile (one
    argument to unbox per call), else a list of lists (:func:`quadcommon.kernel.vector`)."""
    rows = [vector(width) for _ in range(count)]
    return np.array(rows) if compiling() else rows


def _listed(buffer) -> list[float]:
    """A copy of a kernel buffer as a list of Python floats."""
    return buffer[:] if isinstance(buffer, list) else buffer.tolist()


def _clip(x: float, lo: float, hi: float) -> float:
    """``min(max(x, lo), hi)``, the same comparisons (NaN passes through), without two builtin
    calls: the actuator inputs are clipped at every frame."""
    x = lo if lo > x else x
    return hi if hi < x else x


__all__ = ["HEALTHY", "Plant", "RotorFault", "ScheduledFault", "TruthState", "fault_table", "make_plant",
           "motors_of", "rotor_of_motor", "schedule"]
