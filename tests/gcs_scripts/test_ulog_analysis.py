"""``quadsitl analyze`` and ``quadsitl view`` read the autopilot's flight logs (.ulg) as they read
the Parquet logs: the same flight gives the same paper indices from both (to float32 in the log).

In-process here (the paper's circle in simulation time: its record is what the recorder's Parquet
holds, the simulator's float64 truth joined with the controller's rows); the same comparison
against the recorder's own Parquet of a flight through the SITL is in test_e2e_sitl.py.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from autopilot.control.config import load_controller
from autopilot.logger.logger import LogOptions
from gcs_scripts.analysis import analyze
from gcs_scripts.analysis.log_reader import disturbance_events, read_session
from gcs_scripts.analysis.metrics import Indices, indices
from gcs_scripts.view.replay import load_track
from quadcommon.config import load_scenario
from sitl.inprocess import Lockstep, flight_record, paper_stack
from tests.ulog_check import check_ulog

# The tolerance docs/logs.md states: the log holds float32 (and its truth is the HIL frame's
# float32 ODOMETRY, the Parquet's the simulator's float64); measured ~1e-7 relative.
FINAL_ERROR_ABS_M = 2e-6
RELATIVE = 1e-5


def assert_same_indices(parquet: Indices, ulog: Indices) -> None:
    assert np.allclose(parquet.final_error_m, ulog.final_error_m, rtol=0, atol=FINAL_ERROR_ABS_M), (
        parquet,
        ulog,
    )
    for table in ("ise", "iadu"):
        a, b = getattr(parquet, table), getattr(ulog, table)
        assert a.keys() == b.keys()
        for name in a:
            assert b[name] == pytest.approx(a[name], rel=RELATIVE, abs=1e-12), (table, name, a[name], b[name])


@pytest.fixture(scope="module")
def circle(tmp_path_factory):
    """6 s of the paper's circle (its first disturbance included), logged; (log, Parquet, record)."""
    out = tmp_path_factory.mktemp("circle")
    base = paper_stack(load_scenario("circle"), load_controller("intbs_nlhinf"))
    stack = Lockstep(base.sim.setup, replace(base.autopilot.setup, log=LogOptions(str(out / "log"))))
    for _ in range(3000):
        stack.step()
    stack.final_frame()
    record = flight_record(stack, "circle", "intbs_nlhinf")
    (ulg,) = stack.close()
    return ulg, record.write_parquet(out / "circle.parquet"), record


def test_the_same_flight_gives_the_same_indices_from_its_log_and_its_parquet(circle):
    ulg, parquet, record = circle
    check_ulog(ulg)
    from_log = read_session(ulg)
    assert from_log.source == f"flight log {ulg}" and from_log.controller == "intbs_nlhinf"
    assert np.allclose(from_log.time_s, record.time_s, rtol=0, atol=1e-9)  # every control step
    assert_same_indices(indices(read_session(parquet)), indices(from_log))
    # the disturbance's onsets where the simulator applied them
    applied = np.column_stack([record.disturbance_force_n, record.disturbance_torque_n_m])
    expected = disturbance_events(record.time_s, applied)
    assert expected and np.allclose(from_log.event_times_s, expected, rtol=0, atol=1e-9), expected
    # a window as for the recorder's logs
    window = read_session(ulg, (1.0, 4.0))
    assert window.time_s[0] == 0.0 and window.time_s[-1] == pytest.approx(4.0)


def test_quadsitl_analyze_and_view_take_a_flight_log(circle, tmp_path):
    ulg, parquet, _ = circle
    assert analyze.main([str(ulg), str(parquet), "--out", str(tmp_path), "--labels", "ulog", "parquet"]) == 0
    text = (tmp_path / "comparison.md").read_text()
    assert f"flight log {ulg}" in text and "| ulog | parquet |" in text
    track = load_track(ulg)
    assert track.controller == "intbs_nlhinf" and track.columns["t"][0] == 0.0
    # the scenario flies from t = 0, from the ground (its circle starts at z = 0)
    assert track.status[0][1:] == ["AUTO.MISSION", True, "ON_GROUND"] and track.status[1][3] == "IN_AIR"
    assert track.events == [round(t, 6) for t in read_session(ulg).event_times_s]
    assert any("armed for the scenario" in text for _, _, text in track.texts)
    assert max(track.columns["z"]) == pytest.approx(float(np.max(circle[2].position_m[:, 2])), abs=1e-4)


def test_a_file_that_is_not_a_flight_log_is_refused_naming_it(tmp_path):
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"not a ulog at all")
    with pytest.raises(ValueError, match="bad.ulg: not a readable ULog"):
        read_session(bad)
    with pytest.raises(FileNotFoundError):
        read_session(tmp_path / "none.ulg")
