"""Gust-profile format: validation messages, JSON round trip, summaries, examples, cache."""

from __future__ import annotations

import json
import math
import re

import pytest

from quadcommon.config import CONFIG_DIR
from quadcommon.schema import ConfigError
from simulator.environment.discrete_gust import OneMinusCosineGust
from simulator.environment.dryden import DrydenTurbulence
from simulator.environment.gust_profile import (
    MAX_ELEMENTS,
    DisturbanceSchedule,
    GustProfile,
    Step,
    describe,
    gust_profile_from_mapping,
    load_gust_profile,
    profile_to_mapping,
)

GUST = {"start_s": 1.0, "duration_s": 2.0, "amplitude_m_s": 3.0, "axis": "x"}
DRYDEN = {"w20_m_s": 7.7, "altitude_m": 2.5, "seed": 1}


def _error(data: dict) -> str:
    with pytest.raises(ConfigError) as info:
        gust_profile_from_mapping(data, source="test.json")
    return str(info.value)


def _gust(**changes: object) -> dict:
    gust = {**GUST, **changes}
    return {"one_minus_cosine": [{k: v for k, v in gust.items() if v is not None}]}


def _dryden(**changes: object) -> dict:
    dryden = {**DRYDEN, **changes}
    return {"dryden": {k: v for k, v in dryden.items() if v is not None}}


# -- 1-cos validation -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("data", "key", "fragment"),
    [
        (_gust(amplitude_m_s=-1.0), "one_minus_cosine[0].amplitude_m_s", "[0, 50] (m/s)"),
        (_gust(axis=None, direction=[0.0, 0.0, 0.0]), "one_minus_cosine[0].direction", "non-zero 3-vector"),
        (_gust(axis=None, direction=[1.0, 0.0]), "one_minus_cosine[0].direction", "a list of 3 numbers"),
        (_gust(axis=None, direction=[1.0, "a", 0.0]), "one_minus_cosine[0].direction[1]", "a number"),
        (_gust(axis="w"), "one_minus_cosine[0].axis", "one of 'x', 'y', 'z'"),
        (_gust(direction=[1.0, 0.0, 0.0]), "one_minus_cosine[0].axis", "either 'direction' or 'axis'"),
        (_gust(length_m=10.0, airspeed_m_s=5.0), "one_minus_cosine[0].length_m", "not both"),
        (_gust(duration_s=0.0), "one_minus_cosine[0].duration_s", "[0.01, 3600] (s)"),
        (_gust(start_s=-1.0), "one_minus_cosine[0].start_s", "[0, 1e+06] (s)"),
        (
            _gust(duration_s=None, length_m=0.001, airspeed_m_s=5.0),
            "one_minus_cosine[0].length_m",
            "2 length_m / airspeed_m_s",
        ),
        (
            _gust(duration_s=None, length_m=-3.0, airspeed_m_s=5.0),
            "one_minus_cosine[0].length_m",
            "(0, 10000] (m)",
        ),
    ],
)
def test_one_minus_cosine_errors_name_key_value_and_range(data: dict, key: str, fragment: str) -> None:
    message = _error(data)
    assert message.startswith("test.json: ")
    assert f"'{key}'" in message
    assert fragment in message


def test_one_minus_cosine_missing_and_unknown_keys() -> None:
    assert "missing key 'one_minus_cosine[0].duration_s'" in _error(_gust(duration_s=None))
    assert "length_m (m) with airspeed_m_s" in _error(_gust(duration_s=None))
    assert "missing key 'one_minus_cosine[0].airspeed_m_s'" in _error(_gust(duration_s=None, length_m=5.0))
    assert "missing key 'one_minus_cosine[0].direction'" in _error(_gust(axis=None))
    message = _error(_gust(amplitude=3.0))
    assert "unknown key 'one_minus_cosine[0].amplitude'" in message


def test_one_minus_cosine_length_and_airspeed_give_duration() -> None:
    profile = gust_profile_from_mapping(_gust(duration_s=None, length_m=10.0, airspeed_m_s=4.0))
    assert profile.one_minus_cosine[0].duration_s == pytest.approx(5.0)  # 2 d_m / V


# -- Dryden validation --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("data", "key", "fragment"),
    [
        (_dryden(w20_m_s=-1.0), "dryden.w20_m_s", "[0, 30] (m/s)"),
        (_dryden(altitude_m=0.2), "dryden.altitude_m", "[1, 304.8] (m)"),
        (_dryden(altitude_m=400.0), "dryden.altitude_m", "[1, 304.8] (m)"),
        (_dryden(airspeed_m_s=0.0), "dryden.airspeed_m_s", "[0.5, 30] (m/s)"),
        (_dryden(seed=1.5), "dryden.seed", "an integer >= 0"),
        (_dryden(seed=-3), "dryden.seed", "an integer"),
        (_dryden(start_s=5.0, end_s=5.0), "dryden.end_s", "(5, 1e+06] (s)"),
        (_dryden(mean_wind_m_s=[0.0, 50.0, 0.0]), "dryden.mean_wind_m_s[1]", "[-30, 30] (m/s)"),
        (_dryden(warm_start="yes"), "dryden.warm_start", "true or false"),
    ],
)
def test_dryden_errors_name_key_value_and_range(data: dict, key: str, fragment: str) -> None:
    message = _error(data)
    assert f"'{key}'" in message
    assert fragment in message


def test_dryden_requires_seed_refuses_unknown_keys_and_arrays() -> None:
    assert "missing key 'dryden.seed'" in _error(_dryden(seed=None))
    assert "unknown key 'dryden.sigma'" in _error(_dryden(sigma=1.0))
    message = _error({"dryden": [DRYDEN, DRYDEN]})  # [[dryden]] twice: at most one
    assert "key 'dryden'" in message and "a table" in message


def test_unknown_top_level_key_and_element_count() -> None:
    assert "unknown key 'one_minus_cosines'" in _error({"one_minus_cosines": []})
    many = {"step": [{"channel": "force_x", "start_s": 0.0, "value": 0.0}] * (MAX_ELEMENTS + 1)}
    message = _error(many)
    assert f"at most {MAX_ELEMENTS}" in message and "'step'" in message


def test_error_names_offending_value() -> None:
    message = _error(_gust(amplitude_m_s=-2.5))
    assert re.search(r"= -2\.5 is invalid", message)


# -- round trip and summary ----------------------------------------------------------------------------
def test_json_round_trip_of_every_example_profile() -> None:
    names = sorted(p.stem for p in (CONFIG_DIR / "gusts").glob("*.toml"))
    assert {"paper_steps", "dryden_light", "gust_1cos_x", "mixed"} <= set(names)
    for name in names:
        profile = load_gust_profile(name)
        text = json.dumps(profile_to_mapping(profile))  # JSON-able: no inf, no tuples needed
        again = gust_profile_from_mapping(json.loads(text), source=f"{name} round trip")
        assert again == profile, name


def test_round_trip_keeps_non_default_values() -> None:
    profile = GustProfile(
        description="all",
        steps=(Step("force_y", 1.0, 0.5, 3.0),),
        one_minus_cosine=(OneMinusCosineGust(2.0, 1.5, 2.0, (0.0, -2.0, 1.0)),),
        dryden=DrydenTurbulence(15.4, 10.0, 42, 3.0, 1.0, 20.0, (1.0, 2.0, 0.0), False),
    )
    assert gust_profile_from_mapping(json.loads(json.dumps(profile_to_mapping(profile)))) == profile


def test_describe_is_one_line_and_mentions_each_element() -> None:
    text = describe(load_gust_profile("mixed"))
    assert "\n" not in text
    for fragment in ("2 steps", "1 ramp", "1-cos gust 2.5 m/s", "Dryden W20 15.4 m/s at 2.5 m", "mean wind"):
        assert fragment in text
    assert describe(GustProfile()) == "empty profile (no disturbance)"
    assert "along +x at 10 s for 2 s" in describe(load_gust_profile("gust_1cos_x"))
    many = gust_profile_from_mapping({"one_minus_cosine": [GUST] * 5})
    assert "5 1-cos gusts" in describe(many)


def test_paper_steps_keep_their_meaning() -> None:
    profile = load_gust_profile("paper_steps")
    assert not profile.one_minus_cosine and profile.dryden is None
    schedule = DisturbanceSchedule(profile)
    force, torque, wind = schedule.evaluate(31.0)
    assert force == (1.0, 1.0, 1.0) and torque == (1.0, 1.0, 1.0) and wind == (0.0, 0.0, 0.0)
    assert schedule.evaluate(4.999)[0] == (0.0, 0.0, 0.0)
    assert schedule.evaluate(5.0)[0] == (1.0, 0.0, 0.0)


# -- schedule: cache and sums ---------------------------------------------------------------------------
def test_step_only_schedule_is_served_from_the_cache() -> None:
    schedule = DisturbanceSchedule(load_gust_profile("paper_steps"))
    first = schedule.evaluate(6.0)
    assert (schedule._valid_from, schedule._valid_until) == (5.0, 10.0)
    assert schedule.evaluate(7.5) is first  # same object: no recomputation
    assert schedule.evaluate(10.0) is not first


def test_cache_is_not_used_while_wind_varies_and_resumes_after() -> None:
    schedule = DisturbanceSchedule(gust_profile_from_mapping(_gust()))
    schedule.evaluate(1.5)
    assert math.isnan(schedule._valid_from)  # gust active: nothing cached
    schedule.evaluate(3.5)
    assert (schedule._valid_from, schedule._valid_until) == (3.0, math.inf)


def test_elements_add_up_and_start_offset_applies_to_all() -> None:
    data = {
        "step": [{"channel": "force_x", "start_s": 0.0, "value": 1.0}],
        "ramp": [{"channel": "force_x", "start_s": 0.0, "end_s": 2.0, "value": 2.0}],
        "one_minus_cosine": [GUST, {**GUST, "axis": "y"}],
        "dryden": {**DRYDEN, "w20_m_s": 0.0, "mean_wind_m_s": [0.0, 0.0, -1.0]},
    }
    schedule = DisturbanceSchedule(gust_profile_from_mapping(data), start_time_s=10.0)
    force, _, wind = schedule.evaluate(12.0)  # profile time 2 s: gust peak, ramp done
    assert force[0] == pytest.approx(3.0)
    assert wind == pytest.approx((3.0, 3.0, -1.0))
    assert schedule.evaluate(9.0) == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
