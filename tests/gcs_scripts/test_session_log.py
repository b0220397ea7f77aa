"""The recorder's table: joins (pure), incremental assembly, part files and their merge."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from gcs_scripts import session_log as sl
from quadcommon.bus_records import TRUTH_FIELDS

from .helpers import Vehicle, control_times, controller_rows, parse, truth_rows


def _asof_brute_force(sample_keys, sample_values, row_keys):
    out = np.full(len(row_keys), np.nan)
    for i, r in enumerate(row_keys):
        best = None
        for k, v in zip(sample_keys, sample_values, strict=True):
            if k <= r:
                best = v  # the last sample at or before r (keys sorted, last of equals wins)
        if best is not None:
            out[i] = best
    return out


def test_asof_join_matches_brute_force_on_random_arrays() -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        sample_keys = np.sort(rng.integers(0, 1000, size=rng.integers(0, 40)))
        values = rng.normal(size=len(sample_keys))
        row_keys = np.sort(rng.integers(-50, 1100, size=60))
        got = sl.asof_join(sample_keys, values, row_keys)[:, 0]
        np.testing.assert_array_equal(got, _asof_brute_force(sample_keys, values, row_keys))


def test_asof_join_edges() -> None:
    keys = np.array([10, 20, 20, 30])
    values = np.array([[1.0, 10.0], [2.0, 20.0], [3.0, 30.0], [4.0, 40.0]])
    rows = np.array([5, 10, 19, 20, 25, 30, 99])
    got = sl.asof_join(keys, values, rows)
    np.testing.assert_array_equal(got[:, 0], [np.nan, 1.0, 1.0, 3.0, 3.0, 4.0, 4.0])  # equal keys: last wins
    np.testing.assert_array_equal(got[:, 1], [np.nan, 10.0, 10.0, 30.0, 30.0, 40.0, 40.0])
    assert sl.asof_join(np.empty(0, dtype=np.int64), np.empty((0, 2)), rows).shape == (7, 2)


def test_exact_join_and_dedupe() -> None:
    keys, values = sl.dedupe_sorted(np.array([30, 10, 20, 10]), np.array([3.0, 1.0, 2.0, 1.5]))
    np.testing.assert_array_equal(keys, [10, 20, 30])
    np.testing.assert_array_equal(values, [1.5, 2.0, 3.0])  # the later row of a key replaces the first
    got = sl.exact_join(keys, values, np.array([5, 10, 15, 30, 40]))[:, 0]
    np.testing.assert_array_equal(got, [np.nan, 1.5, np.nan, 3.0, np.nan])


def test_time_key_unifies_float_instants_of_both_processes() -> None:
    # The simulator computes k * dt; the autopilot time_usec * 1e-6: different floats, same µs.
    k = np.arange(100_000, 100_100)
    assert np.array_equal(sl.time_key(k * 0.002), sl.time_key(np.rint(k * 2000.0) * 1e-6))


def _feed(assembler: sl.SessionAssembler, times: np.ndarray, wall: float, vehicle: Vehicle) -> None:
    assembler.add_truth(truth_rows(times), wall)
    assembler.add_controller(controller_rows(times), wall)
    frames = [vehicle.heartbeat(armed=True)]
    for t in times[::15]:  # LOCAL_POSITION_NED at ~33 Hz, stamped in whole ms
        frames.append(vehicle.local_position(t, x=round(t, 3) * 10.0))
    for msg in parse(frames):
        assembler.add_mavlink(msg, wall)


def test_assembler_joins_and_hands_out_rows_up_to_the_watermark() -> None:
    vehicle = Vehicle(instance=2)
    a = sl.SessionAssembler(system_id=3, wall=0.0)
    times = control_times(1.0, 500)  # 1.000 .. 1.998 s
    _feed(a, times, wall=0.1, vehicle=vehicle)
    # Controller is behind: only rows up to its latest time may go out (exact join intact).
    a.add_truth(truth_rows(control_times(2.0, 100)), wall=0.2)
    table = a.take(wall=0.3)
    cols = {n: table.column(n).to_numpy() for n in table.column_names}
    assert table.schema.names == sl.SCHEMA.names
    last_mav = sl.time_key(times[::15][-1])
    assert cols["time_s"][-1] == pytest.approx(last_mav * 1e-6)  # min over the live streams
    np.testing.assert_allclose(cols["x_m"], np.sin(cols["time_s"]))
    np.testing.assert_allclose(cols["x_ref_m"], controller_rows(cols["time_s"])[:, 1])
    # As-of: the latest LOCAL_POSITION_NED stamped at or before the row.
    assert np.all(cols["mav_local_time_s"] <= cols["time_s"] + 1e-12)
    assert np.all(cols["time_s"] - cols["mav_local_time_s"] < 15 * 0.002 + 1e-9)
    np.testing.assert_allclose(cols["mav_local_x_m"], np.round(cols["mav_local_time_s"], 3) * 10.0, atol=1e-5)
    # HEARTBEAT (no stamp) took the stamp of the next stamped message: valid from the first row.
    assert np.all(cols["mav_armed"] == 1.0)
    # The rest comes out on the final take, without duplicates.
    rest = a.take(wall=0.4, final=True)
    all_times = np.concatenate([cols["time_s"], rest.column("time_s").to_numpy()])
    assert np.all(np.diff(all_times) > 0)
    assert len(all_times) == 600
    tail = {n: rest.column(n).to_numpy() for n in ("x_ref_m", "x_m")}
    assert np.isnan(tail["x_ref_m"][-100:]).all() and not np.isnan(tail["x_m"]).any()


def test_assembler_stale_stream_does_not_hold_rows_back() -> None:
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    a.add_controller(controller_rows(control_times(0.0, 10)), wall=0.0)  # then the autopilot goes quiet
    a.add_truth(truth_rows(control_times(0.0, 1000)), wall=5.0)
    held = a.take(wall=4.9)  # controller silent for less than STALE_WALL_S: it holds the rest back
    assert held.num_rows == 10 and not np.isnan(held.column("x_ref_m").to_numpy()).any()
    table = a.take(wall=5.1)  # controller stale (> 5 s): the truth alone sets the watermark
    assert table.num_rows == 990
    assert np.isnan(table.column("x_ref_m").to_numpy()).all()


def test_assembler_without_zenoh_falls_back_to_mavlink_rows() -> None:
    vehicle = Vehicle()
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    msgs = parse([vehicle.local_position(0.1 * k, x=float(k)) for k in range(10)])
    for m in msgs:
        a.add_mavlink(m, wall=0.5)
    assert a.take(wall=0.6) is None  # zenoh may still come: wait
    table = a.take(wall=10.0, final=True)
    np.testing.assert_allclose(table.column("time_s").to_numpy(), 0.1 * np.arange(10))
    np.testing.assert_array_equal(table.column("mav_local_x_m").to_numpy(), np.arange(10.0))


def test_only_the_telemetry_clock_sets_the_recording_start() -> None:
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    vehicle = Vehicle()
    # The autopilot may send HOME_POSITION with time_usec = 0 before its first frame.
    for m in parse([vehicle.home_position(time_usec=0), vehicle.local_position(12.5, 0.0)]):
        a.add_mavlink(m, wall=0.0)
    assert a.first_time_s == 12.5
    assert a.mav["home"].keys == [0]  # still tabulated (as of any later row)


def test_assembler_ignores_other_systems_and_collects_statustext() -> None:
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    mine, other = Vehicle(0), Vehicle(5)
    for m in parse([other.local_position(1.0, 9.0), mine.local_position(1.0, 1.0), mine.statustext("armed")]):
        a.add_mavlink(m, wall=0.0)
    assert a.mav["local"].values == [(1.0, 0.0, 0.0, 0.0, 0.0, 0.0)]
    assert a.statustext == [(1.0, 6, "armed")]


def test_parts_merge_and_read_back(tmp_path: Path) -> None:
    a = sl.SessionAssembler(system_id=1, wall=0.0)
    writer = sl.PartWriter(tmp_path / "s.parts")
    for k in range(3):
        times = control_times(k * 0.2, 100)
        a.add_truth(truth_rows(times), wall=k)
        a.add_controller(controller_rows(times), wall=k)
        writer.write(a.take(wall=k + 0.5), {"part": k, "scenario": "circle"})
    assert [p.name for p in sl.part_paths(tmp_path / "s.parts")] == [
        "part-000001.parquet",
        "part-000002.parquet",
        "part-000003.parquet",
    ]
    for p in sl.part_paths(tmp_path / "s.parts"):
        assert pq.read_table(p).num_rows == 100  # each part is a complete file
    table, meta = sl.read_session_table(tmp_path / "s.parts")
    assert table.num_rows == 300 and meta["part"] == 2  # metadata of the last part
    merged = sl.merge_parts(
        tmp_path / "s.parts", tmp_path / "s.parquet", {"scenario": "circle", "done": True}
    )
    assert not (tmp_path / "s.parts").exists()
    table2, meta2 = sl.read_session_table(tmp_path / "s")  # bare NAME resolves to NAME.parquet
    assert merged.exists() and meta2["done"] is True
    assert table2.num_rows == 300
    assert pq.ParquetFile(merged).num_row_groups == 3  # streamed part by part
    np.testing.assert_array_equal(table2.column("time_s").to_numpy(), table.column("time_s").to_numpy())


def test_column_descriptions_cover_every_column_and_name_the_frames() -> None:
    desc = sl.column_descriptions()
    assert set(desc) == set(sl.column_names(estimator=True))
    assert "NED" in desc["mav_local_z_m"] and "paper" in desc["z_m"]
    assert sl.column_names()[: len(TRUTH_FIELDS)] == list(TRUTH_FIELDS)
