"""The control-law registry: a law is one file and one registration, found by name in a
configuration directory's laws/; a law that breaks the contract is refused when it registers or
loads, with the reason and its file; one that fails in flight terminates the flight, and the
autopilot lives on."""

from __future__ import annotations

import re

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.control import registry
from autopilot.control.cascade import Cascade, law_context
from autopilot.control.config import load_controller
from autopilot.control.registry import ControllerFailure, LawError
from autopilot.params.definitions import controller_config_from_params, default_parameters
from autopilot.records import StateEstimate
from quadcommon.config import config_path, load_sitl, load_vehicle
from quadcommon.kernel import compiling, kernel
from quadcommon.schema import ConfigError
from quadcommon.trajectories import Reference
from tests.own_law import laws_forgotten_afterwards, nan_above, write_overlay
from tests.stack import Gcs, make_stack


@pytest.fixture
def overlay(tmp_path):
    """A configuration directory in QUADSITL_CONFIG_DIR; its laws forgotten afterwards."""
    with laws_forgotten_afterwards(tmp_path):
        yield tmp_path


HOVER = Reference((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
BELOW = StateEstimate((0.0, 0.0, 0.9), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def test_a_law_in_a_configuration_directory_is_found_flown_and_tuned_by_name(overlay):
    name = write_overlay(overlay, "toy_pd")
    config = load_controller(name)
    assert config.translational.law == "toy_pd" and config.translational.kp == 4.0
    assert "toy_pd" in registry.names(registry.TRANSLATIONAL)
    assert type(config.translational).__module__ == "quadsitl_laws.toy_pd"  # importable by name (pickles)
    params = default_parameters(config, load_sitl().rates)
    assert params["PD_KP"] == 4.0 and "BS_C1_X" not in params and "NLH_W1" in params
    cascade = Cascade(config, load_vehicle("paper_quad"), 0.002)
    assert cascade.step(BELOW, HOVER).acceleration_cmd_m_s2[2] == pytest.approx(4.0 * 0.1)  # kp * 0.1 m below
    params.set("PD_KP", 8.0)
    cascade.retune(controller_config_from_params(config, params))
    assert cascade.step(BELOW, HOVER).acceleration_cmd_m_s2[2] == pytest.approx(8.0 * 0.1)


def test_an_unknown_law_is_a_config_error_listing_the_known_ones(tmp_path):
    path = tmp_path / "bad.toml"
    text = config_path("controllers", "intbs").read_text()
    path.write_text(text.replace('"integral_first_step"', '"sliding"'))
    with pytest.raises(ConfigError, match="translational.law.*'sliding'.*integral_second_step"):
        load_controller(path)


def test_a_broken_law_file_stops_only_the_laws_it_defines_and_says_which(overlay):
    """A syntax error in one file of laws/: the shipped laws and the directory's other laws still
    load, the file is named with its error once, and asking for its law gives that error."""
    write_overlay(overlay, "toy_pd")
    write_overlay(overlay, "half_written", failure="def (:")  # its controller file names it
    with pytest.warns(registry.LawFileWarning, match=r"half_written\.py.*SyntaxError.*'half_written'"):
        translational = registry.names(registry.TRANSLATIONAL)
    assert {"toy_pd", "integral_second_step", "px4_position"} <= set(translational)
    assert "half_written" not in translational
    assert load_controller("intbs_nlhinf").translational.law == "integral_second_step"
    assert load_controller("toy_pd").translational.law == "toy_pd"
    where = re.escape(str(overlay / "laws" / "half_written.py"))
    with pytest.raises(ConfigError, match=rf"translational\.law' = 'half_written'.*{where}.*SyntaxError"):
        load_controller("half_written")
    with pytest.raises(ConfigError, match=rf"{where}.*SyntaxError"):
        registry.law(registry.TRANSLATIONAL, "half_written")


def test_a_law_file_that_fails_after_registering_takes_its_laws_with_it(overlay):
    name = write_overlay(overlay, "toy_late")
    with (overlay / "laws" / "toy_late.py").open("a") as law_file:
        law_file.write("\nraise RuntimeError('not finished')\n")
    with pytest.warns(registry.LawFileWarning, match=r"toy_late\.py.*RuntimeError: not finished"):
        assert "toy_late" not in registry.names(registry.TRANSLATIONAL)
    with pytest.raises(ConfigError, match=r"toy_late\.py.*RuntimeError: not finished"):
        load_controller(name)


def test_an_unknown_law_beside_a_broken_file_names_the_file(overlay):
    (overlay / "laws").mkdir()
    (overlay / "laws" / "generated.py").write_text("NAMES = [f'law_{i}' for i in range(3)]\nimport nosuch\n")
    (overlay / "controllers").mkdir()
    text = config_path("controllers", "intbs").read_text()
    (overlay / "controllers" / "mine.toml").write_text(text.replace('"integral_first_step"', '"law_1"'))
    reason = r"'law_1'.*integral_second_step.*generated\.py, line 2: ModuleNotFoundError"
    with pytest.warns(registry.LawFileWarning), pytest.raises(ConfigError, match=reason):
        load_controller("mine")


class Minimal:
    NAME = "minimal"
    STATE = ()
    load_gains = parameters = gains_from_params = pack = staticmethod(lambda *a: ())

    @staticmethod
    @kernel
    def step(g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw, dt,
             integrate):  # fmt: skip
        return (0.0,) * 8


@pytest.mark.parametrize(
    "change, reason",
    [
        ({"NAME": "no name"}, "NAME must be a name"),
        ({"STATE": ["xi"]}, "STATE must be a tuple"),
        ({"pack": None}, "no pack"),
        ({"step": staticmethod(lambda g, x: (0.0,) * 8)}, "must be a @kernel"),
        ({"step": staticmethod(kernel(lambda g, x, position: (0.0,) * 8))}, "takes 3 arguments"),
    ],
)
def test_a_law_that_breaks_the_contract_is_refused_when_it_registers(change, reason):
    broken = type("Broken", (Minimal,), change)
    with pytest.raises(LawError, match=reason):
        registry.register(registry.TRANSLATIONAL)(broken)
    assert "minimal" not in registry.names(registry.TRANSLATIONAL)


@pytest.mark.parametrize(
    "failure, reason",
    [
        ("raise ValueError('not yet written')", "step raised at hover: ValueError: not yet written"),
        ("ax = g[99]", "step raised at hover: IndexError"),
        ("return ax, ay, az", "must return 8 finite numbers"),
        ("az = az + 100.0", "asks for 28 N of thrust"),
        ("az = az * math.nan", "must return 8 finite numbers"),
    ],
)
def test_a_law_that_fails_at_hover_is_refused_when_a_controller_loads_it(overlay, failure, reason):
    name = write_overlay(overlay, "toy_bad", failure=failure)
    with pytest.raises(ConfigError, match=rf"translational law 'toy_bad' \(.*toy_bad\.py\): .*{reason}"):
        Cascade(load_controller(name), load_vehicle("paper_quad"), 0.002)


def test_a_law_numba_cannot_compile_is_refused_with_the_reason(overlay):
    name = write_overlay(overlay, "toy_dict", failure="table = {'a': object()}")
    with pytest.raises(ConfigError, match="toy_dict \\+ nlhinf do not compile with numba"):
        Cascade(load_controller(name), load_vehicle("paper_quad"), 0.002)


@pytest.mark.skipif(not compiling(), reason="numba compiles nothing here (QUADSITL_PURE_PYTHON=1)")
def test_a_step_calling_a_plain_function_is_refused_with_the_file_line_and_name(overlay):
    """numba's typing error, nested through the cascade's kernels, reduced to its cause: the law's
    file and line, the name it could not type, and what to do."""
    name = write_overlay(overlay, "toy_helper", failure="az = plain_helper(az)")
    law_file = overlay / "laws" / "toy_helper.py"
    law_file.write_text(law_file.read_text() + "\n\ndef plain_helper(a):\n    return 0.5 * a\n")
    line = law_file.read_text().splitlines().index("    az = plain_helper(az)") + 1
    with pytest.raises(ConfigError) as refused:
        Cascade(load_controller(name), load_vehicle("paper_quad"), 0.002)
    text = str(refused.value)
    assert "toy_helper + nlhinf do not compile with numba" in text
    assert f"{law_file}, line {line}" in text
    assert "plain_helper" in text and "az = plain_helper(az)" in text
    assert "@kernel" in text  # the remedy
    assert "\x1b[" not in text and "buffered_step" not in text  # no colour codes, no numba frames


def test_a_law_failing_in_flight_terminates_the_flight_and_the_autopilot_lives_on(overlay):
    """NaN once the vehicle is 1.5 m above home: the cascade raises ControllerFailure, the autopilot
    stops the motors (disarmed), says why on every link, and keeps answering frames."""
    name = write_overlay(overlay, "toy_nan", failure=nan_above(1.5))
    cascade = Cascade(load_controller(name), load_vehicle("paper_quad"), 0.002)
    with pytest.raises(ControllerFailure, match="toy_nan.*non-finite output"):
        cascade.step(StateEstimate((0.0, 0.0, 1.6), (0.0,) * 3, (0.0,) * 3, (0.0,) * 3), HOVER)
    stack = make_stack(controller=name)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 2.5).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: any("flight terminated" in t for t in g.statustext), sim_timeout=10.0,
             what="the failsafe's STATUSTEXT")  # fmt: skip
    assert any("toy_nan" in t and "non-finite" in t for t in gcs.statustext)
    gcs.wait(lambda g: not g.armed, sim_timeout=1.0, what="disarmed")
    frames = stack.autopilot.frames
    gcs.wait(lambda g: stack.autopilot.frames > frames + 100, sim_timeout=1.0, what="frames still answered")


def test_the_papers_laws_are_registered():
    assert set(registry.names(registry.TRANSLATIONAL)) >= {"integral_second_step", "integral_first_step",
                                                           "backstepping"}  # fmt: skip
    assert set(registry.names(registry.ROTATIONAL)) >= {"nlhinf", "integral_backstepping"}


BOTH_HALVES = '''
"""A PD position law and a PD attitude law in one file, registered under one name."""
import math
from dataclasses import dataclass

from autopilot.control.registry import ROTATIONAL, TRANSLATIONAL, register
from autopilot.control.translational import thrust_and_tilt
from autopilot.control.tunable import Tunable, TunableLaw
from quadcommon.kernel import kernel


@kernel
def position_step(g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw,
                  dt, integrate):
    a = [ref_acceleration[i] - g[0] * (position[i] - ref_position[i]) - g[1] * (velocity[i] - ref_velocity[i])
         for i in range(3)]
    thrust, roll, pitch, thrust_limited, tilt_limited = thrust_and_tilt(g[2], g[3], g[4], g[5], a[0], a[1],
                                                                        a[2], euler)
    return thrust, roll, pitch, a[0], a[1], a[2], thrust_limited, tilt_limited


@kernel
def attitude_step(g, x, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt, integrate):
    return (-g[0] * (euler[0] - eta_d[0]) - g[1] * (euler_rates[0] - eta_d_dot[0]),
            -g[0] * (euler[1] - eta_d[1]) - g[1] * (euler_rates[1] - eta_d_dot[1]),
            -g[0] * (euler[2] - eta_d[2]) - g[1] * (euler_rates[2] - eta_d_dot[2]))


@dataclass(frozen=True)
class Gains:
    law: str
    kp: float
    kd: float


@register(TRANSLATIONAL)
class Position(TunableLaw):
    NAME = "both_pd"
    GAINS = Gains
    TUNABLE = (Tunable("kp", "BOTH_XY_KP", 0.0, 100.0), Tunable("kd", "BOTH_XY_KD", 0.0, 100.0))
    step = staticmethod(position_step)

    @staticmethod
    def pack(gains, context):
        return (gains.kp, gains.kd, context.mass_kg, context.gravity_m_s2, context.thrust_max_n,
                math.sin(context.tilt_max_rad))


@register(ROTATIONAL)
class Attitude(TunableLaw):
    NAME = "both_pd"
    GAINS = Gains
    TUNABLE = (Tunable("kp", "BOTH_ATT_KP", 0.0, 100.0), Tunable("kd", "BOTH_ATT_KD", 0.0, 100.0))
    step = staticmethod(attitude_step)

    @staticmethod
    def pack(gains, context):
        return (gains.kp, gains.kd)
'''


def test_one_file_may_register_both_halves_of_a_cascade_under_one_name(overlay):
    """docs/controllers.md, "Both halves in one file": names are per loop."""
    (overlay / "laws").mkdir()
    (overlay / "laws" / "both_pd.py").write_text(BOTH_HALVES)
    (overlay / "controllers").mkdir()
    (overlay / "controllers" / "both_pd.toml").write_text(
        'name = "both_pd"\n[translational]\nlaw = "both_pd"\nkp = 4.0\nkd = 3.0\n'
        '[rotational]\nlaw = "both_pd"\nkp = 1.0\nkd = 0.1\n'
        "[command_filter]\nnatural_frequency_rad_s = 60.0\ndamping = 0.9\n"
    )
    config = load_controller("both_pd")
    assert (config.translational.kp, config.rotational.kp) == (4.0, 1.0)
    assert registry.law(registry.TRANSLATIONAL, "both_pd") is not registry.law(registry.ROTATIONAL, "both_pd")
    params = default_parameters(config, load_sitl().rates)
    assert (params["BOTH_XY_KP"], params["BOTH_ATT_KP"]) == (4.0, 1.0)
    context = law_context(config, load_vehicle("paper_quad"), 0.002)
    position = registry.BoundLaw(registry.TRANSLATIONAL, config.translational, context)
    attitude = registry.BoundLaw(registry.ROTATIONAL, config.rotational, context)
    out = position.step((0.0, 0.0, 0.9), (0.0,) * 3, (0.0,) * 3, (0.0, 0.0, 1.0), (0.0,) * 3, (0.0,) * 3, 0.0,
                        0.002, True)  # fmt: skip
    assert out.acceleration_z_m_s2 == pytest.approx(4.0 * 0.1)  # kp * 0.1 m below
    torque = attitude.step((0.1, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, 0.002,
                           True)  # fmt: skip
    assert torque[0] == pytest.approx(-0.1)
