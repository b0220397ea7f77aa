"""The nominal Section II model as a plant: eqs. (1)-(6) integrated in ``(xi, xi', eta, eta')``.

The model the controllers are designed on (``plant.model = "nominal"``), for checking them against
their own assumptions; the simulator's default is the coupled plant of :mod:`.plant`. Same inputs
and read-outs as that plant under ``actuation = "wrench"``. Pure: no clocks, no I/O.
"""

from __future__ import annotations

from quadcommon.config import VehicleConfig
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

from .plant import ZERO3, Plant, TruthState, Vector3


class NominalPlant:
    """The Section II model, eqs. (1)-(6), integrated in ``(xi, xi_dot, eta, eta_dot)`` by RK4.

    Inputs are the same as :class:`Plant` under ``actuation = "wrench"``: thrust and a body
    torque, whose generalised torque on the Euler coordinates is ``W_eta^T tau_body``.
    """

    def __init__(self, vehicle: VehicleConfig, physics_dt_s: float) -> None:
        if vehicle.actuation.mode != "wrench":
            raise ValueError("the nominal Section II plant takes actuation = 'wrench' only")
        self.vehicle = vehicle
        self.dt = physics_dt_s
        self.mass = vehicle.plant.mass_kg
        self.gravity = vehicle.nominal.gravity_m_s2
        self.inertia_diag = vehicle.plant.inertia_kg_m2
        self.thrust_max = vehicle.actuation.thrust_max_n
        self.torque_max = vehicle.actuation.torque_max_n_m
        self.ground_contact = vehicle.plant.ground_contact
        self.thrust_cmd = 0.0
        self.torque_cmd: Vector3 = ZERO3
        self.force_dist: Vector3 = ZERO3
        self.torque_dist_eta: Vector3 = ZERO3
        self.wind: Vector3 = ZERO3
        self.state: list[float] = [0.0] * 12

    set_wrench = Plant.set_wrench
    set_actuator_controls = Plant.set_actuator_controls
    set_disturbance = Plant.set_disturbance
    rotor_mode = False

    def advance(self, disturbances) -> None:
        """:meth:`Plant.advance`'s contract, one :meth:`step` at a time."""
        for force, torque, wind in disturbances:
            self.set_disturbance(force, torque, wind)
            self.step()

    def set_rotor_commands(self, speeds_rad_s: tuple[float, float, float, float]) -> None:
        """Refused (ValueError): the nominal plant is driven by thrust and torque, it has no rotors."""
        raise ValueError("the nominal plant has no rotors")

    def reset(
        self,
        position_m: Vector3,
        euler_rad: Vector3,
        velocity_m_s: Vector3 = ZERO3,
        body_rates_rad_s: Vector3 = ZERO3,
    ) -> None:
        """Place the vehicle at ``position_m`` (world, z up) with ZYX Euler angles ``euler_rad``, world
        velocity ``velocity_m_s`` and body (FLU) rates ``body_rates_rad_s``, converted to Euler rates
        (eq. (3))."""
        eta_dot = euler_rates_from_body_rates(euler_rad[0], euler_rad[1], body_rates_rad_s)
        self.state = [*position_m, *velocity_m_s, *euler_rad, *eta_dot]

    def derivative(self, s: list[float]) -> list[float]:
        """The state derivative of ``s = (xi, xi_dot, eta, eta_dot)`` (world m, m/s; ZYX Euler rad,
        rad/s) under the commanded thrust and torque and the disturbances: eq. (2) for the translation,
        eq. (4) ``M(eta) eta_ddot + C(eta, eta_dot) eta_dot = tau`` for the rotation."""
        m, g = self.mass, self.gravity
        phi, theta, psi = s[6], s[7], s[8]
        eta = (phi, theta, psi)
        eta_dot = (s[9], s[10], s[11])
        U1 = self.thrust_cmd
        fx, fy, fz = self.force_dist
        # eq. (2): m xi'' = R e3 U1 + F_d - m g e3 (R e3: the last column of R)
        R = rotation_matrix(phi, theta, psi)
        ax = (R[0][2] * U1 + fx) / m
        ay = (R[1][2] * U1 + fy) / m
        az = -g + (R[2][2] * U1 + fz) / m
        # eq. (4): M eta_ddot + C eta_dot = tau_eta_a + tau_eta_d
        tau_ctrl = euler_torque_from_body_torque(phi, theta, self.torque_cmd)
        rhs_c = coriolis_times(self.inertia_diag, eta, eta_dot, eta_dot)
        td = self.torque_dist_eta
        rhs = tuple(tau_ctrl[i] + td[i] - rhs_c[i] for i in range(3))
        eta_ddot = solve3(inertia_matrix(self.inertia_diag, phi, theta), rhs)
        return [s[3], s[4], s[5], ax, ay, az, *eta_dot, *eta_ddot]

    def step(self) -> None:
        """Advance the state by one physics step ``dt`` with classical RK4; with ground contact, a
        vehicle at or below z = 0 and not climbing is put on the ground, level and at rest."""
        f = self.derivative
        s = self.state
        h = self.dt
        k1 = f(s)
        k2 = f([a + 0.5 * h * b for a, b in zip(s, k1, strict=True)])
        k3 = f([a + 0.5 * h * b for a, b in zip(s, k2, strict=True)])
        k4 = f([a + h * b for a, b in zip(s, k3, strict=True)])
        self.state = [
            a + h / 6.0 * (b1 + 2.0 * (b2 + b3) + b4)
            for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4, strict=True)
        ]
        if self.ground_contact and self.state[2] <= 0.0 and self.state[5] <= 0.0:
            s = self.state
            s[2] = 0.0
            s[3:6] = [0.0, 0.0, 0.0]
            s[6], s[7] = 0.0, 0.0
            s[9:12] = [0.0, 0.0, 0.0]

    def kinematics(self) -> tuple[Vector3, Vector3, Vector3, Vector3]:
        """Position (m), velocity (m/s) in the world frame (z up), ZYX Euler angles (rad) and their
        rates (rad/s)."""
        s = self.state
        return ((s[0], s[1], s[2]), (s[3], s[4], s[5]), (s[6], s[7], s[8]), (s[9], s[10], s[11]))

    def on_ground(self) -> bool:
        """Resting on the ground: contact enabled, at z = 0 and not moving vertically."""
        return self.ground_contact and self.state[2] <= 1e-9 and abs(self.state[5]) < 1e-9

    def truth(self) -> TruthState:
        """The current ground truth as a :class:`TruthState`: world position, velocity, acceleration (zero
        on the ground), attitude, body rates (eq. (3)), the specific force in the body (FLU, m/s^2), the
        commanded thrust and body torque; the rotor speeds are zero (no rotors)."""
        s = self.state
        ds = self.derivative(s)
        euler = (s[6], s[7], s[8])
        eta_dot = (s[9], s[10], s[11])
        R = rotation_matrix(*euler)
        w = body_rates_from_euler_rates(euler[0], euler[1], eta_dot)  # eq. (3)
        on_ground = self.on_ground()
        acc = ZERO3 if on_ground else (ds[3], ds[4], ds[5])
        specific = transpose_times(R, (acc[0], acc[1], acc[2] + self.gravity))
        return TruthState(
            position_m=(s[0], s[1], s[2]),
            velocity_m_s=(s[3], s[4], s[5]),
            acceleration_m_s2=acc,
            quaternion=quaternion_from_euler(*euler),
            euler_rad=euler,
            body_rates_rad_s=w,
            euler_rates_rad_s=eta_dot,
            specific_force_body_m_s2=specific,
            rotor_speeds_rad_s=(0.0, 0.0, 0.0, 0.0),
            thrust_n=self.thrust_cmd,
            torque_body_n_m=self.torque_cmd,
            on_ground=on_ground,
        )
