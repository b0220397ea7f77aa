"""IntBS attitude law (Bouabdallah & Siegwart 2007, the paper's ref. [2]), on eq. (4).

Integral in the FIRST backstepping step, per Euler axis (e1 = eta - eta_d):
chi' = e1, e2 = e1' + c1 e1 + lambda chi, and the commanded angular acceleration
``eta_cmd'' = eta_d'' + (c1^2 - 1 - lambda) e1 - (c1 + c2) e2 + c1 lambda chi``, applied through
the nominal model: ``tau = M(eta) eta_cmd'' + C(eta, eta') eta'`` (a generalised torque; the
actuators get ``W_eta^-T tau``). The chi terms of eta_cmd'' add up to ``-c2 lambda chi``, whose
torque near hover ``I c2 lambda chi`` sets the anti-windup bound and the retune.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from quadcommon.frames import wrap_pi
from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout
from quadcommon.layout import values as layout_values
from quadcommon.numerics import clip_symmetric
from quadcommon.rigid_body import body_torque_from_euler_torque, coriolis_matrix, inertia_matrix, matrix_times
from quadcommon.schema import Section

from ...params.store import ParamSpec
from ..registry import ROTATIONAL, register
from ..translational import GAIN_HI, INTEGRAL_LO, rescale_integrals

Vector3 = tuple[float, float, float]
EULER_AXES = ("R", "P", "Y")  # parameter suffixes: roll, pitch, yaw
_POSITIVE = {"lo": 0.0, "lo_open": True, "hi": 1e4}

# Gains array, per Euler axis from each offset: c1, c2, lambda, the nominal inertia, the bounds.
GAINS = layout("IntegralBacksteppingAttitudeGains", (
    Field("c1", 3),
    Field("c2", 3),
    Field("lambda_", 3, doc="the integral gain lambda"),
    Field("inertia", 3),
    Field("bound", 3),
))  # fmt: skip


@kernel
def commanded_acceleration(g, x, i, e, e_dot, ref_acc):
    """eta_cmd'' on Euler axis i (the module's formula)."""
    c1, c2, lam = g[GAINS.c1 + i], g[GAINS.c2 + i], g[GAINS.lambda_ + i]
    chi = x[i]
    e2 = e_dot + c1 * e + lam * chi
    return ref_acc + (c1 * c1 - 1.0 - lam) * e - (c1 + c2) * e2 + c1 * lam * chi


@kernel
def step(g, x, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt, integrate):
    """The rotational step of the registry's contract: eta_cmd'' per Euler axis, the chi integrals advanced
    (held within the anti-windup bound), and the body torque ``W_eta^-T (M eta_cmd'' + C eta')`` (N m)."""
    e0, e1, e2 = euler[0] - eta_d[0], euler[1] - eta_d[1], wrap_pi(euler[2] - eta_d[2])
    acc = (
        commanded_acceleration(g, x, 0, e0, euler_rates[0] - eta_d_dot[0], eta_d_ddot[0]),
        commanded_acceleration(g, x, 1, e1, euler_rates[1] - eta_d_dot[1], eta_d_ddot[1]),
        commanded_acceleration(g, x, 2, e2, euler_rates[2] - eta_d_dot[2], eta_d_ddot[2]),
    )
    if integrate:
        x[0] = clip_symmetric(x[0] + e0 * dt, g[GAINS.bound])
        x[1] = clip_symmetric(x[1] + e1 * dt, g[GAINS.bound + 1])
        x[2] = clip_symmetric(x[2] + e2 * dt, g[GAINS.bound + 2])
    inertia = (g[GAINS.inertia], g[GAINS.inertia + 1], g[GAINS.inertia + 2])
    Ma = matrix_times(inertia_matrix(inertia, euler[0], euler[1]), acc)
    Ce = matrix_times(coriolis_matrix(inertia, euler, euler_rates), euler_rates)
    return body_torque_from_euler_torque(euler[0], euler[1], (Ma[0] + Ce[0], Ma[1] + Ce[1], Ma[2] + Ce[2]))


@dataclass(frozen=True)
class IntBSAttitudeGains:
    """Per Euler axis (roll, pitch, yaw): c1, c2 and lambda (the integral gain)."""

    law: str
    c1: Vector3
    c2: Vector3
    k_integral: Vector3


def integral_weights(gains: IntBSAttitudeGains) -> Vector3:
    """The weight ``c2 lambda`` of chi in each axis's commanded angular acceleration (1/s^3): it sets the
    anti-windup bound and how a retune rescales chi."""
    return tuple(gains.c2[i] * gains.k_integral[i] for i in range(3))  # type: ignore[return-value]


@register(ROTATIONAL)
class IntegralBacksteppingAttitude:
    """IntBS attitude law (``law = "integral_backstepping"`` in ``[rotational]``): c1, c2 and the integral
    gain lambda per Euler axis, tunable in flight as ``ATT_C1_*``, ``ATT_C2_*``, ``ATT_KI_*``; its state
    the integrals chi of the roll, pitch and yaw errors (rad s)."""

    NAME = "integral_backstepping"
    STATE = ("chi_roll", "chi_pitch", "chi_yaw")
    step = staticmethod(step)

    @classmethod
    def load_gains(cls, section: Section) -> IntBSAttitudeGains:
        c1, c2 = section.vector("c1", **_POSITIVE), section.vector("c2", **_POSITIVE)
        return IntBSAttitudeGains(cls.NAME, c1, c2, section.vector("k_integral", lo=0.0, hi=1e4))

    @staticmethod
    def parameters(gains: IntBSAttitudeGains) -> tuple[ParamSpec, ...]:
        specs = []
        groups = (("C1", gains.c1, 0.01, "c1"), ("C2", gains.c2, 0.01, "c2"),
                  ("KI", gains.k_integral, INTEGRAL_LO, "lambda (integral)"))  # fmt: skip
        for name, values, lo, what in groups:
            for i, axis in enumerate(EULER_AXES):
                what_axis = f"IntBS attitude {what}, {('roll', 'pitch', 'yaw')[i]}"
                specs.append(ParamSpec(f"ATT_{name}_{axis}", values[i], lo, GAIN_HI, description=what_axis))
        return tuple(specs)

    @staticmethod
    def gains_from_params(gains: IntBSAttitudeGains, params: Mapping[str, float]) -> IntBSAttitudeGains:
        def vec(prefix: str, default: Vector3) -> Vector3:
            names = [f"{prefix}_{a}" for a in EULER_AXES]
            if not all(n in params for n in names):
                return default
            return (params[names[0]], params[names[1]], params[names[2]])

        return replace(gains, c1=vec("ATT_C1", gains.c1), c2=vec("ATT_C2", gains.c2),
                       k_integral=vec("ATT_KI", gains.k_integral))  # fmt: skip

    @staticmethod
    def pack(gains: IntBSAttitudeGains, context) -> tuple[float, ...]:
        inertia, tau = context.inertia_kg_m2, context.torque_max_n_m
        w = integral_weights(gains)
        bound = tuple(tau[i] / (inertia[i] * w[i]) if w[i] > 0.0 else math.inf for i in range(3))
        return layout_values(
            GAINS, c1=gains.c1, c2=gains.c2, lambda_=gains.k_integral, inertia=inertia, bound=bound
        )

    @staticmethod
    def retune(old, new, context, state, euler, euler_rates) -> list[float]:
        """chi rescaled so ``c2 lambda chi`` (hence its image ``M (.)`` in tau at any state) is
        unchanged; a new lambda of zero drops the integral."""
        return rescale_integrals(state, integral_weights(old), integral_weights(new))
