"""Session logs -> FlightRecord: the same indices as from the data directly; windows; parts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs_scripts import session_log as sl
from gcs_scripts.analysis.log_reader import coalesce_duplicate_times, disturbance_events, read_session
from gcs_scripts.analysis.metrics import indices
from gcs_scripts.analysis.record import FlightRecord

from .helpers import control_times, controller_rows, truth_rows

META = {"scenario": "helix", "controller": "intbs", "vehicle": "paper_quad"}


def _session(tmp_path: Path, times: np.ndarray, merged: bool = True, pre_arm_rows: int = 0) -> Path:
    """A recorder session written with the recorder's own classes (parts, then merged)."""
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    writer = sl.PartWriter(tmp_path / "run.parts")
    ctrl = controller_rows(times)
    ctrl[:pre_arm_rows, 1:] = np.nan  # on the ground: no reference yet
    for i, chunk in enumerate(np.array_split(np.arange(len(times)), 4)):
        a.add_truth(truth_rows(times[chunk]), wall=float(i))
        a.add_controller(ctrl[chunk], wall=float(i))
        writer.write(a.take(wall=i + 0.5), META)
    if merged:
        return sl.merge_parts(tmp_path / "run.parts", tmp_path / "run.parquet", META)
    return tmp_path / "run.parts"


def _direct_record(times: np.ndarray) -> FlightRecord:
    """The FlightRecord built straight from the arrays the session was made of."""
    tr, cr = truth_rows(times), controller_rows(times)
    t = {n: tr[:, i] for i, n in enumerate(sl.TRUTH_FIELDS)}
    c = {n: cr[:, i] for i, n in enumerate(sl.CONTROLLER_FIELDS)}
    return FlightRecord(
        label="direct",
        scenario="helix",
        controller="intbs",
        time_s=times,
        position_m=np.column_stack([t["x_m"], t["y_m"], t["z_m"]]),
        position_ref_m=np.column_stack([c["x_ref_m"], c["y_ref_m"], c["z_ref_m"]]),
        euler_rad=np.column_stack([t["phi_rad"], t["theta_rad"], t["psi_rad"]]),
        euler_ref_rad=np.column_stack([c["phi_ref_rad"], c["theta_ref_rad"], c["psi_ref_rad"]]),
        thrust_n=c["U1_n"],
        torque_euler_n_m=np.column_stack([c["tau_phi_n_m"], c["tau_theta_n_m"], c["tau_psi_n_m"]]),
    )


def _assert_same_indices(a: FlightRecord, b: FlightRecord) -> None:
    ia, ib = indices(a), indices(b)
    np.testing.assert_allclose(ia.final_error_m, ib.final_error_m, rtol=1e-12, atol=1e-12)
    for name in ia.ise:
        assert ia.ise[name] == pytest.approx(ib.ise[name], rel=1e-9, abs=1e-15)
    for name in ia.iadu:
        assert ia.iadu[name] == pytest.approx(ib.iadu[name], rel=1e-9, abs=1e-15)


def test_indices_from_the_log_match_indices_from_the_data(tmp_path: Path) -> None:
    times = control_times(0.0, 2000)
    record = read_session(_session(tmp_path, times))
    assert record.scenario == "helix" and record.controller == "intbs" and record.label == "intbs"
    np.testing.assert_allclose(record.time_s, times, atol=1e-9)
    _assert_same_indices(record, _direct_record(times))
    # Disturbance steps in the truth (Ax at 1 s, Ap at 2 s) become the event times.
    assert record.event_times_s == pytest.approx([1.0, 2.0])
    assert record.disturbance_force_n[-1, 0] == 1.0


def test_window_trims_and_shifts_to_zero(tmp_path: Path) -> None:
    times = control_times(0.0, 3000)  # 0 .. 5.998 s
    t0, duration = 1.5, 2.0
    record = read_session(_session(tmp_path, times), window=(t0, duration))
    assert record.time_s[0] == pytest.approx(0.0, abs=1e-9)
    assert record.time_s[-1] == pytest.approx(duration, abs=1e-9)
    inside = times[(times >= t0 - 1e-9) & (times <= t0 + duration + 1e-9)]
    direct = _direct_record(inside)
    direct.time_s = inside - t0
    _assert_same_indices(record, direct)
    assert record.event_times_s == pytest.approx([0.5])  # the Ap step at 2 s; Ax (1 s) is before t0


def test_rows_without_a_reference_are_dropped(tmp_path: Path) -> None:
    times = control_times(0.0, 1000)
    record = read_session(_session(tmp_path, times, pre_arm_rows=200))
    assert len(record.time_s) == 800
    assert record.time_s[0] == pytest.approx(times[200])


def test_parts_directory_reads_like_the_merged_file(tmp_path: Path) -> None:
    times = control_times(0.0, 1200)
    parts = _session(tmp_path, times, merged=False)
    from_parts = read_session(parts)
    _assert_same_indices(from_parts, _direct_record(times))
    assert read_session(tmp_path / "run").label == "intbs"  # bare NAME finds NAME.parts


def test_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no session log"):
        read_session(tmp_path / "nothing")
    times = control_times(0.0, 100)
    path = _session(tmp_path, times)
    with pytest.raises(ValueError, match="run.parquet: fewer than 2 samples"):
        read_session(path, window=(50.0, 1.0))


def test_inprocess_flight_record_files_are_accepted(tmp_path: Path) -> None:
    times = control_times(0.0, 1000)
    direct = _direct_record(times)
    path = direct.write_parquet(tmp_path / "inproc.parquet")
    record = read_session(path, window=(None, 1.0))  # from the start, 1 s
    assert record.time_s[0] == 0.0 and record.time_s[-1] == pytest.approx(1.0)
    assert record.label == "direct"
    later = read_session(path, window=(0.5, 1.0))  # a t0 trims in-process runs too, shifted to 0
    assert later.time_s[0] == pytest.approx(0.0) and later.time_s[-1] == pytest.approx(1.0)
    assert later.position_m[0] == pytest.approx(direct.position_m[np.searchsorted(direct.time_s, 0.5)])
    with pytest.raises(ValueError, match="no samples"):
        read_session(path, window=(12.3, 1.0))


def test_coalesce_duplicate_times_merges_split_rows() -> None:
    cols = {
        "time_s": np.array([0.004, 0.002, 0.002, 0.006]),
        "x_m": np.array([4.0, 2.0, np.nan, 6.0]),
        "x_ref_m": np.array([40.0, np.nan, 20.0, 60.0]),
    }
    out = coalesce_duplicate_times(cols)
    np.testing.assert_array_equal(out["time_s"], [0.002, 0.004, 0.006])
    np.testing.assert_array_equal(out["x_m"], [2.0, 4.0, 6.0])
    np.testing.assert_array_equal(out["x_ref_m"], [20.0, 40.0, 60.0])


def test_disturbance_events_one_per_step_and_per_ramp() -> None:
    t = np.arange(0.0, 10.0, 0.5)
    d = np.zeros((len(t), 6))
    d[t >= 2.0, 0] = 1.0  # step at 2 s
    ramp = (t >= 5.0) & (t < 7.0)
    d[ramp, 3] = (t[ramp] - 4.5) * 0.2  # a ramp starting at 5 s...
    d[t >= 7.0, 3] = 0.5  # ...then held
    assert disturbance_events(t, d) == [2.0, 5.0]
