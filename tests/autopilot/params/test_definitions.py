"""Parameters: specs per cascade, validation (name, type, range, read-only), config mapping,
consistency (pre-arm "bad parameters") and the params.toml file."""

import pytest

from autopilot.control.config import load_controller
from autopilot.params.definitions import (
    consistency_problems,
    controller_config_from_params,
    controller_params,
    default_parameters,
)
from autopilot.params.storage import load_params_file, read_params_file, write_params_file
from autopilot.params.store import INT32, ParameterStore, ParamSpec
from quadcommon.config import load_sitl
from quadcommon.schema import ConfigError

RATES = load_sitl().rates


def store_for(name: str) -> ParameterStore:
    return default_parameters(load_controller(name), RATES)


def test_gain_parameters_exist_only_for_the_active_cascade():
    paper = store_for("intbs_nlhinf")
    assert {"BS_C1_X", "BS_C2_Z", "BS_KI_Y", "BS_TILT_MAX", "NLH_W1", "NLH_W3", "NLH_WU", "CF_WN"} <= set(
        paper.names()
    )
    assert not any(n.startswith("ATT_") for n in paper.names())
    intbs = store_for("intbs")
    assert {"ATT_C1_R", "ATT_C2_P", "ATT_KI_Y", "BS_KI_Z"} <= set(intbs.names())
    assert not any(n.startswith("NLH_") for n in intbs.names())
    bs = store_for("bs_nlhinf")
    assert not any(n.startswith("BS_KI") for n in bs.names())  # no translational integral
    assert bs.specs["NLH_W3"].read_only and bs["NLH_W3"] == 0.0
    for store in (paper, intbs, bs):
        assert all(len(n) <= 16 for n in store.names())
        assert "MIS_TAKEOFF_ALT" in store and "COM_DL_LOSS_T" in store and "GF_ACTION" in store


def test_defaults_are_the_config_values_and_map_back():
    config = load_controller("intbs")
    store = default_parameters(config, RATES)
    assert store["ATT_C2_R"] == 111.1 and store["BS_KI_X"] == 1.5 and store["CF_ZETA"] == 1.0
    assert controller_config_from_params(config, store) == config
    assert store.set("ATT_KI_P", 45.0) is None
    assert store.set("BS_C1_Z", 12.0) is None
    mapped = controller_config_from_params(config, store)
    assert mapped.rotational.k_integral == (90.0, 45.0, 89.9)
    assert mapped.translational.c1 == (17.0, 17.0, 12.0)
    paper = load_controller("intbs_nlhinf")
    store = default_parameters(paper, RATES)
    store.set("NLH_W3", 4.5)
    assert controller_config_from_params(paper, store).rotational.omega3 == 4.5
    gains = {spec.name for spec in controller_params(paper)}  # what a retune must follow
    assert "NLH_W3" in gains and "NAV_DLL_ACT" not in gains


@pytest.mark.parametrize(
    "name, value, reason",
    [
        ("NOPE", 1.0, "unknown parameter"),
        ("MIS_TAKEOFF_ALT", 1000.0, "out of range [0.2, 100] m"),
        ("MIS_TAKEOFF_ALT", float("nan"), "not finite"),
        ("NAV_DLL_ACT", 1.5, "not an integer"),
        ("NAV_DLL_ACT", 5, "out of range"),
        ("GF_ACTION", 4, "flight termination is not supported"),
        ("SITL_CTRL_HZ", 250.0, "read-only"),
        ("MAV_SYS_ID", 7, "--instance"),
        ("BS_KI_X", 0.0, "out of range"),  # integral gains stay > 0 (the retune rescales by them)
    ],
)
def test_refused_values_say_why_and_keep_the_old_value(name, value, reason):
    store = store_for("intbs_nlhinf")
    old = store.values.get(name)
    problem = store.set(name, value)
    assert problem is not None and reason in problem
    assert store.values.get(name) == old


def test_float32_rounding_at_a_bound_is_accepted():
    store = ParameterStore([ParamSpec("X", 0.1, 0.1, 0.3)])
    assert store.set("X", 0.30000001192092896) is None  # float32(0.3)
    assert store.set("X", 0.09999999403953552) is None  # float32(0.1)


def test_listeners_see_accepted_changes_only():
    store = store_for("intbs_nlhinf")
    seen = []
    store.on_change(lambda n, v: seen.append((n, v)))
    store.set("NAV_DLL_ACT", 2)
    store.set("NAV_DLL_ACT", 2)  # unchanged: nothing to do
    store.set("NAV_DLL_ACT", 9)  # refused
    assert seen == [("NAV_DLL_ACT", 2.0)]
    assert store.set_many({"NAV_DLL_ACT": 1, "GF_ACTION": 4}) is not None  # all or nothing
    assert store["NAV_DLL_ACT"] == 2.0


def test_consistency_problems():
    store = store_for("intbs_nlhinf")
    assert consistency_problems(store) == []
    store.set("GF_MAX_VER_DIST", 4.0)
    problems = consistency_problems(store)
    assert any("RTL_RETURN_ALT 5 m is not below GF_MAX_VER_DIST 4 m" in p for p in problems)
    store.set("RTL_RETURN_ALT", 3.0)
    assert consistency_problems(store) == []
    store.set("MIS_TAKEOFF_ALT", 4.0)
    assert "MIS_TAKEOFF_ALT" in consistency_problems(store)[0]
    store.set("GF_MAX_VER_DIST", 0.0)
    store.set("MPC_LAND_SPEED", 2.0)
    assert "MPC_LAND_SPEED 2 m/s exceeds MPC_Z_VEL_MAX_DN 1 m/s" in consistency_problems(store)[0]


def test_file_round_trip(tmp_path):
    path = tmp_path / "params.toml"
    store = store_for("intbs_nlhinf")
    store.set("NLH_W3", 4.5)
    store.set("NAV_DLL_ACT", 3)
    store.set("MIS_TAKEOFF_ALT", 0.30000001192092896)
    write_params_file(path, store, header="test")
    text = path.read_text()
    assert "NAV_DLL_ACT = 3  #" in text and "NLH_W3 = 4.5  #" in text
    assert "SITL_CTRL_HZ" not in text and "MAV_SYS_ID" not in text  # read-only: not saved
    fresh = store_for("intbs_nlhinf")
    loaded = load_params_file(path, fresh)
    assert fresh.values == store.values
    assert fresh.specs["NAV_DLL_ACT"].kind == INT32 and isinstance(loaded["NAV_DLL_ACT"], float)


@pytest.mark.parametrize(
    "line, message",
    [
        (
            "NLH_W3 = 0.0",
            "key 'NLH_W3' = 0.0 is refused (NLH_W3: 0 out of range [0.001, 1000]); allowed: [0.001, 1000]",
        ),
        ("NAV_DLL_ACT = 1.0", "key 'NAV_DLL_ACT' = 1.0 must be an integer; allowed: [0, 3]"),
        ("NAV_DLL_ACT = true", "key 'NAV_DLL_ACT' = True must be a number"),
        ("ATT_C1_R = 3.0", "key 'ATT_C1_R' = 3.0 is not a parameter of this autopilot"),
        ("SITL_CTRL_HZ = 250.0", "key 'SITL_CTRL_HZ' = 250.0 cannot be set: fixed by config/sitl.toml"),
        ("GF_ACTION = 4", "flight termination is not supported"),
        ("MIS_TAKEOFF_ALT = ", "not valid TOML"),
    ],
)
def test_bad_file_names_file_key_value_and_range(tmp_path, line, message):
    path = tmp_path / "bad.toml"
    path.write_text(f"MPC_TKO_SPEED = 1.2\n{line}\n")
    store = store_for("intbs_nlhinf")
    with pytest.raises(ConfigError) as info:
        load_params_file(path, store)
    assert str(path) in str(info.value) and message in str(info.value)
    assert store["MPC_TKO_SPEED"] == store.specs["MPC_TKO_SPEED"].default  # all or nothing


def test_missing_file_is_an_error_for_read():
    with pytest.raises(ConfigError, match="not found"):
        read_params_file("/nonexistent/params.toml", store_for("intbs"))
