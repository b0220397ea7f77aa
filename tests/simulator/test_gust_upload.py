"""Pure handling of gust-profile upload requests (the simulator side of quadsitl/<N>/sim/gusts)."""

from __future__ import annotations

import json

import pytest

from simulator.environment.gust_profile import GustProfile, load_gust_profile, profile_to_mapping
from simulator.environment.gust_upload import MAX_PAYLOAD_BYTES, handle_gust_request

GUST = {"start_s": 1.0, "duration_s": 2.0, "amplitude_m_s": 3.0, "axis": "x"}


def _request(**fields: object) -> bytes:
    return json.dumps(fields).encode()


def _rejected(payload: bytes, now_s: float = 12.5) -> str:
    ok, reply, profile, start = handle_gust_request(payload, now_s)
    assert not ok and profile is None and start is None
    answer = json.loads(reply)
    assert answer["accepted"] is False
    return answer["error"]


def test_accepts_and_starts_now_by_default() -> None:
    ok, reply, profile, start = handle_gust_request(_request(profile={"one_minus_cosine": [GUST]}), 12.5)
    assert ok and start == 12.5
    assert isinstance(profile, GustProfile) and len(profile.one_minus_cosine) == 1
    answer = json.loads(reply)
    assert answer == {
        "accepted": True,
        "start_s": 12.5,
        "summary": "1-cos gust 3 m/s along +x at 1 s for 2 s",
    }


@pytest.mark.parametrize(
    ("start", "expected"),
    [("now", 12.5), ({"at_s": 20.0}, 20.0), ({"at_s": 12.5}, 12.5), ({"after_s": 2.5}, 15.0)],
)
def test_start_forms(start: object, expected: float) -> None:
    ok, _, _, start_s = handle_gust_request(_request(profile={}, start=start), 12.5)
    assert ok and start_s == pytest.approx(expected)


def test_paper_profile_uploads_as_json_and_summary_names_it() -> None:
    paper = load_gust_profile("paper_steps")
    ok, reply, profile, _ = handle_gust_request(
        _request(profile=profile_to_mapping(paper), mode="replace"), 0.0
    )
    assert ok and profile == paper
    assert json.loads(reply)["summary"].endswith(": 6 steps")


def test_empty_profile_is_accepted_and_clears_disturbances() -> None:
    ok, reply, profile, _ = handle_gust_request(_request(profile={}), 3.0)
    assert ok and profile is not None and profile.is_empty
    assert json.loads(reply)["summary"] == "empty profile (no disturbance)"


@pytest.mark.parametrize(
    ("payload", "fragments"),
    [
        (b"{not json", ["gust upload: payload is not valid UTF-8 JSON"]),
        (b"\xff\xfe", ["not valid UTF-8 JSON"]),
        (b"[1, 2]", ["must be a JSON object", "got list"]),
        (_request(start="now"), ["gust upload: missing key 'profile'"]),
        (_request(profile=[1]), ["key 'profile' = [1] is invalid; allowed: a table"]),
        (
            _request(profile={"one_minus_cosine": [{**GUST, "amplitude_m_s": -1.0}]}),
            [
                "gust upload: key 'profile.one_minus_cosine[0].amplitude_m_s' = -1.0 is invalid",
                "[0, 50] (m/s)",
            ],
        ),
        (
            _request(profile={"dryden": {"w20_m_s": 7.7, "altitude_m": 2.5, "seed": 1, "colour": "pink"}}),
            ["unknown key 'profile.dryden.colour'"],
        ),
        (
            _request(profile={}, start={"at_s": 3.0}),
            ["key 'start.at_s' = 3.0 is invalid", "would lie before the simulation time now, 12.5"],
        ),
        (_request(profile={}, start={"after_s": -1.0}), ["key 'start.after_s' = -1.0", "[0, 1e+06] (s)"]),
        (_request(profile={}, start={"at_s": 20.0, "after_s": 1.0}), ["key 'start'", "exactly one key"]),
        (_request(profile={}, start={}), ["key 'start'", "exactly one key"]),
        (_request(profile={}, start="later"), ["key 'start' = 'later' is invalid", "one of 'now'"]),
        (_request(profile={}, start=5), ["key 'start' = 5 is invalid", "a table"]),
        (_request(profile={}, start={"at_s": 20.0, "when": 1}), ["unknown key 'start.when'"]),
        (_request(profile={}, mode="add"), ["key 'mode' = 'add' is invalid", "'replace'", "add up"]),
        (_request(profile={}, extra=1), ["unknown key 'extra'"]),
    ],
)
def test_rejections_carry_the_exact_validation_message(payload: bytes, fragments: list[str]) -> None:
    error = _rejected(payload)
    for fragment in fragments:
        assert fragment in error


def test_oversized_payload_is_refused_before_parsing() -> None:
    error = _rejected(b" " * (MAX_PAYLOAD_BYTES + 1))
    assert f"at most {MAX_PAYLOAD_BYTES} bytes" in error


def test_dryden_too_fast_for_the_physics_step_is_refused() -> None:
    dryden = {"w20_m_s": 7.7, "altitude_m": 1.0, "airspeed_m_s": 30.0, "seed": 1}
    ok, reply, *_ = handle_gust_request(_request(profile={"dryden": dryden}), 0.0, step_s=0.01)
    assert not ok
    assert "key 'profile.dryden'" in json.loads(reply)["error"] and "too coarse" in json.loads(reply)["error"]
    assert handle_gust_request(_request(profile={"dryden": dryden}), 0.0, step_s=0.001).ok


def test_result_unpacks_into_four_values_and_has_names() -> None:
    result = handle_gust_request(_request(profile={}), 1.0)
    ok, reply, profile, start = result
    assert (result.ok, result.reply, result.profile, result.start_s) == (ok, reply, profile, start)


def test_a_past_anchor_is_accepted_while_the_first_event_is_still_ahead():
    """A script anchors the paper's steps (first at +5 s) on an instant it has just observed."""
    steps = {"step": [{"channel": "force_x", "start_s": 5.0, "value": 1.0}]}
    ok, reply, profile, start_s = handle_gust_request(_request(profile=steps, start={"at_s": 10.0}), 12.5)
    assert ok and start_s == 10.0
    ok, reply, _, _ = handle_gust_request(_request(profile=steps, start={"at_s": 7.0}), 12.5)
    assert not ok and b"first event (5 s after at_s)" in reply
