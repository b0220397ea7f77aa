"""A researcher's own control law, as the tests write it: one file in a configuration directory's
laws/ and a controller file naming it (docs/controllers.md, "Adding a control law")."""

from __future__ import annotations

import contextlib
import os
import sys

from autopilot.control import registry
from quadcommon.config import CONFIG_ENV, config_path

TOY_LAW = '''
"""A toy translational law: a = p_d'' - kp e1 - kd e1' (no integral), then eqs. 23-29."""

from dataclasses import dataclass, replace

from autopilot.control.registry import TRANSLATIONAL, register
from autopilot.control.translational import thrust_and_tilt
from autopilot.params.store import ParamSpec
from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, values

import math

GAINS = layout("ToyGains", (
    Field("kp"), Field("kd"), Field("mass"), Field("gravity"), Field("thrust_max"), Field("sin_tilt_max"),
))


@dataclass(frozen=True)
class PdGains:
    law: str
    kp: float
    kd: float


@kernel
def step(g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw, dt,
         integrate):
    kp, kd = g[GAINS.kp], g[GAINS.kd]
    ax = ref_acceleration[0] - kp * (position[0] - ref_position[0]) - kd * (velocity[0] - ref_velocity[0])
    ay = ref_acceleration[1] - kp * (position[1] - ref_position[1]) - kd * (velocity[1] - ref_velocity[1])
    az = ref_acceleration[2] - kp * (position[2] - ref_position[2]) - kd * (velocity[2] - ref_velocity[2])
    {failure}
    thrust, roll, pitch, thrust_limited, tilt_limited = thrust_and_tilt(
        g[GAINS.mass], g[GAINS.gravity], g[GAINS.thrust_max], g[GAINS.sin_tilt_max], ax, ay, az, euler)
    return thrust, roll, pitch, ax, ay, az, thrust_limited, tilt_limited


@register(TRANSLATIONAL)
class ProportionalDerivative:
    NAME = "{name}"
    STATE = ()
    step = staticmethod(step)

    @classmethod
    def load_gains(cls, section):
        kp, kd = section.number("kp", lo=0.0, hi=100.0), section.number("kd", lo=0.0, hi=100.0)
        return PdGains(cls.NAME, kp, kd)

    @staticmethod
    def parameters(gains):
        return (ParamSpec("PD_KP", gains.kp, 0.0, 100.0), ParamSpec("PD_KD", gains.kd, 0.0, 100.0))

    @staticmethod
    def gains_from_params(gains, params):
        return replace(gains, kp=params.get("PD_KP", gains.kp), kd=params.get("PD_KD", gains.kd))

    @staticmethod
    def pack(gains, context):
        return values(GAINS, kp=gains.kp, kd=gains.kd, mass=context.mass_kg, gravity=context.gravity_m_s2,
                      thrust_max=context.thrust_max_n, sin_tilt_max=math.sin(context.tilt_max_rad))
'''


def write_overlay(directory, name: str, failure: str = "pass", kp: float = 4.0) -> str:
    """A configuration directory with a toy law ``name`` (laws/NAME.py) and a controller of the same
    name flying it with the paper's attitude law; returns the controller's name."""
    (directory / "laws").mkdir(parents=True, exist_ok=True)
    (directory / "controllers").mkdir(exist_ok=True)
    law = TOY_LAW.replace("{name}", name).replace("{failure}", failure)
    (directory / "laws" / f"{name}.py").write_text(law)
    paper = config_path("controllers", "intbs_nlhinf").read_text()
    start, end = paper.index("[translational]"), paper.index("[rotational]")
    toml = paper[:start] + f'[translational]\nlaw = "{name}"\nkp = {kp}\nkd = 3.0\n\n' + paper[end:]
    toml = toml.replace('name = "intbs_nlhinf"', f'name = "{name}"')
    (directory / "controllers" / f"{name}.toml").write_text(toml)
    return name


def nan_above(height_m: float) -> str:
    """A ``failure`` for :func:`write_overlay`: the law's output turns NaN once the vehicle is above
    ``height_m`` (it passes the check at hover, 1 m, when it loads, then fails in flight)."""
    return f"if position[2] > {height_m}:\n        az = math.nan"


@contextlib.contextmanager
def laws_forgotten_afterwards(directory):
    """``directory`` as the only configuration directory (QUADSITL_CONFIG_DIR) for the block; the
    environment, the laws its files registered and the record of files that did not load restored
    afterwards."""
    registry.names(registry.TRANSLATIONAL)  # the built-in laws loaded before the snapshot
    before = {loop: dict(laws) for loop, laws in registry._LAWS.items()}
    broken = dict(registry._BROKEN)
    environment = os.environ.get(CONFIG_ENV)
    os.environ[CONFIG_ENV] = str(directory)
    try:
        yield directory
    finally:
        if environment is None:
            os.environ.pop(CONFIG_ENV, None)
        else:
            os.environ[CONFIG_ENV] = environment
        for loop, laws in before.items():
            registry._LAWS[loop].clear()
            registry._LAWS[loop].update(laws)
        registry._BROKEN.clear()
        registry._BROKEN.update(broken)
        for module in [name for name in sys.modules if name.startswith(registry.USER_PACKAGE + ".")]:
            del sys.modules[module]
        registry.user_package()
