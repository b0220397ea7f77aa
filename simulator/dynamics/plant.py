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
  1 and 3 spin counter-clockwise seen from above), thrust ``b Omega^2``, reaction torque
  ``d Omega^2``, first-order speed dynamics towards the command, speed limits, gyroscopic moment
  ``J_r Omega_r (q, -p, 0)`` with ``Omega_r = -Omega1 + Omega2 - Omega3 + Omega4`` and the
  reaction to rotor acceleration ``J_r dOmega_r/dt`` about z;
* disturbances: a force in the world frame applied at G (the ``[Ax, Ay, Az]`` of eq. 1), torques
  on the Euler coordinates as in eq. (4), applied as the equivalent body couple
  ``W_eta^-T [Ap, Aq, Ar]``; wind enters through linear drag ``-k (v_O - wind)`` at G;
* ground contact (optional): the plane z = 0 under O; a vehicle pressed against it rests level.

Nominal plant (``plant.model = "nominal"``, :mod:`.nominal_plant`): eqs. (1)-(6) integrated in
``(xi, eta)``: the model the controllers are designed on, for checking them against their own
assumptions.

The per-step path uses plain floats (15x cheaper than small-array numpy here).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import NamedTuple

from quadcommon.config import VehicleConfig
from quadcommon.rigid_body import (
    euler_from_rotation,
    euler_rates_from_body_rates,
    quaternion_from_euler,
    rotation_from_quaternion,
)

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)


class TruthState(NamedTuple):
    """Ground truth of the plant at one instant, in the paper's frames (SI units).

    Position, velocity and acceleration are those of the geometric centre O (where the vehicle's
    position is defined), in the world frame. ``specific_force_body`` is what an ideal
    accelerometer at O reads (body frame, m/s^2; +g upward at rest).

    (A NamedTuple, immutable: built once per frame, where a frozen dataclass's 12 fields cost
    1.4 us against 0.5 us.)
    """

    position_m: Vector3
    velocity_m_s: Vector3
    acceleration_m_s2: Vector3
    quaternion: tuple[float, float, float, float]  # (w, x, y, z), body to world
    euler_rad: Vector3
    body_rates_rad_s: Vector3
    euler_rates_rad_s: Vector3
    specific_force_body_m_s2: Vector3
    rotor_speeds_rad_s: tuple[float, float, float, float]
    thrust_n: float  # applied (saturated) total thrust
    torque_body_n_m: Vector3  # applied (saturated) control torque about O, body frame
    on_ground: bool


class Plant:
    """Coupled quadrotor integrated by RK4 at a fixed physics step."""

    def __init__(self, vehicle: VehicleConfig, physics_dt_s: float) -> None:
        if vehicle.plant.model != "coupled":
            raise ValueError("Plant integrates the coupled model; use NominalPlant for 'nominal'")
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
        self.inertia_inv = _inverse3(self.inertia)
        self.com_offset = plant.com_offset_m
        # O is |r_G| from G at most: with G higher than this above z = 0, O is in the air.
        self._ground_reach = math.sqrt(sum(c * c for c in plant.com_offset_m)) + 1e-3
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
        self._derivative = self._make_derivative()
        self.state: list[float] = []
        self.reset(ZERO3, ZERO3)
        self._compiled = _compiled_step(self)  # None: numba absent (or QUADSITL_PURE_PYTHON=1)
        self._truth: tuple[list[float], TruthState] | None = None  # advance()'s (state it is of, truth)

    # -- state ------------------------------------------------------------------------------------
    def reset(
        self,
        position_m: Vector3,
        euler_rad: Vector3,
        velocity_m_s: Vector3 = ZERO3,
        body_rates_rad_s: Vector3 = ZERO3,
    ) -> None:
        """Place O at ``position_m`` with the given attitude and motion; rotors at rest."""
        q = quaternion_from_euler(*euler_rad)
        R = rotation_from_quaternion(*q)
        rx, ry, rz = self.com_offset
        Rr = tuple(R[i][0] * rx + R[i][1] * ry + R[i][2] * rz for i in range(3))
        w = body_rates_rad_s
        wxr = (w[1] * rz - w[2] * ry, w[2] * rx - w[0] * rz, w[0] * ry - w[1] * rx)
        Rwxr = tuple(R[i][0] * wxr[0] + R[i][1] * wxr[1] + R[i][2] * wxr[2] for i in range(3))
        p_G = [position_m[i] + Rr[i] for i in range(3)]
        v_G = [velocity_m_s[i] + Rwxr[i] for i in range(3)]
        self.state = [*p_G, *v_G, *q, *w]
        if self.rotor_mode:
            self.state += [0.0, 0.0, 0.0, 0.0]

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
    def _make_derivative(self):  # noqa: C901 - one flat function is the fast form here
        """Build ``f(state) -> state_dot`` with every constant bound as a local (hot path)."""
        m = self.mass
        g = self.gravity
        (J00, J01, J02), (J10, J11, J12), (J20, J21, J22) = self.inertia
        (K00, K01, K02), (K10, K11, K12), (K20, K21, K22) = self.inertia_inv
        rx, ry, rz = self.com_offset
        kdx, kdy, kdz = self.drag
        has_drag = (kdx, kdy, kdz) != ZERO3
        b, d, arm, Jr, tau_r = self.b, self.d, self.arm, self.rotor_inertia, self.rotor_tau
        rotor_mode = self.rotor_mode
        sqrt = math.sqrt
        plant = self

        def derivative(s: list[float]) -> list[float]:
            _, _, _, vx, vy, vz, qw, qx, qy, qz, p, q, r = s[:13]
            # Rotation body -> world.
            xx, yy, zz = qx * qx, qy * qy, qz * qz
            xy, xz, yz = qx * qy, qx * qz, qy * qz
            wx, wy, wz = qw * qx, qw * qy, qw * qz
            R00, R01, R02 = 1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)
            R10, R11, R12 = 2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)
            R20, R21, R22 = 2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)

            # Actuators: thrust along body z at O and control torque (body).
            if rotor_mode:
                w1, w2, w3, w4 = s[13], s[14], s[15], s[16]
                c1, c2, c3, c4 = plant.rotor_cmd
                dw1, dw2 = (c1 - w1) / tau_r, (c2 - w2) / tau_r
                dw3, dw4 = (c3 - w3) / tau_r, (c4 - w4) / tau_r
                s1, s2, s3, s4 = w1 * w1, w2 * w2, w3 * w3, w4 * w4
                thrust = b * (s1 + s2 + s3 + s4)
                omega_r = -w1 + w2 - w3 + w4
                tx = arm * b * (s4 - s2) + Jr * omega_r * q
                ty = arm * b * (s3 - s1) - Jr * omega_r * p
                tz = d * (-s1 + s2 - s3 + s4) + Jr * (-dw1 + dw2 - dw3 + dw4)
            else:
                thrust = plant.thrust_cmd
                tx, ty, tz = plant.torque_cmd

            # Moment of the thrust (applied at O) about G: (-r_G) x (0, 0, T).
            tx -= ry * thrust
            ty += rx * thrust

            # Torque disturbance on the Euler coordinates -> body couple W^-T tau_eta (eq. 4).
            ap, aq, ar = plant.torque_dist_eta
            if ap != 0.0 or aq != 0.0 or ar != 0.0:
                st = -R20
                ct = sqrt(max(1.0 - st * st, 1e-12))
                sf, cf = R21 / ct, R22 / ct
                rhs = (ar + st * ap) / ct
                tx += ap
                ty += cf * aq + sf * rhs
                tz += -sf * aq + cf * rhs

            # Euler's equation about G: J w_dot = tau - w x J w.
            hx = J00 * p + J01 * q + J02 * r
            hy = J10 * p + J11 * q + J12 * r
            hz = J20 * p + J21 * q + J22 * r
            ex = tx - (q * hz - r * hy)
            ey = ty - (r * hx - p * hz)
            ez = tz - (p * hy - q * hx)
            dp = K00 * ex + K01 * ey + K02 * ez
            dq = K10 * ex + K11 * ey + K12 * ez
            dr = K20 * ex + K21 * ey + K22 * ez

            # Newton's equation for G (world frame).
            fx, fy, fz = plant.force_dist
            fx += R02 * thrust
            fy += R12 * thrust
            fz += R22 * thrust
            if has_drag:
                # Air-relative velocity of O: v_G - R (w x r_G) - wind.
                cx, cy, cz = q * rz - r * ry, r * rx - p * rz, p * ry - q * rx
                wnx, wny, wnz = plant.wind
                fx -= kdx * (vx - (R00 * cx + R01 * cy + R02 * cz) - wnx)
                fy -= kdy * (vy - (R10 * cx + R11 * cy + R12 * cz) - wny)
                fz -= kdz * (vz - (R20 * cx + R21 * cy + R22 * cz) - wnz)
            ax, ay, az = fx / m, fy / m, fz / m - g

            # Attitude kinematics q_dot = 1/2 q (x) (0, w).
            out = [
                vx, vy, vz, ax, ay, az,
                -0.5 * (qx * p + qy * q + qz * r),
                0.5 * (qw * p + qy * r - qz * q),
                0.5 * (qw * q + qz * p - qx * r),
                0.5 * (qw * r + qx * q - qy * p),
                dp, dq, dr,
            ]  # fmt: skip
            if rotor_mode:
                out += [dw1, dw2, dw3, dw4]
            return out

        return derivative

    def advance(self, disturbances: Sequence[tuple[Vector3, Vector3, Vector3]]) -> None:
        """One physics step per ``(force, torque, wind)`` of ``disturbances``, each held over its
        step (:meth:`set_disturbance` then :meth:`step`): a lockstep frame's physics. Compiled, the
        steps and the truth read-out that the next frame asks for are one call (the same
        operations as :meth:`step` and :meth:`truth`: bit for bit); :meth:`truth` then returns it
        until the state or an input changes."""
        if self._compiled is None:
            for force, torque, wind in disturbances:
                self.set_disturbance(force, torque, wind)
                self.step()
            return
        pos, vel, acc, euler, euler_rates, specific, on_ground = self._compiled.advance(self, disturbances)
        self.force_dist, self.torque_dist_eta, self.wind = disturbances[-1]
        s = self.state
        speeds, thrust, torque = self._actuation(s)
        truth = TruthState(pos, vel, acc, (s[6], s[7], s[8], s[9]), euler, (s[10], s[11], s[12]), euler_rates,
                           specific, speeds, thrust, torque, on_ground)  # fmt: skip
        self._truth = (list(s), truth)  # a copy: an in-place change of the state misses the cache

    def step(self) -> None:
        """Advance one physics step (classical RK4, inputs held): compiled when numba is there
        (:mod:`.compiled`, the same operations in the same order: bit for bit), else here."""
        if self._compiled is not None:
            self._compiled.step(self)
            return
        f = self._derivative
        s = self.state
        h = self.dt
        h2 = 0.5 * h
        # (zip without strict=: the lists have the state's length by construction, and the check
        # doubles the cost of these comprehensions)
        k1 = f(s)
        k2 = f([a + h2 * b for a, b in zip(s, k1)])  # noqa: B905
        k3 = f([a + h2 * b for a, b in zip(s, k2)])  # noqa: B905
        k4 = f([a + h * b for a, b in zip(s, k3)])  # noqa: B905
        h6 = h / 6.0
        s = [a + h6 * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]  # noqa: B905
        # Keep the quaternion on the unit sphere (RK4 drifts off it by O(h^5) per step).
        qw, qx, qy, qz = s[6], s[7], s[8], s[9]
        n = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        s[6], s[7], s[8], s[9] = qw * n, qx * n, qy * n, qz * n
        self.state = s
        if self.ground_contact and s[2] < self._ground_reach:  # O may be at the ground only then
            self._resolve_ground_contact()

    def _resolve_ground_contact(self) -> None:
        """Keep O on or above z = 0: a vehicle pressed into the ground rests there, level."""
        s = self.state
        R = rotation_from_quaternion(s[6], s[7], s[8], s[9])
        rx, ry, rz = self.com_offset
        z_O = s[2] - (R[2][0] * rx + R[2][1] * ry + R[2][2] * rz)
        if z_O > 0.0:
            return
        # velocity of O along z
        p, q, r = s[10], s[11], s[12]
        cx, cy, cz = q * rz - r * ry, r * rx - p * rz, p * ry - q * rx
        vz_O = s[5] - (R[2][0] * cx + R[2][1] * cy + R[2][2] * cz)
        if vz_O > 0.0:
            return
        psi = math.atan2(R[1][0], R[0][0])
        qn = quaternion_from_euler(0.0, 0.0, psi)
        Rl = rotation_from_quaternion(*qn)
        x_O = s[0] - (R[0][0] * rx + R[0][1] * ry + R[0][2] * rz)
        y_O = s[1] - (R[1][0] * rx + R[1][1] * ry + R[1][2] * rz)
        s[0] = x_O + Rl[0][0] * rx + Rl[0][1] * ry + Rl[0][2] * rz
        s[1] = y_O + Rl[1][0] * rx + Rl[1][1] * ry + Rl[1][2] * rz
        s[2] = Rl[2][0] * rx + Rl[2][1] * ry + Rl[2][2] * rz
        s[3:6] = [0.0, 0.0, 0.0]
        s[6:10] = list(qn)
        s[10:13] = [0.0, 0.0, 0.0]

    # -- read-out ---------------------------------------------------------------------------------
    def on_ground(self) -> bool:
        if not self.ground_contact:
            return False
        s = self.state
        R = rotation_from_quaternion(s[6], s[7], s[8], s[9])
        rx, ry, rz = self.com_offset
        z_O = s[2] - (R[2][0] * rx + R[2][1] * ry + R[2][2] * rz)
        return z_O <= 1e-6 and abs(s[5]) < 1e-6

    def kinematics(self) -> tuple[Vector3, Vector3, Vector3, Vector3]:
        """``(position, velocity, euler, euler_rates)`` of O: the cheap read-out for control."""
        s = self.state
        R = rotation_from_quaternion(s[6], s[7], s[8], s[9])
        w = (s[10], s[11], s[12])
        Rr = _rotate(R, self.com_offset)
        Rwxr = _rotate(R, _cross(w, self.com_offset))
        euler = euler_from_rotation(R)
        return (
            (s[0] - Rr[0], s[1] - Rr[1], s[2] - Rr[2]),
            (s[3] - Rwxr[0], s[4] - Rwxr[1], s[5] - Rwxr[2]),
            euler,
            euler_rates_from_body_rates(euler[0], euler[1], w),
        )

    def truth(self) -> TruthState:
        """Ground truth now (one extra derivative evaluation gives the accelerations).

        Written out component by component: it runs once per frame, on the lockstep path (where
        :meth:`advance` has usually computed it already, compiled)."""
        cached = self._truth
        if cached is not None and cached[0] == self.state:
            return cached[1]
        s = self.state
        ds = self._derivative(s)
        q = (s[6], s[7], s[8], s[9])
        (R00, R01, R02), (R10, R11, R12), (R20, R21, R22) = rotation_from_quaternion(*q)
        rx, ry, rz = self.com_offset
        p, qr, r = s[10], s[11], s[12]
        dp, dq, dr = ds[10], ds[11], ds[12]
        # w x r and (w_dot x r + w x (w x r)): the motion of O relative to G
        cx, cy, cz = qr * rz - r * ry, r * rx - p * rz, p * ry - qr * rx
        ax_ = dq * rz - dr * ry + (qr * cz - r * cy)
        ay_ = dr * rx - dp * rz + (r * cx - p * cz)
        az_ = dp * ry - dq * rx + (p * cy - qr * cx)
        pos = (s[0] - (R00 * rx + R01 * ry + R02 * rz), s[1] - (R10 * rx + R11 * ry + R12 * rz),
               s[2] - (R20 * rx + R21 * ry + R22 * rz))  # fmt: skip
        vel = (s[3] - (R00 * cx + R01 * cy + R02 * cz), s[4] - (R10 * cx + R11 * cy + R12 * cz),
               s[5] - (R20 * cx + R21 * cy + R22 * cz))  # fmt: skip
        on_ground = self.ground_contact and pos[2] <= 1e-6 and abs(s[5]) < 1e-6
        if on_ground:
            acc = ZERO3
        else:
            acc = (ds[3] - (R00 * ax_ + R01 * ay_ + R02 * az_), ds[4] - (R10 * ax_ + R11 * ay_ + R12 * az_),
                   ds[5] - (R20 * ax_ + R21 * ay_ + R22 * az_))  # fmt: skip
        fx, fy, fz = acc[0], acc[1], acc[2] + self.gravity  # specific force, world; into the body: R^T
        specific = (R00 * fx + R10 * fy + R20 * fz, R01 * fx + R11 * fy + R21 * fz,
                    R02 * fx + R12 * fy + R22 * fz)  # fmt: skip
        euler = euler_from_rotation(((R00, R01, R02), (R10, R11, R12), (R20, R21, R22)))
        w = (p, qr, r)
        speeds, thrust, torque = self._actuation(s)
        return TruthState(
            position_m=pos,
            velocity_m_s=vel,
            acceleration_m_s2=acc,
            quaternion=q,
            euler_rad=euler,
            body_rates_rad_s=w,
            euler_rates_rad_s=euler_rates_from_body_rates(euler[0], euler[1], w),
            specific_force_body_m_s2=specific,
            rotor_speeds_rad_s=speeds,
            thrust_n=thrust,
            torque_body_n_m=torque,
            on_ground=on_ground,
        )


    def _actuation(self, s: list[float]) -> tuple[tuple[float, float, float, float], float, Vector3]:
        """Rotor speeds, applied thrust and control torque about O of state ``s`` (truth)."""
        if self.rotor_mode:
            speeds = (s[13], s[14], s[15], s[16])
            sq = [x * x for x in speeds]
            torque = (
                self.arm * self.b * (sq[3] - sq[1]),
                self.arm * self.b * (sq[2] - sq[0]),
                self.d * (-sq[0] + sq[1] - sq[2] + sq[3]),
            )
            return speeds, self.b * sum(sq), torque
        return (0.0, 0.0, 0.0, 0.0), self.thrust_cmd, self.torque_cmd


def make_plant(vehicle: VehicleConfig, physics_dt_s: float):
    """The plant the vehicle config asks for (``plant.model``): this one, or the Section II model
    (:class:`.nominal_plant.NominalPlant`)."""
    if vehicle.plant.model == "nominal":
        from .nominal_plant import NominalPlant

        return NominalPlant(vehicle, physics_dt_s)
    return Plant(vehicle, physics_dt_s)


def _compiled_step(plant: Plant):
    """The numba step for ``plant`` (:mod:`.compiled`), or None: numba is not installed (the
    ``campaign`` extra brings it) or ``QUADSITL_PURE_PYTHON=1`` asks for the Python reference."""
    if os.environ.get("QUADSITL_PURE_PYTHON") == "1":
        return None
    try:
        from .compiled import CompiledStep
    except ImportError:
        return None
    return CompiledStep(plant)


# -- small helpers (off the RK4 path) -------------------------------------------------------------
def _clip(x: float, lo: float, hi: float) -> float:
    """``min(max(x, lo), hi)``, the same comparisons (NaN passes through), without two builtin
    calls: the actuator inputs are clipped at every frame."""
    x = lo if lo > x else x
    return hi if hi < x else x


def _cross(a: Vector3, b: Vector3) -> Vector3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _rotate(R, v: Vector3) -> Vector3:
    return tuple(R[i][0] * v[0] + R[i][1] * v[1] + R[i][2] * v[2] for i in range(3))  # type: ignore[return-value]


def _rotate_transpose(R, v: Vector3) -> Vector3:
    return tuple(R[0][i] * v[0] + R[1][i] * v[1] + R[2][i] * v[2] for i in range(3))  # type: ignore[return-value]


def _inverse3(A):
    (a, b, c), (d, e, f), (g, h, i) = A
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return (
        ((e * i - f * h) / det, (c * h - b * i) / det, (b * f - c * e) / det),
        ((f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det),
        ((d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det),
    )


__all__ = ["Plant", "TruthState", "make_plant"]
