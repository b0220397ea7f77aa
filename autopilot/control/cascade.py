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
from typing import NamedTuple

import numpy as np

from quadcommon.config import VehicleConfig
from quadcommon.kernel import borrowed, compiled, compiling, freeze, kernel, typing_error_cause
from quadcommon.rigid_body import body_rates_from_euler_rates, euler_torque_from_body_torque
from quadcommon.schema import ConfigError
from quadcommon.trajectories import Reference

from ..records import StateEstimate
from . import command_filter as cf
from . import registry
from .allocation import A_SIZE, OUT_SIZE, actuator_numbers, allocate_rotors, saturate_wrench
from .config import ControllerConfig
from .registry import ROTATIONAL, TRANSLATIONAL, ControllerFailure, LawContext, non_finite_output

Vector3 = tuple[float, float, float]

# The cascade's own numbers: the control period, wrench (0.0) or rotors (1.0), the command filter's
# coefficients (command_filter.F_*), the actuators' numbers (allocation.A_*).
K_DT, K_ROTORS, K_FILTER = 0, 1, 2
K_ACTUATORS = K_FILTER + cf.F_SIZE
K_SIZE = K_ACTUATORS + A_SIZE
# What a step may be given instead of computing it (flags, added up).
OVERRIDE_ROLL_PITCH, OVERRIDE_ATTITUDE, OVERRIDE_THRUST = 1, 2, 4
# What a step returns, in order.
OUTPUTS = (
    "thrust", "tau_eta_x", "tau_eta_y", "tau_eta_z", "tau_x", "tau_y", "tau_z",
    "phi_d", "theta_d", "psi_d", "phi_d_dot", "theta_d_dot", "psi_d_dot", "phi_r", "theta_r",
    "a_x", "a_y", "a_z", "saturated", "tilt_limited",
)  # fmt: skip


@kernel
def cascade_step(translational, rotational, K, gt, xt, gr, xr, filt, position, velocity, euler, euler_rates,
                 ref_position, ref_velocity, ref_acceleration, yaw, yaw_rate, yaw_acceleration, integrate,
                 override, roll_pitch, attitude, thrust_given, out):  # fmt: skip
    """One step of the cascade (module docstring) with the laws ``translational`` and ``rotational``
    (their step kernels), their gains ``gt``, ``gr`` and states ``xt``, ``xr``; the command filter's
    state ``filt``. Normalised commands and rotor speeds go into ``out`` (allocation.OUT_SIZE);
    returns the numbers named by :data:`OUTPUTS`."""
    dt = K[K_DT]
    thrust, roll_r, pitch_r, a_x, a_y, a_z, thrust_limited, tilt_limited = translational(
        gt, xt, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, yaw, dt, integrate
    )
    if override & OVERRIDE_ROLL_PITCH:
        roll_r, pitch_r = roll_pitch[0], roll_pitch[1]
    phi_d, theta_d, phi_d_dot, theta_d_dot, phi_d_ddot, theta_d_ddot = cf.advance(K, K_FILTER, filt, roll_r,
                                                                                 pitch_r)  # fmt: skip
    eta_d = (phi_d, theta_d, yaw)
    eta_d_dot = (phi_d_dot, theta_d_dot, yaw_rate)
    eta_d_ddot = (phi_d_ddot, theta_d_ddot, yaw_acceleration)
    if override & OVERRIDE_ATTITUDE:
        eta_d = (attitude[0], attitude[1], attitude[2])
        eta_d_dot = (attitude[3], attitude[4], attitude[5])
        eta_d_ddot = (attitude[6], attitude[7], attitude[8])
    if override & OVERRIDE_THRUST:
        thrust = thrust_given
    body_rates = body_rates_from_euler_rates(euler[0], euler[1], euler_rates)
    tx, ty, tz = rotational(gr, xr, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt,
                            integrate)  # fmt: skip
    if K[K_ROTORS] != 0.0:
        thrust_a, ta0, ta1, ta2, saturated = allocate_rotors(K, K_ACTUATORS, thrust, tx, ty, tz, out)
    else:
        thrust_a, ta0, ta1, ta2, saturated = saturate_wrench(K, K_ACTUATORS, thrust, tx, ty, tz, out)
    te0, te1, te2 = euler_torque_from_body_torque(euler[0], euler[1], (ta0, ta1, ta2))
    return (thrust_a, te0, te1, te2, ta0, ta1, ta2, eta_d[0], eta_d[1], eta_d[2], eta_d_dot[0], eta_d_dot[1],
            eta_d_dot[2], roll_r, pitch_r, a_x, a_y, a_z,
            1.0 if (saturated != 0.0 or thrust_limited != 0.0) else 0.0, tilt_limited)  # fmt: skip


@kernel
def output_finite(o):
    """False when the wrench a cascade step applies is not finite (``o``: :func:`cascade_step`'s
    outputs; U1 and the body torque): a NaN or inf anywhere in it shows in their sum (saturation
    lets NaN through). The one check of a law's output, wherever the cascade flies: the autopilot
    (:meth:`Cascade.step`) and the campaign engine (:func:`sitl.campaign.kernels.simulate`)."""
    return math.isfinite(o[0] + o[4] + o[5] + o[6])


# What a step is given instead of computing it (Cascade.step's overrides), as numbers: the flags
# (OVERRIDE_*, added up), roll and pitch, the attitude reference (eta_d, eta_d', eta_d''), U1.
V_FLAGS, V_ROLL_PITCH, V_ATTITUDE, V_THRUST = 0, 1, 3, 12
V_SIZE = 13


@kernel
def buffered_step(translational, rotational, buf, at, position, velocity, euler, euler_rates, ref_position,
                  ref_velocity, ref_acceleration, yaw, yaw_rate, yaw_acceleration, integrate):  # fmt: skip
    """:func:`cascade_step` with its arrays as parts of one buffer, at the offsets ``at`` (K, gt, xt,
    gr, xr, the filter's state, the overrides given (layout ``V_*``), out, end): a compiled call
    converts each array argument on its own, so one buffer costs one conversion instead of eight.
    Returns :data:`OUTPUTS` followed by ``out`` (the normalised commands and the rotor speeds)."""
    buf = borrowed(buf)  # the caller's for the call: its parts are passed on without counting
    v = buf[at[6] : at[7]]
    attitude = (v[V_ATTITUDE], v[V_ATTITUDE + 1], v[V_ATTITUDE + 2], v[V_ATTITUDE + 3], v[V_ATTITUDE + 4],
                v[V_ATTITUDE + 5], v[V_ATTITUDE + 6], v[V_ATTITUDE + 7], v[V_ATTITUDE + 8])  # fmt: skip
    out = buf[at[7] : at[8]]
    K, gt, xt = buf[at[0] : at[1]], buf[at[1] : at[2]], buf[at[2] : at[3]]
    gr, xr, filt = buf[at[3] : at[4]], buf[at[4] : at[5]], buf[at[5] : at[6]]
    roll_pitch = (v[V_ROLL_PITCH], v[V_ROLL_PITCH + 1])
    o = cascade_step(translational, rotational, K, gt, xt, gr, xr, filt, position, velocity, euler,
                     euler_rates, ref_position, ref_velocity, ref_acceleration, yaw, yaw_rate,
                     yaw_acceleration, integrate, int(v[V_FLAGS]), roll_pitch, attitude, v[V_THRUST], out)
    return o + (out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7])


class AttitudeReference(NamedTuple):
    """What the rotational law tracks: eta_d, eta_d', eta_d'' (ZYX Euler, paper frames)."""

    euler_rad: Vector3
    euler_rates_rad_s: Vector3
    euler_accelerations_rad_s2: Vector3


class CascadeOutput(NamedTuple):
    thrust_n: float  # applied U1
    torque_euler_n_m: Vector3  # applied tau_eta (tau_phi, tau_theta, tau_psi)
    torque_body_n_m: Vector3  # applied body torque
    actuator_controls: tuple[float, float, float, float]  # normalised, see allocation.py
    rotor_speeds_rad_s: tuple[float, float, float, float]  # commanded (rotors mode), else zeros
    euler_ref_rad: Vector3  # eta_d (filtered roll/pitch references, yaw reference)
    euler_rate_ref_rad_s: Vector3
    roll_pitch_raw_rad: tuple[float, float]  # phi_r, theta_r before the command filter
    acceleration_cmd_m_s2: Vector3


def law_context(controller: ControllerConfig, vehicle: VehicleConfig, dt: float) -> LawContext:
    nominal, actuation = vehicle.nominal, vehicle.actuation
    return LawContext(
        mass_kg=nominal.mass_kg, gravity_m_s2=nominal.gravity_m_s2, inertia_kg_m2=nominal.inertia_kg_m2,
        arm_length_m=nominal.arm_length_m, thrust_max_n=actuation.thrust_max_n,
        torque_max_n_m=actuation.torque_max_n_m, tilt_max_rad=controller.tilt_max_rad, dt_s=dt,
    )  # fmt: skip


def cascade_numbers(controller: ControllerConfig, vehicle: VehicleConfig, dt: float) -> tuple[float, ...]:
    """The cascade's own numbers (layout ``K_*``)."""
    f = controller.command_filter
    rotors = 1.0 if vehicle.actuation.mode == "rotors" else 0.0
    filter_numbers = cf.discretise(f.natural_frequency_rad_s, f.damping, dt, f.enabled)
    return (dt, rotors, *filter_numbers, *actuator_numbers(vehicle))


class Packed(NamedTuple):
    """A controller config as numbers: its two law classes, their context and gains arrays, and
    the cascade's own numbers (layout ``K_*``)."""

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
        sizes = (K_SIZE, len(packed.gt), len(self.translational.STATE), len(packed.gr),
                 len(self.rotational.STATE), cf.S_SIZE, V_SIZE, OUT_SIZE)  # fmt: skip
        self._at = tuple(int(v) for v in np.cumsum((0, *sizes)))
        self.buffer = np.zeros(self._at[-1])
        self.K, self.gt, self.xt, self.gr, self.xr, self.filt, self.given, self.out = (
            self.buffer[a:b] for a, b in zip(self._at[:-1], self._at[1:], strict=True)
        )
        self.K[:], self.gt[:], self.gr[:] = packed.K, packed.gt, packed.gr
        self._last: tuple[Vector3, Vector3] | None = None  # (eta, eta') of the latest step: for retune
        self._overridden = False
        self._step = _entry(self)

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
        given = self.given
        overridden = roll_pitch is not None or attitude is not None or thrust_n is not None
        if overridden:
            flags = 0
            if roll_pitch is not None:
                flags += OVERRIDE_ROLL_PITCH
                given[V_ROLL_PITCH : V_ROLL_PITCH + 2] = roll_pitch
            if attitude is not None:
                flags += OVERRIDE_ATTITUDE
                given[V_ATTITUDE : V_ATTITUDE + 9] = [v for part in attitude for v in part]
            if thrust_n is not None:
                flags += OVERRIDE_THRUST
                given[V_THRUST] = thrust_n
            given[V_FLAGS] = flags
        elif self._overridden:
            given[V_FLAGS] = 0.0
        self._overridden = overridden
        try:
            o = self._step(self.buffer, self._at, state.position_m, state.velocity_m_s, state.euler_rad,
                           state.euler_rates_rad_s, ref.position_m, ref.velocity_m_s, ref.acceleration_m_s2,
                           ref.yaw_rad, ref.yaw_rate_rad_s, ref.yaw_acceleration_rad_s2, integrate)
        except Exception as error:  # noqa: BLE001 - a law (maybe a user's) failed: the failsafe acts
            raise ControllerFailure(f"controller {self.name}: {type(error).__name__}: {error}") from error
        if not output_finite(o):
            raise ControllerFailure(f"{non_finite_output(self.name)} (U1 {o[0]}, tau {o[4:7]})")
        self._last = (state.euler_rad, state.euler_rates_rad_s)
        return CascadeOutput(
            o[0], (o[1], o[2], o[3]), (o[4], o[5], o[6]), (o[20], o[21], o[22], o[23]),
            (o[24], o[25], o[26], o[27]), (o[7], o[8], o[9]), (o[10], o[11], o[12]), (o[13], o[14]),
            (o[15], o[16], o[17]),
        )  # fmt: skip

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
            step(cascade.buffer.copy(), cascade._at, up, z3, z3, z3, up, z3, z3, 0.0, 0.0, 0.0, True)
        except Exception as error:  # numba's typing errors: a law it cannot compile
            laws = f"{cascade.translational.NAME} + {cascade.rotational.NAME}"
            raise ConfigError(not_compiled(laws, error)) from error
        freeze(step)
        step._quadsitl_warm = True
    return step
