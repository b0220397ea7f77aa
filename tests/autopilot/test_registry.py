"""The control-law registry: a new law is one class (its file) plus one registration, and then the
config loader, the cascade and the parameter table all know it without naming it."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from dataclasses import dataclass, replace

import pytest

from autopilot.control import registry
from autopilot.control.cascade import Cascade, StateEstimate
from autopilot.control.config import load_controller
from autopilot.params.definitions import controller_config_from_params, default_parameters
from autopilot.params.store import ParamSpec
from quadcommon.config import config_path, load_sitl, load_vehicle
from quadcommon.schema import ConfigError
from quadcommon.trajectories import Reference


@dataclass(frozen=True)
class PdGains:
    law: str
    kp: float
    kd: float


class ProportionalDerivative:
    """A toy translational law: a = p_d'' - kp e1 - kd e1' (no integral)."""

    NAME = "test_pd"

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

    def __init__(self, gains, nominal) -> None:
        self.gains, self.integral = gains, [0.0, 0.0, 0.0]

    def reset(self) -> None:
        pass

    def retune(self, gains) -> None:
        self.gains = gains

    def integral_acceleration(self):
        return (0.0, 0.0, 0.0)

    def accelerations(self, e1, e1_dot, ref_acc, dt, integrate):
        g = self.gains
        return [ref_acc[i] - g.kp * e1[i] - g.kd * e1_dot[i] for i in range(3)]


@pytest.fixture
def registered() -> Iterator[type]:
    law = registry.register(registry.TRANSLATIONAL)(ProportionalDerivative)  # the one registration
    yield law
    registry._LAWS[registry.TRANSLATIONAL].pop(law.NAME)


def test_a_new_law_is_loaded_flown_and_tuned_without_naming_it_anywhere(registered, tmp_path):
    path = tmp_path / "pd.toml"
    text = config_path("controllers", "intbs_nlhinf").read_text()
    start, end = text.index("[translational]"), text.index("[rotational]")
    path.write_text(text[:start] + '[translational]\nlaw = "test_pd"\nkp = 4.0\nkd = 3.0\n\n' + text[end:])
    config = load_controller(path)
    assert config.translational == PdGains("test_pd", 4.0, 3.0)
    params = default_parameters(config, load_sitl().rates)
    assert params["PD_KP"] == 4.0 and "BS_C1_X" not in params and "NLH_W1" in params
    cascade = Cascade(config, load_vehicle("paper_quad"), 0.002)
    ref = Reference((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
    below = StateEstimate((0.0, 0.0, 0.9), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = cascade.step(below, ref)
    assert out.acceleration_cmd_m_s2[2] == pytest.approx(4.0 * 0.1)  # kp * 0.1 m below
    params.set("PD_KP", 8.0)
    cascade.retune(controller_config_from_params(config, params))
    assert cascade.step(below, ref).acceleration_cmd_m_s2[2] == pytest.approx(8.0 * 0.1)


def test_an_unknown_law_is_a_config_error_listing_the_known_ones(tmp_path):
    path = tmp_path / "bad.toml"
    shutil.copy(config_path("controllers", "intbs"), path)
    path.write_text(path.read_text().replace('law = "integral_first_step"', 'law = "sliding_mode"'))
    with pytest.raises(ConfigError, match="translational.law.*'sliding_mode'.*integral_second_step"):
        load_controller(path)


def test_two_laws_of_one_name_are_refused(registered):
    with pytest.raises(ValueError, match="two translational laws named 'test_pd'"):
        registry.register(registry.TRANSLATIONAL)(ProportionalDerivative)


def test_the_papers_laws_are_registered():
    assert set(registry.names(registry.TRANSLATIONAL)) >= {"integral_second_step", "integral_first_step",
                                                           "backstepping"}  # fmt: skip
    assert set(registry.names(registry.ROTATIONAL)) >= {"nlhinf", "integral_backstepping"}
