"""The control cascade: translational law -> command filter -> attitude law -> actuators.

Cascades are selected by name (``config/controllers/NAME.toml``): ``intbs_nlhinf`` (the
paper's), ``intbs`` (integral in the first step, both loops), ``bs_nlhinf`` (no integral); the
laws themselves are looked up by name (:mod:`.registry`, ``laws/``). Pure: one
:meth:`Cascade.step` per control period, driven by whoever owns the clock.

The attitude laws produce the generalised torque tau_eta of eq. (4); the actuators produce a
body torque, ``tau_body = W_eta^-T tau_eta``, which is what is saturated (or allocated to the
rotors). The torque reported back (for logs and the IADU index) is the applied one, mapped
back to the Euler coordinates.
"""

from __future__ import annotations

from typing import NamedTuple

from quadcommon.config import VehicleConfig
from quadcommon.rigid_body import body_torque_from_euler_torque, euler_torque_from_body_torque
from quadcommon.trajectories import Reference

from . import registry
from .allocation import Allocator
from .command_filter import SecondOrderFilter
from .config import ControllerConfig
from .translational import TranslationalController

Vector3 = tuple[float, float, float]


class StateEstimate(NamedTuple):
    """What the controllers see (paper frames): position/velocity of O, Euler angles and rates."""

    position_m: Vector3
    velocity_m_s: Vector3
    euler_rad: Vector3
    euler_rates_rad_s: Vector3


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


class Cascade:
    """``compiled=True``: step with :mod:`.compiled` where it can (numba installed, the built-in laws,
    wrench actuation, integrating), bit for bit the same as the Python laws; the autopilot asks
    for it. The laws' state then lives in the kernel's arrays between steps and is copied back to
    the Python law objects before anything else reads or changes them (retune, reset, a
    non-integrating step)."""

    def __init__(
        self, controller: ControllerConfig, vehicle: VehicleConfig, dt: float, compiled: bool = False
    ) -> None:
        self.config = controller
        self.name = controller.name
        self.dt = dt
        nominal = vehicle.nominal
        self.rotor_mode = vehicle.actuation.mode == "rotors"
        tr_law = registry.law(registry.TRANSLATIONAL, controller.translational.law)
        rot_law = registry.law(registry.ROTATIONAL, controller.rotational.law)
        self.translational = TranslationalController(
            tr_law(controller.translational, nominal), nominal, vehicle.actuation.thrust_max_n,
            controller.tilt_max_rad,
        )  # fmt: skip
        self.rotational = rot_law(controller.rotational, nominal)
        if hasattr(self.rotational, "set_integral_limit"):  # anti-windup at the actuators' limit
            self.rotational.set_integral_limit(vehicle.actuation.torque_max_n_m)
        self.filter = SecondOrderFilter(controller.command_filter, dt, channels=2)
        self.allocator = Allocator(vehicle)
        self._kernel = _CompiledCascade.for_cascade(self) if compiled else None

    def retune(self, controller: ControllerConfig) -> None:
        """Switch to the gains of ``controller`` (same laws) between two steps.

        Each law rescales its integral states so that the integral action's contribution to its
        output is unchanged at the moment of the change (no jump in U1 or tau from the integrals);
        the command filter keeps its state. Laws cannot change in flight (ValueError).
        """
        kernel = self._kernel
        if kernel is not None:
            kernel.pull(self)
        old = self.config
        if (
            controller.translational.law != old.translational.law
            or controller.rotational.law != old.rotational.law
        ):
            raise ValueError("retune keeps the laws; a different cascade needs a restart")
        self.translational.law.retune(controller.translational)
        self.translational.set_tilt_max(controller.tilt_max_rad)
        self.rotational.retune(controller.rotational)
        self.filter.retune(controller.command_filter)
        self.config = controller
        if kernel is not None:
            kernel.push(self, new_gains=True)

    def reset(self) -> None:
        """Zero every integral and re-initialise the command filter (disarmed / on the ground)."""
        self.translational.reset()
        self.rotational.reset()
        self.filter.reset()
        if self._kernel is not None:
            self._kernel.push(self)

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

        The manual modes fly the same loops with parts of the cascade's chain given instead of
        computed: ``roll_pitch`` replaces the translational law's (phi_r, theta_r) before the
        command filter (STABILIZED, ALTCTL: the sticks' tilt); ``attitude`` replaces the filter's
        (eta_d, eta_d', eta_d'') whole, yaw included (ACRO: the attitude the sticks' rates
        integrate); ``thrust_n`` replaces the translational law's U1 (STABILIZED, ACRO: the
        throttle), saturated as any U1. The translational law still runs (its integrals follow
        ``integrate``); the rotational law always tracks what reaches it.
        """
        kernel = self._kernel
        overridden = roll_pitch is not None or attitude is not None or thrust_n is not None
        if kernel is None:
            return self._step(state, ref, integrate, roll_pitch, attitude, thrust_n)
        if integrate and not overridden:
            out = kernel.step(state, ref)
            if out is not None:
                return out
        kernel.pull(self)
        out = self._step(state, ref, integrate, roll_pitch, attitude, thrust_n)
        kernel.push(self)
        return out

    def law_states(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        """The laws' internal states now, named (``translational.<name>``, ``rotational.<name>``):
        the integrals, for logs. Read between steps."""
        if self._kernel is not None:
            self._kernel.pull(self)
            self._kernel.push(self)
        tr = tuple(self.translational.integral)
        rot = tuple(self.rotational.integral)
        names = tuple(f"translational.integral_{a}" for a in "xyz") + tuple(
            f"rotational.integral_{a}" for a in ("roll", "pitch", "yaw")
        )
        return names, tr + rot

    def _step(
        self,
        state: StateEstimate,
        ref: Reference,
        integrate: bool,
        roll_pitch: tuple[float, float] | None = None,
        attitude: AttitudeReference | None = None,
        thrust_n: float | None = None,
    ) -> CascadeOutput:
        """The specification: the Python laws, one step."""
        dt = self.dt
        euler = state.euler_rad
        outer = self.translational.update(
            state.position_m,
            state.velocity_m_s,
            euler,
            ref.position_m,
            ref.velocity_m_s,
            ref.acceleration_m_s2,
            dt,
            integrate,
        )
        raw = (outer.roll_ref_rad, outer.pitch_ref_rad) if roll_pitch is None else tuple(roll_pitch)
        (phi_d, phi_d_dot, phi_d_ddot), (theta_d, theta_d_dot, theta_d_ddot) = self.filter.outputs(raw)
        self.filter.advance(raw)
        eta_d = (phi_d, theta_d, ref.yaw_rad)
        eta_d_dot = (phi_d_dot, theta_d_dot, ref.yaw_rate_rad_s)
        eta_d_ddot = (phi_d_ddot, theta_d_ddot, ref.yaw_acceleration_rad_s2)
        if attitude is not None:
            eta_d, eta_d_dot, eta_d_ddot = attitude
        tau_eta = self.rotational.update(
            euler, state.euler_rates_rad_s, eta_d, eta_d_dot, eta_d_ddot, dt, integrate
        )
        if thrust_n is not None:
            outer = outer._replace(thrust_n=thrust_n)
        phi, theta = euler[0], euler[1]
        tau_body = body_torque_from_euler_torque(phi, theta, tau_eta)
        if self.rotor_mode:
            alloc = self.allocator.to_rotors(outer.thrust_n, tau_body)
            thrust, tau_applied = alloc.thrust_n, alloc.torque_body_n_m
            controls, speeds = alloc.normalised, alloc.speeds_rad_s
        else:
            thrust, tau_applied = self.allocator.saturate_wrench(outer.thrust_n, tau_body)
            controls = self.allocator.wrench_to_normalised(thrust, tau_applied)
            speeds = (0.0, 0.0, 0.0, 0.0)
        return CascadeOutput(
            thrust_n=thrust,
            torque_euler_n_m=euler_torque_from_body_torque(phi, theta, tau_applied),
            torque_body_n_m=tau_applied,
            actuator_controls=controls,  # type: ignore[arg-type]
            rotor_speeds_rad_s=speeds,
            euler_ref_rad=eta_d,
            euler_rate_ref_rad_s=eta_d_dot,
            roll_pitch_raw_rad=raw,
            acceleration_cmd_m_s2=outer.acceleration_cmd_m_s2,
        )


_ZERO4 = (0.0, 0.0, 0.0, 0.0)


class _CompiledCascade:
    """The kernel's arrays for one Cascade (:func:`.compiled.cascade_step`) and the copies of the
    laws' state between them and the Python law objects."""

    @classmethod
    def for_cascade(cls, cascade: Cascade) -> _CompiledCascade | None:
        """None where the Python laws fly: numba absent, QUADSITL_PURE_PYTHON=1, a law the kernels
        do not have (the registry's), the rotor actuation."""
        if cascade.rotor_mode:
            return None
        try:
            from . import compiled
        except ImportError:  # numba is in the campaign extra
            return None
        if not compiled.enabled() or not compiled.supports(cascade):
            return None
        return cls(cascade, compiled)

    def __init__(self, cascade: Cascade, compiled) -> None:
        import numpy as np

        self._compiled = compiled
        self.C = compiled.controller_array(cascade)
        self.integ_t, self.integ_r, self.filt = np.zeros(3), np.zeros(3), np.zeros(compiled.F_SIZE)
        self.stale = False  # the arrays are ahead of the Python laws
        self.last_state: tuple[Vector3, Vector3] | None = None
        # Load (or compile) the kernel now, on scratch arrays, not at the first step in flight; then
        # no compiling in the middle of a flight: numba converts what it can to this signature (an
        # int among the floats), and anything it cannot takes the Python laws (TypeError).
        z3 = (0.0, 0.0, 0.0)
        compiled.cascade_step(self.C.copy(), np.zeros(3), np.zeros(3), np.zeros(compiled.F_SIZE),
                              z3, z3, z3, z3, z3, z3, z3, 0.0, 0.0, 0.0)  # fmt: skip
        compiled.cascade_step.disable_compile()
        self._step = compiled.cascade_step
        self.push(cascade)

    def push(self, cascade: Cascade, new_gains: bool = False) -> None:
        """The Python laws' state (and, after a retune, their gains) into the arrays."""
        if new_gains:
            self.C = self._compiled.controller_array(cascade)
        self.integ_t[:] = cascade.translational.law.integral
        self.integ_r[:] = cascade.rotational.integral
        f = cascade.filter
        self.filt[0:2] = f.value
        self.filt[2:4] = f.rate
        self.filt[4] = 1.0 if f.initialised else 0.0
        self.stale = False

    def pull(self, cascade: Cascade) -> None:
        """The arrays' state back into the Python laws (before they are read or changed)."""
        if not self.stale:
            return
        cascade.translational.law.integral = self.integ_t.tolist()
        rot = cascade.rotational
        if rot.NAME == "nlhinf" and rot.k_p == 0.0:  # the Python law does not integrate then
            rot.integral = [0.0, 0.0, 0.0]
        else:
            rot.integral = self.integ_r.tolist()
        if self.last_state is not None and hasattr(rot, "_last_state"):
            rot._last_state = self.last_state
        f = cascade.filter
        f.value, f.rate, f.initialised = self.filt[0:2].tolist(), self.filt[2:4].tolist(), self.filt[4] == 1.0
        self.stale = False

    def step(self, state: StateEstimate, ref: Reference) -> CascadeOutput | None:
        """One integrating step in the kernel; None if numba cannot take its arguments."""
        try:
            o = self._step(self.C, self.integ_t, self.integ_r, self.filt, state.position_m,
                           state.velocity_m_s, state.euler_rad, state.euler_rates_rad_s, ref.position_m,
                           ref.velocity_m_s, ref.acceleration_m_s2, ref.yaw_rad, ref.yaw_rate_rad_s,
                           ref.yaw_acceleration_rad_s2)  # fmt: skip
        except TypeError:
            return None
        self.stale = True
        self.last_state = (state.euler_rad, state.euler_rates_rad_s)
        return CascadeOutput(
            o[0], (o[1], o[2], o[3]), (o[4], o[5], o[6]), (o[7], o[8], o[9], o[10]), _ZERO4,
            (o[11], o[12], ref.yaw_rad), (o[13], o[14], ref.yaw_rate_rad_s), (o[15], o[16]),
            (o[17], o[18], o[19]),
        )  # fmt: skip
