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
    def __init__(self, controller: ControllerConfig, vehicle: VehicleConfig, dt: float) -> None:
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

    def retune(self, controller: ControllerConfig) -> None:
        """Switch to the gains of ``controller`` (same laws) between two steps.

        Each law rescales its integral states so that the integral action's contribution to its
        output is unchanged at the moment of the change (no jump in U1 or tau from the integrals);
        the command filter keeps its state. Laws cannot change in flight (ValueError).
        """
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

    def reset(self) -> None:
        """Zero every integral and re-initialise the command filter (disarmed / on the ground)."""
        self.translational.reset()
        self.rotational.reset()
        self.filter.reset()

    def step(self, state: StateEstimate, ref: Reference, integrate: bool = True) -> CascadeOutput:
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
        raw = (outer.roll_ref_rad, outer.pitch_ref_rad)
        (phi_d, phi_d_dot, phi_d_ddot), (theta_d, theta_d_dot, theta_d_ddot) = self.filter.outputs(raw)
        self.filter.advance(raw)
        eta_d = (phi_d, theta_d, ref.yaw_rad)
        eta_d_dot = (phi_d_dot, theta_d_dot, ref.yaw_rate_rad_s)
        eta_d_ddot = (phi_d_ddot, theta_d_ddot, ref.yaw_acceleration_rad_s2)
        tau_eta = self.rotational.update(
            euler, state.euler_rates_rad_s, eta_d, eta_d_dot, eta_d_ddot, dt, integrate
        )
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
