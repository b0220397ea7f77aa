"""The control cascade: translational law -> command filter -> attitude law -> actuators.

Cascades are selected by name (``config/controllers/NAME.toml``): ``intbs_nlhinf`` (the paper's),
``intbs`` (integral in the first step, both loops), ``bs_nlhinf`` (no integral), ``px4_pid`` (PX4's
cascade of P and PID loops; ``px4_pid_tuned`` with gains from PX4's autotune) and ``se3`` (geometric
control on SE(3)); the laws themselves are looked up by name (:mod:`.registry`). Pure: one
:meth:`Cascade.step` per control period, driven by whoever owns the clock.

One step (:func:`cascade_step`, a kernel composed with the cascade's two laws):

1. the translational law: U1 and the roll/pitch references (phi_r, theta_r);
2. the command filter: eta_d, eta_d', eta_d'' from (phi_r, theta_r) and the reference's yaw;
3. the rotational law: the body torque;
4. the actuators: U1 and the torque saturated (``actuation = "wrench"``) or allocated to the
   rotors, as normalised commands. The torque reported back (logs, the IADU index) is the applied
   one, also as the generalised torque ``tau_eta = W_eta^T tau_body`` of eq. (4).

The manual modes replace parts of the chain (:meth:`Cascade.step`'s overrides). The same kernel
is what the autopilot flies per frame, compiled by numba with the two laws inlined
(:func:`quadcommon.kernel.compiled`), and what the campaign engine flies per run.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from quadcommon.config import VehicleConfig
from quadcommon.kernel import borrowed, compiled, compiling, freeze, kernel, typing_error_cause
from quadcommon.layout import Field, layout
from quadcommon.rigid_body import body_rates_from_euler_rates, euler_torque_from_body_torque
from quadcommon.schema import ConfigError
from quadcommon.trajectories import Reference

from ..records import StateEstimate
from . import command_filter as cf
from . import registry
from .allocation import ACTUATORS, OUT_SIZE, actuator_numbers, allocate_rotors, saturate_wrench
from .config import ControllerConfig
from .registry import ROTATIONAL, TRANSLATIONAL, ControllerFailure, LawContext, non_finite_output

Vector3 = tuple[float, float, float]

# The cascade's own numbers (the first part of its buffer).
CASCADE_NUMBERS = layout("CascadeNumbers", (
    Field("dt", unit="s", doc="control period"),
    Field("rotors", doc="1.0: the wrench allocated to the rotors; 0.0: the wrench saturated"),
    Field("filter", cf.FILTER_COEFFICIENTS.size, doc="the command filter's coefficients"),
    Field("actuators", ACTUATORS.size, doc="the actuators' numbers (allocation.ACTUATORS)"),
))  # fmt: skip
# What a step may be given instead of computing it (Cascade.step's overrides).
OVERRIDE_ROLL_PITCH, OVERRIDE_ATTITUDE, OVERRIDE_THRUST = 1, 2, 4
GIVEN = layout("GivenOverrides", (
    Field("flags", doc="OVERRIDE_* added up (0: nothing given)"),
    Field("roll_pitch", 2, unit="rad", doc="phi_r, theta_r instead of the translational law's"),
    Field("attitude", 9, unit="rad, rad/s, rad/s^2", doc="eta_d, eta_d', eta_d'' instead of the filter's"),
    Field("thrust", unit="N", doc="U1 instead of the translational law's"),
))  # fmt: skip


class CascadeMemory(NamedTuple):
    """The arrays a cascade step reads and advances: its own numbers (:data:`CASCADE_NUMBERS`), the
    laws' gains and states, the command filter's state (command_filter.S_*), the overrides given
    (:data:`GIVEN`)."""

    numbers: Any
    translational_gains: Any
    translational_state: Any
    rotational_gains: Any
    rotational_state: Any
    filter_state: Any
    given: Any


class StepResult(NamedTuple):
    """What one cascade step returns (paper frames, SI units)."""

    thrust: float  # applied U1 (N)
    torque_euler: Vector3  # applied tau_eta = W_eta^T tau_body, eq. (4) (N m)
    torque_body: Vector3  # applied body torque (N m)
    euler_ref: Vector3  # eta_d: the filtered roll/pitch references and the yaw reference (rad)
    euler_rate_ref: Vector3  # eta_d' (rad/s)
    roll_pitch_raw: tuple[float, float]  # phi_r, theta_r before the command filter (rad)
    acceleration_cmd: Vector3  # the translational law's commanded acceleration (m/s^2)
    saturated: float  # 1.0 when an actuator limit or the thrust limit acted
    tilt_limited: float  # 1.0 when the roll/pitch reference is at the tilt limit


class BufferParts(NamedTuple):
    """Where each part of a :class:`Cascade`'s one buffer starts (``end``: its length)."""

    numbers: int
    translational_gains: int
    translational_state: int
    rotational_gains: int
    rotational_state: int
    filter_state: int
    given: int
    out: int
    end: int


@kernel
def cascade_step(translational, rotational, memory, state, reference, integrate, out):
    """One step of the cascade (module docstring) with the laws ``translational`` and ``rotational``
    (their step kernels) on their ``memory`` (:class:`CascadeMemory`), flying ``state``
    (:class:`~autopilot.records.StateEstimate`) towards ``reference``
    (:class:`~quadcommon.trajectories.Reference`); the laws' states advance if ``integrate``.
    Normalised commands and rotor speeds go into ``out`` (allocation.OUT_SIZE); returns a
    :class:`StepResult`."""
    K, given = memory.numbers, memory.given
    gt, xt, gr, xr = (memory.translational_gains, memory.translational_state, memory.rotational_gains,
                      memory.rotational_state)  # fmt: skip
    dt = K[CASCADE_NUMBERS.dt]
    euler, euler_rates = state.euler_rad, state.euler_rates_rad_s
    yaw = reference.yaw_rad
    thrust, roll_r, pitch_r, a_x, a_y, a_z, thrust_limited, tilt_limited = translational(
        gt, xt, state.position_m, state.velocity_m_s, euler, reference.position_m, reference.velocity_m_s,
        reference.acceleration_m_s2, yaw, dt, integrate,
    )  # fmt: skip
    override = int(given[GIVEN.flags])
    if override & OVERRIDE_ROLL_PITCH:
        roll_r, pitch_r = given[GIVEN.roll_pitch], given[GIVEN.roll_pitch + 1]
    phi_d, theta_d, phi_d_dot, theta_d_dot, phi_d_ddot, theta_d_ddot = cf.advance(
        K, CASCADE_NUMBERS.filter, memory.filter_state, roll_r, pitch_r
    )
    eta_d = (phi_d, theta_d, yaw)
    eta_d_dot = (phi_d_dot, theta_d_dot, reference.yaw_rate_rad_s)
    eta_d_ddot = (phi_d_ddot, theta_d_ddot, reference.yaw_acceleration_rad_s2)
    if override & OVERRIDE_ATTITUDE:
        a = GIVEN.attitude
        eta_d = (given[a], given[a + 1], given[a + 2])
        eta_d_dot = (given[a + 3], given[a + 4], given[a + 5])
        eta_d_ddot = (given[a + 6], given[a + 7], given[a + 8])
    if override & OVERRIDE_THRUST:
        thrust = given[GIVEN.thrust]
    body_rates = body_rates_from_euler_rates(euler[0], euler[1], euler_rates)
    tx, ty, tz = rotational(gr, xr, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt,
                            integrate)  # fmt: skip
    actuators = CASCADE_NUMBERS.actuators
    if K[CASCADE_NUMBERS.rotors] != 0.0:
        thrust_a, ta0, ta1, ta2, saturated = allocate_rotors(K, actuators, thrust, tx, ty, tz, out)
    else:
        thrust_a, ta0, ta1, ta2, saturated = saturate_wrench(K, actuators, thrust, tx, ty, tz, out)
    te0, te1, te2 = euler_torque_from_body_torque(euler[0], euler[1], (ta0, ta1, ta2))
    return StepResult(
        thrust_a, (te0, te1, te2), (ta0, ta1, ta2), eta_d, eta_d_dot, (roll_r, pitch_r), (a_x, a_y, a_z),
        1.0 if (saturated != 0.0 or thrust_limited != 0.0) else 0.0, tilt_limited,
    )  # fmt: skip


@kernel
def output_finite(thrust, torque_body):
    """False when the wrench a cascade step applies is not finite (its U1 and body torque): a NaN
    or inf anywhere in it shows in their sum (saturation lets NaN through). The one check of a
    law's output, wherever the cascade flies: the autopilot (:meth:`Cascade.step`) and the
    campaign engine (:func:`sitl.campaign.kernels.simulate`)."""
    return math.isfinite(thrust + torque_body[0] + torque_body[1] + torque_body[2])


class CascadeOutput(NamedTuple):
    """One step's result as the autopilot reads it (:meth:`Cascade.step`)."""

    thrust_n: float  # applied U1
    torque_euler_n_m: Vector3  # applied tau_eta (tau_phi, tau_theta, tau_psi)
    torque_body_n_m: Vector3  # applied body torque
    actuator_controls: tuple[float, float, float, float]  # normalised, see allocation.py
    rotor_speeds_rad_s: tuple[float, float, float, float]  # commanded (rotors mode), else zeros
    euler_ref_rad: Vector3  # eta_d (filtered roll/pitch references, yaw reference)
    euler_rate_ref_rad_s: Vector3
    roll_pitch_raw_rad: tuple[float, float]  # phi_r, theta_r before the command filter
    acceleration_cmd_m_s2: Vector3


@kernel
def buffered_step(translational, rotational, buf, at, position, velocity, euler, euler_rates, ref_position,
                  ref_velocity, ref_acceleration, yaw, yaw_rate, yaw_acceleration, integrate):  # fmt: skip
    """:func:`cascade_step` as the entry :class:`Cascade` calls: its arrays as parts of one buffer
    at the offsets ``at`` (a :class:`BufferParts` as a plain tuple), the state and the reference
    as plain tuples and floats. Plain arguments because a compiled call types each argument from
    Python: a tuple in C, a named tuple through Python (microseconds a call); one buffer because
    each array argument is converted on its own. Returns the step as the autopilot reads it, a
    :class:`CascadeOutput`'s fields as a plain tuple (``CascadeOutput._make``: compiled code boxes
    a named tuple for Python at several times the cost of a tuple)."""
    buf = borrowed(buf)  # the caller's for the call: its parts are passed on without counting
    a = BufferParts(at[0], at[1], at[2], at[3], at[4], at[5], at[6], at[7], at[8])
    memory = CascadeMemory(
        buf[a.numbers : a.translational_gains], buf[a.translational_gains : a.translational_state],
        buf[a.translational_state : a.rotational_gains], buf[a.rotational_gains : a.rotational_state],
        buf[a.rotational_state : a.filter_state], buf[a.filter_state : a.given], buf[a.given : a.out],
    )  # fmt: skip
    state = StateEstimate(position, velocity, euler, euler_rates)
    reference = Reference(ref_position, ref_velocity, ref_acceleration, yaw, yaw_rate, yaw_acceleration)
    out = buf[a.out : a.end]
    o = cascade_step(translational, rotational, memory, state, reference, integrate, out)
    return CascadeOutput(o.thrust, o.torque_euler, o.torque_body, (out[0], out[1], out[2], out[3]),
                         (out[4], out[5], out[6], out[7]), o.euler_ref, o.euler_rate_ref, o.roll_pitch_raw,
                         o.acceleration_cmd)[:]  # fmt: skip


class AttitudeReference(NamedTuple):
    """What the rotational law tracks: eta_d, eta_d', eta_d'' (ZYX Euler, paper frames)."""

    euler_rad: Vector3
    euler_rates_rad_s: Vector3
    euler_accelerations_rad_s2: Vector3


_make_output = CascadeOutput._make


def law_context(controller: ControllerConfig, vehicle: VehicleConfig, dt: float) -> LawContext:
    """What a law is built from besides its gains: the nominal vehicle's mass, gravity, inertia and
    arm, the actuation's limits and the control period ``dt`` (s)."""
    nominal, actuation = vehicle.nominal, vehicle.actuation
    return LawContext(
        mass_kg=nominal.mass_kg, gravity_m_s2=nominal.gravity_m_s2, inertia_kg_m2=nominal.inertia_kg_m2,
        arm_length_m=nominal.arm_length_m, thrust_max_n=actuation.thrust_max_n,
        torque_max_n_m=actuation.torque_max_n_m, tilt_max_rad=controller.tilt_max_rad, dt_s=dt,
    )  # fmt: skip


def cascade_numbers(controller: ControllerConfig, vehicle: VehicleConfig, dt: float) -> tuple[float, ...]:
    """The cascade's own numbers (layout :data:`CASCADE_NUMBERS`)."""
    f = controller.command_filter
    rotors = 1.0 if vehicle.actuation.mode == "rotors" else 0.0
    filter_numbers = cf.discretise(f.natural_frequency_rad_s, f.damping, dt, f.enabled)
    return (dt, rotors, *filter_numbers, *actuator_numbers(vehicle))


class Packed(NamedTuple):
    """A controller config as numbers: its two law classes, their context and gains arrays, and
    the cascade's own numbers (layout :data:`CASCADE_NUMBERS`)."""

    translational: type
    rotational: type
    context: LawContext
    K: tuple[float, ...]
    gt: tuple[float, ...]
    gr: tuple[float, ...]


def pack(controller: ControllerConfig, vehicle: VehicleConfig, dt: float) -> Packed:
    """``controller`` on ``vehicle`` at the control period ``dt``, checked (:func:`registry.check`)."""
    context = law_context(controller, vehicle, dt)
    translational = registry.law(TRANSLATIONAL, controller.translational.law)
    rotational = registry.law(ROTATIONAL, controller.rotational.law)
    return Packed(translational, rotational, context, cascade_numbers(controller, vehicle, dt),
                  registry.check(TRANSLATIONAL, translational, controller.translational, context),
                  registry.check(ROTATIONAL, rotational, controller.rotational, context))  # fmt: skip


class Cascade:
    """A controller config flying: its laws' gains and states, the command filter's state, and the
    step entry (compiled with the two laws where numba compiles)."""

    def __init__(self, controller: ControllerConfig, vehicle: VehicleConfig, dt: float) -> None:
        self.config = controller
        self.name = controller.name
        self.dt = dt
        self.vehicle = vehicle
        packed = pack(controller, vehicle, dt)
        self.translational, self.rotational = packed.translational, packed.rotational
        self.context = packed.context
        # One buffer, and views of its parts (buffered_step): the cascade's numbers, the laws' gains and
        # states, the filter's state, the overrides given, the outputs.
        sizes = (CASCADE_NUMBERS.size, len(packed.gt), len(self.translational.STATE), len(packed.gr),
                 len(self.rotational.STATE), cf.FILTER_STATE.size, GIVEN.size, OUT_SIZE)  # fmt: skip
        self._at = BufferParts(*(int(v) for v in np.cumsum((0, *sizes))))
        self._at_tuple = tuple(self._at)  # (the entry's argument: a plain tuple, see buffered_step)
        self.buffer = np.zeros(self._at.end)
        self.K[:], self.gt[:], self.gr[:] = packed.K, packed.gt, packed.gr
        self._last: tuple[Vector3, Vector3] | None = None  # (eta, eta') of the latest step: for retune
        self._overridden = False
        self._step = _entry(self)

    # -- the buffer's parts (views taken when asked: a copy of the cascade keeps them its own) --
    @property
    def K(self) -> np.ndarray:
        """The cascade's own numbers (:data:`CASCADE_NUMBERS`)."""
        return self.buffer[self._at.numbers : self._at.translational_gains]

    @property
    def gt(self) -> np.ndarray:
        """The translational law's gains."""
        return self.buffer[self._at.translational_gains : self._at.translational_state]

    @property
    def xt(self) -> np.ndarray:
        """The translational law's state."""
        return self.buffer[self._at.translational_state : self._at.rotational_gains]

    @property
    def gr(self) -> np.ndarray:
        """The rotational law's gains."""
        return self.buffer[self._at.rotational_gains : self._at.rotational_state]

    @property
    def xr(self) -> np.ndarray:
        """The rotational law's state."""
        return self.buffer[self._at.rotational_state : self._at.filter_state]

    @property
    def filt(self) -> np.ndarray:
        """The command filter's state (command_filter.S_*)."""
        return self.buffer[self._at.filter_state : self._at.given]

    @property
    def given(self) -> np.ndarray:
        """The overrides given to the next step (:data:`GIVEN`)."""
        return self.buffer[self._at.given : self._at.out]

    @property
    def out(self) -> np.ndarray:
        """The last step's normalised commands, then its rotor speeds (allocation.OUT_SIZE)."""
        return self.buffer[self._at.out : self._at.end]

    # -- stepping ---------------------------------------------------------------------------------
    def step(
        self,
        state: StateEstimate,
        ref: Reference,
        integrate: bool = True,
        *,
        roll_pitch: tuple[float, float] | None = None,
        attitude: AttitudeReference | None = None,
        thrust_n: float | None = None,
    ) -> CascadeOutput:
        """One control step towards ``ref``; the laws' states advance by ``dt`` if ``integrate``.

        The manual modes fly the same loops with parts of the chain given instead of computed:
        ``roll_pitch`` replaces the translational law's (phi_r, theta_r) before the command filter
        (STABILIZED, ALTCTL: the sticks' tilt); ``attitude`` replaces the filter's (eta_d, eta_d',
        eta_d'') whole, yaw included (ACRO: the attitude the sticks' rates integrate); ``thrust_n``
        replaces the translational law's U1 (STABILIZED, ACRO: the throttle), saturated as any U1.
        The translational law still runs (its states follow ``integrate``); the rotational law
        tracks whatever reaches it.

        A law that raises or gives a non-finite output raises :class:`ControllerFailure`.
        """
        overridden = roll_pitch is not None or attitude is not None or thrust_n is not None
        if overridden:
            given, flags = self.given, 0
            if roll_pitch is not None:
                flags += OVERRIDE_ROLL_PITCH
                given[GIVEN.roll_pitch : GIVEN.roll_pitch + 2] = roll_pitch
            if attitude is not None:
                flags += OVERRIDE_ATTITUDE
                given[GIVEN.attitude : GIVEN.attitude + 9] = [v for part in attitude for v in part]
            if thrust_n is not None:
                flags += OVERRIDE_THRUST
                given[GIVEN.thrust] = thrust_n
            given[GIVEN.flags] = flags
        elif self._overridden:
            self.given[GIVEN.flags] = 0.0
        self._overridden = overridden
        try:
            o = _make_output(self._step(
                self.buffer, self._at_tuple, state.position_m, state.velocity_m_s, state.euler_rad,
                state.euler_rates_rad_s, ref.position_m, ref.velocity_m_s, ref.acceleration_m_s2, ref.yaw_rad,
                ref.yaw_rate_rad_s, ref.yaw_acceleration_rad_s2, integrate,
            ))
        except Exception as error:  # noqa: BLE001 - a law (maybe a user's) failed: the failsafe acts
            raise ControllerFailure(f"controller {self.name}: {type(error).__name__}: {error}") from error
        if not output_finite(o.thrust_n, o.torque_body_n_m):
            reason = f"{non_finite_output(self.name)} (U1 {o.thrust_n}, tau {o.torque_body_n_m})"
            raise ControllerFailure(reason)
        self._last = (state.euler_rad, state.euler_rates_rad_s)
        return o

    def law_states(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        """The laws' states now, named (``translational.<name>``, ``rotational.<name>``), for logs."""
        names = (*(f"translational.{n}" for n in self.translational.STATE),
                 *(f"rotational.{n}" for n in self.rotational.STATE))  # fmt: skip
        return names, (*(float(v) for v in self.xt), *(float(v) for v in self.xr))

    # -- state ------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Zero the laws' states and re-initialise the command filter (disarmed / on the ground)."""
        for buffer in (self.xt, self.xr, self.filt):
            buffer[:] = [0.0] * len(buffer)

    def retune(self, controller: ControllerConfig) -> None:
        """Switch to the gains of ``controller`` (same laws) between two steps.

        Each law with a ``retune`` maps its state so that its action stays continuous (no jump in
        U1 or tau from its integrals); the command filter keeps its state with its new
        coefficients. Laws cannot change in flight (ValueError).
        """
        old = self.config
        if (controller.translational.law != old.translational.law
                or controller.rotational.law != old.rotational.law):  # fmt: skip
            raise ValueError("retune keeps the laws; a different cascade needs a restart")
        packed = pack(controller, self.vehicle, self.dt)
        context = packed.context
        euler, rates = self._last if self._last is not None else (None, None)
        changes = ((self.translational, self.xt, old.translational, controller.translational),
                   (self.rotational, self.xr, old.rotational, controller.rotational))  # fmt: skip
        for law, x, before, after in changes:
            retune = getattr(law, "retune", None)
            if retune is not None and len(x):
                x[:] = [float(v) for v in retune(before, after, context, [float(v) for v in x], euler, rates)]
        self.gt[:], self.gr[:], self.K[:] = packed.gt, packed.gr, packed.K
        self.config, self.context = controller, context


def not_compiled(laws: str, error: Exception) -> str:
    """Why the law pair ``laws`` did not compile: the cause numba found (file, line, what it could
    not type: :func:`quadcommon.kernel.typing_error_cause`), else the start of its error."""
    cause = typing_error_cause(error) or "\n".join(str(error).strip().splitlines()[:12])
    return (f"the laws {laws} do not compile with numba ({type(error).__name__}):\n{cause}\n"
            "(QUADSITL_PURE_PYTHON=1 runs them as Python, slower)")  # fmt: skip


def _entry(cascade: Cascade):
    """The step of ``cascade``'s law pair: compiled once per process (loaded from numba's cache
    after the first time), warmed up on a copy of the cascade's buffer at hover so nothing compiles
    in the middle of a flight, then frozen."""
    step = compiled(buffered_step, cascade.translational.step, cascade.rotational.step)
    if compiling() and not getattr(step, "_quadsitl_warm", False):
        z3, up = (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)
        try:
            step(cascade.buffer.copy(), cascade._at_tuple, up, z3, z3, z3, up, z3, z3, 0.0, 0.0, 0.0, True)
        except Exception as error:  # numba's typing errors: a law it cannot compile
            laws = f"{cascade.translational.NAME} + {cascade.rotational.NAME}"
            raise ConfigError(not_compiled(laws, error)) from error
        freeze(step)
        step._quadsitl_warm = True
    return step
