"""Logs -> replay tracks: a recorded session (the recorder's own classes) and an in-process run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs_scripts import session_log as sl
from gcs_scripts.link import custom_mode
from gcs_scripts.view.replay import decimate_indices, load_track
from tests.gcs_scripts.helpers import Vehicle, control_times, controller_rows, parse, truth_rows

pytestmark = pytest.mark.timeout(60)
META = {"scenario": "hover", "controller": "intbs", "vehicle": "paper_quad"}


def _session(tmp_path: Path) -> Path:
    """4 s of a session: on the ground until 1 s (no references), armed in OFFBOARD after."""
    times = control_times(0.0, 2000)
    ctrl = controller_rows(times)
    ground = times < 1.0
    ctrl[ground, 1:] = np.nan
    ctrl[:, -2] = np.where(ground, 0.0, 1.0)
    v = Vehicle(instance=0)
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    writer = sl.PartWriter(tmp_path / "run.parts")
    for i, chunk in enumerate(np.array_split(np.arange(len(times)), 8)):
        a.add_truth(truth_rows(times[chunk]), wall=float(i))
        a.add_controller(ctrl[chunk], wall=float(i))
        t = float(times[chunk][-1])
        armed = t >= 1.0
        mode = custom_mode("OFFBOARD" if armed else "AUTO.LOITER")[0]
        frames = [v.heartbeat(armed, mode), v.extended_sys_state(2 if armed else 1), v.local_position(t, 0.0)]
        if i == 3:
            frames.insert(0, v.statustext("offboard setpoints lost: switching to hold"))
        for msg in parse(frames):
            a.add_mavlink(msg, wall=float(i))
        writer.write(a.take(wall=i + 0.5), META)
    meta = dict(META, statustext=[list(s) for s in a.statustext])
    return sl.merge_parts(tmp_path / "run.parts", tmp_path / "run.parquet", meta)


def test_decimation_keeps_at_most_rate_samples_per_second_and_the_last():
    t = control_times(0.0, 5001)  # 0 .. 10 s at 500 Hz
    idx = decimate_indices(t, 30.0)
    assert idx[0] == 0 and idx[-1] == len(t) - 1
    assert np.all(np.diff(t[idx]) > 0)
    assert len(idx) <= 30 * 10 + 2


def test_session_track_keeps_the_ground_phase_events_modes_and_texts(tmp_path):
    track = load_track(_session(tmp_path), rate_hz=30)
    c = track.columns
    assert c["t"][0] == pytest.approx(0.0) and c["t"][-1] == pytest.approx(3.998)
    assert len(c["t"]) <= 30 * 4 + 2
    assert c["xr"][0] is None and c["xr"][-1] is not None  # no reference before arming
    assert track.events == pytest.approx([1.0, 2.0])  # the helpers' disturbance steps
    modes = [s[1] for s in track.status]
    assert modes[0] == ""  # before the first HEARTBEAT was recorded: unknown
    assert [m for m in modes if m][:2] == ["AUTO.LOITER", "OFFBOARD"]
    assert [s[2] for s in track.status][-1] is True
    assert track.texts and track.texts[0][2].startswith("offboard setpoints lost")
    assert track.controller == "intbs" and "intbs" in track.label
    js = track.to_json()
    assert set(js["cols"]) >= {"t", "x", "xr", "phi", "u1", "tphi", "fx", "mx"}


def test_align_armed_and_start(tmp_path):
    path = _session(tmp_path)
    armed = load_track(path, align="armed")
    assert armed.offset_s == pytest.approx(1.0, abs=0.6)  # the first recorded heartbeat that says armed
    assert armed.columns["t"][0] == pytest.approx(-armed.offset_s)
    assert load_track(path, align="start").columns["t"][0] == pytest.approx(0.0)
    with pytest.raises(ValueError, match="align"):
        load_track(path, align="wall")


def test_in_process_run_file(tmp_path):
    from autopilot.control.config import load_controller
    from quadcommon.config import load_scenario
    from sitl.inprocess import RunOptions, run_scenario

    record = run_scenario(load_scenario("circle"), load_controller("bs_nlhinf"), RunOptions(duration_s=3.0))
    path = record.write_parquet(tmp_path / "circle.parquet")
    track = load_track(path, label="BS-NLH∞")
    assert track.label == "BS-NLH∞" and track.controller == "bs_nlhinf"
    assert track.columns["t"][-1] == pytest.approx(record.time_s[-1])
    assert track.events == pytest.approx(record.event_times_s)
    assert track.status[0][1] == "in-process run"


def test_not_a_log(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    bad = tmp_path / "other.parquet"
    pq.write_table(pa.table({"a": [1.0, 2.0]}), bad)
    with pytest.raises(ValueError, match="not a quadsitl session log"):
        load_track(bad)
    with pytest.raises(FileNotFoundError):
        load_track(tmp_path / "missing")


def test_a_flight_logs_rotor_health_reaches_the_replay(tmp_path):
    """A motor failure injected in flight (PX4's motor 1, the right rotor, at 60 %): the flight log's
    sim_rotors (from the frames' report) gives the replay its rotor-health columns."""
    from pymavlink.dialects.v20 import common as m

    from autopilot.control.config import load_controller
    from quadcommon.config import load_scenario, load_vehicle
    from quadcommon.failures import Type, Unit
    from sitl.inprocess import RunOptions, paper_stack

    options = RunOptions(log_dir=str(tmp_path))
    stack = paper_stack(load_scenario("helix"), load_controller("intbs_nlhinf"), options,
                        vehicle=load_vehicle("paper_quad_rotors"))  # fmt: skip
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = stack.ground_station()
    stack.run_for(0.5)
    gcs.command(m.MAV_CMD_INJECT_FAILURE, Unit.motor, Type.wrong, 1, 0.6)
    stack.run_for(0.5)
    (log,) = stack.close()
    track = load_track(log, rate_hz=50.0)
    t = np.array(track.columns["t"])
    e2, f2 = np.array(track.columns["e2"], dtype=float), np.array(track.columns["f2"], dtype=float)
    assert (e2[t < 0.49] == 1.0).all() and (f2[t < 0.49] == 0.0).all()
    assert e2[-1] == pytest.approx(0.6, abs=1e-6) and f2[-1] == Type.wrong
    for n in (1, 3, 4):
        assert track.columns[f"e{n}"][-1] == 1.0 and track.columns[f"f{n}"][-1] == 0.0
