"""The estimator's rows in the records: FlightRecord's Parquet and the recorder's session log.

Flown on the EKF, both files carry the estimator columns (``x_est_m``...) beside the truth;
flown on truth they have none (the files older readers know); older files still load.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from gcs_scripts import session_log as sl
from gcs_scripts.analysis.log_reader import read_session
from gcs_scripts.analysis.record import ESTIMATOR_COLUMNS, FlightRecord
from quadcommon.bus_records import ESTIMATOR_FIELDS

from .helpers import control_times, controller_rows, truth_rows

pytestmark = pytest.mark.timeout(30)

META = {"scenario": "helix", "controller": "intbs_nlhinf", "vehicle": "paper_quad"}
_E = {n: i for i, n in enumerate(ESTIMATOR_FIELDS)}


def estimator_rows(times: np.ndarray, nan_before: int = 0) -> np.ndarray:
    """Rows with known values: x_est = sin t + 1 mm, the rest a distinct value per column."""
    rows = np.zeros((len(times), len(ESTIMATOR_FIELDS)))
    rows[:, 0] = times
    for i in range(1, len(ESTIMATOR_FIELDS)):
        rows[:, i] = 0.001 * i + 1e-4 * times
    rows[:, _E["x_est_m"]] = np.sin(times) + 0.001
    rows[:nan_before, 1:] = np.nan  # no estimate yet
    return rows


def _record(times: np.ndarray, estimator: np.ndarray | None) -> FlightRecord:
    n = len(times)
    pos = np.column_stack([np.sin(times), np.cos(times), 1.0 + times])
    return FlightRecord(
        label="intbs_nlhinf",
        scenario="helix",
        controller="intbs_nlhinf",
        time_s=times,
        position_m=pos,
        position_ref_m=pos + 0.01,
        euler_rad=np.zeros((n, 3)),
        euler_ref_rad=np.zeros((n, 3)),
        thrust_n=np.full(n, 9.81),
        torque_euler_n_m=np.zeros((n, 3)),
        estimator=estimator,
    )


# -- FlightRecord ---------------------------------------------------------------------------------
def test_flight_record_round_trips_its_estimator_rows(tmp_path: Path) -> None:
    times = control_times(0.0, 200)
    est = estimator_rows(times, nan_before=5)
    path = _record(times, est).write_parquet(tmp_path / "ekf.parquet")
    assert set(ESTIMATOR_COLUMNS) <= set(pq.read_schema(path).names)
    back = FlightRecord.read_parquet(path)
    assert back.estimator is not None
    np.testing.assert_array_equal(back.estimator, est)  # NaN rows included (array_equal: NaN == NaN)
    # A window keeps the estimator rows that belong to it.
    part = back.window(0.1, 0.2, shift=True)
    assert part.estimator is not None and len(part.estimator) == len(part.time_s)
    np.testing.assert_array_equal(
        part.estimator[:, 1:], est[(times >= 0.1 - 1e-6) & (times <= 0.2 + 1e-6), 1:]
    )


def test_flight_record_on_truth_has_no_estimator_columns(tmp_path: Path) -> None:
    times = control_times(0.0, 50)
    path = _record(times, None).write_parquet(tmp_path / "truth.parquet")
    names = pq.read_schema(path).names
    assert not any(n in names for n in ESTIMATOR_COLUMNS)
    assert FlightRecord.read_parquet(path).estimator is None


def test_flight_record_rejects_an_estimator_of_the_wrong_length() -> None:
    times = control_times(0.0, 20)
    with pytest.raises(ValueError, match="estimator"):
        _record(times, estimator_rows(times[:-1]))


# -- the recorder's session log ---------------------------------------------------------------
def _session(tmp_path: Path, estimator_from_part: int | None, merged: bool = True) -> tuple[Path, np.ndarray]:
    """Four parts; the estimator's rows start arriving with part ``estimator_from_part`` (None: never)."""
    times = control_times(1.0, 400)
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    writer = sl.PartWriter(tmp_path / "run.parts")
    for i, chunk in enumerate(np.array_split(np.arange(len(times)), 4)):
        a.add_truth(truth_rows(times[chunk]), wall=float(i))
        a.add_controller(controller_rows(times[chunk]), wall=float(i))
        if estimator_from_part is not None and i >= estimator_from_part:
            a.add_estimator(estimator_rows(times[chunk]), wall=float(i))
        writer.write(a.take(wall=i + 0.5), META)
    if merged:
        return sl.merge_parts(tmp_path / "run.parts", tmp_path / "run.parquet", META), times
    return tmp_path / "run.parts", times


def test_session_flown_on_truth_has_exactly_the_old_columns(tmp_path: Path) -> None:
    path, _ = _session(tmp_path, None)
    table, _ = sl.read_session_table(path)
    assert table.schema.names == sl.SCHEMA.names
    assert read_session(path).estimator is None


@pytest.mark.parametrize("merged", [True, False])
def test_session_on_the_ekf_records_estimate_beside_truth(tmp_path: Path, merged: bool) -> None:
    # The estimator's first rows come with the second part: the first part has no such columns.
    path, times = _session(tmp_path, 1, merged=merged)
    if not merged:
        first = sl.part_paths(path)[0]
        assert "x_est_m" not in pq.read_schema(first).names
    table, _ = sl.read_session_table(path)
    assert table.schema.names == sl.SCHEMA_WITH_ESTIMATOR.names
    assert table.num_rows == len(times)
    x_est = table.column("x_est_m").to_numpy()
    first_part = len(np.array_split(np.arange(len(times)), 4)[0])
    assert np.isnan(x_est[:first_part]).all()  # before the estimator's rows: NaN, not lost rows
    np.testing.assert_allclose(x_est[first_part:], np.sin(times[first_part:]) + 0.001)
    np.testing.assert_allclose(table.column("x_m").to_numpy(), np.sin(times))  # truth intact
    record = read_session(path)
    assert record.estimator is not None and record.estimator.shape == (
        len(record.time_s),
        len(ESTIMATOR_FIELDS),
    )
    np.testing.assert_allclose(record.estimator[:, 0], record.time_s)
    ok = ~np.isnan(record.estimator[:, _E["x_est_m"]])
    err = record.estimator[ok, _E["x_est_m"]] - record.position_m[ok, 0]
    np.testing.assert_allclose(err, 0.001, atol=1e-12)


def test_estimator_rows_after_the_watermark_wait_and_come_out_on_the_final_take() -> None:
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    times = control_times(0.0, 300)
    a.add_truth(truth_rows(times), wall=0.1)
    a.add_controller(controller_rows(times), wall=0.1)
    a.add_estimator(estimator_rows(times[:200]), wall=0.1)  # the estimator is behind
    table = a.take(wall=0.2)
    assert table.num_rows == 200  # the live estimator stream holds the exact join back
    a.add_estimator(estimator_rows(times[200:]), wall=0.3)
    rest = a.take(wall=0.4, final=True)
    assert rest.num_rows == 100
    assert not np.isnan(rest.column("x_est_m").to_numpy()).any()
    # Rows of the estimator alone (before truth started, after it stopped) are kept, like truth's.
    b = sl.SessionAssembler(system_id=1, wall=0.0)
    b.add_estimator(estimator_rows(control_times(0.0, 10)), wall=0.0)
    b.add_truth(truth_rows(control_times(0.02, 10)), wall=0.0)
    out = b.take(wall=0.1, final=True)
    assert out.num_rows == 20
    assert np.isnan(out.column("x_m").to_numpy()[:10]).all()
    assert np.isnan(out.column("x_est_m").to_numpy()[10:]).all()


def test_a_recording_that_ends_while_streaming_leaves_out_the_ragged_tail() -> None:
    """Stopped on its own condition, the last take ends where every stream still flowing at the
    stop has arrived: the truth rows whose estimate is still in flight are left out, not given
    empty estimator cells. A stream that stopped before does not hold the end back; a plain final
    take (Ctrl-C) keeps everything."""
    times = control_times(0.0, 300)

    def assembler(estimator_wall: float = 0.1) -> sl.SessionAssembler:
        a = sl.SessionAssembler(system_id=1, wall=0.0)
        a.add_truth(truth_rows(times), wall=0.1)
        a.add_controller(controller_rows(times), wall=0.1)
        a.add_estimator(estimator_rows(times[:280]), wall=estimator_wall)  # its last 20 rows behind
        return a

    whole = assembler().take(wall=0.2, final=True, flowing_since=0.1)
    assert whole.num_rows == 280 and not np.isnan(whole.column("x_est_m").to_numpy()).any()
    everything = assembler().take(wall=0.2, final=True)
    assert everything.num_rows == 300 and np.isnan(everything.column("x_est_m").to_numpy()[280:]).all()
    # The estimator stopped (wall 0.05) before the stop was decided (0.1): its rows are complete.
    stopped = assembler(estimator_wall=0.05).take(wall=0.2, final=True, flowing_since=0.1)
    assert stopped.num_rows == 300
