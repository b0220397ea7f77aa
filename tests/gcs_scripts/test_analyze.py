"""analyze(): comparison table and overlaid figures from logs; the quadsitl analyze entry point."""

from __future__ import annotations

from pathlib import Path

import pytest

from autopilot.control.config import load_controller
from gcs_scripts.analysis.analyze import analyze, main
from quadcommon.config import load_scenario
from sitl.inprocess import RunOptions, run_scenario

from .helpers import control_times
from .test_log_reader import _direct_record, _session


def test_analyze_writes_table_and_figures(tmp_path: Path) -> None:
    times = control_times(0.0, 1500)
    session = _session(tmp_path, times)
    inproc = _direct_record(times - times[0]).write_parquet(tmp_path / "inproc.parquet")
    out = tmp_path / "out"
    paths = analyze([session, inproc], out, window=[(0.5, 2.0), (None, 2.0)])
    names = sorted(p.name for p in paths)
    assert names == sorted(
        ["comparison.md"]
        + [f"comparison_{k}.png" for k in ("path3d", "position", "position_error", "orientation", "controls")]
    )
    for p in paths:
        assert p.exists() and p.stat().st_size > 0
    text = (out / "comparison.md").read_text()
    assert "| final error x (m) |" in text and "| Index | intbs | direct |" in text
    assert "t0=0.5 s, 2 s" in text and "first 2 s" in text


def test_main_parses_windows_and_reports_errors(tmp_path: Path, capsys) -> None:
    times = control_times(0.0, 1500)
    session = _session(tmp_path, times)
    out = tmp_path / "o"
    assert main([str(session), str(session), "--out", str(out), "--t0", "0.5", "1.0", "--duration", "1"]) == 0
    text = (out / "comparison.md").read_text()
    assert "intbs (run.parquet)" in text and "intbs (run.parquet) #2" in text  # labels made unique
    assert "t0=1 s, 1 s" in text
    assert main([str(tmp_path / "missing.parquet"), "--out", str(out)]) == 2
    assert "no session log" in capsys.readouterr().err


@pytest.fixture(scope="module")
def ekf_mocap_record(tmp_path_factory) -> Path:
    """4 s of the paper's helix flown in-process on the EKF with mocap, as a FlightRecord file."""
    rec = run_scenario(
        load_scenario("helix"),
        load_controller("intbs_nlhinf"),
        RunOptions(duration_s=4.0, estimator="ekf", sensors="mocap"),
    )
    return rec.write_parquet(tmp_path_factory.mktemp("ekf") / "ekf_mocap.parquet")


@pytest.mark.timeout(120)
def test_analyze_draws_estimate_vs_truth_and_tabulates_its_rms(tmp_path: Path, ekf_mocap_record) -> None:
    times = control_times(0.0, 1500)
    truth_only = _direct_record(times).write_parquet(tmp_path / "truth.parquet")
    out = tmp_path / "out"
    paths = analyze([ekf_mocap_record, truth_only], out, labels=["ekf", "truth"])
    names = {p.name for p in paths}
    estimate_figures = {
        f"comparison_estimate_{k}.png" for k in ("position_error", "attitude_error", "test_ratios")
    }
    assert estimate_figures <= names
    for p in paths:
        assert p.exists() and p.stat().st_size > 0
    text = (out / "comparison.md").read_text()
    assert "## Estimation (estimate − truth)" in text
    table = {
        line.split("|")[1].strip(): line.split("|")[2].strip()
        for line in text.split("## Estimation")[1].splitlines()
        if line.startswith("| ") and line.count("|") == 3  # one column: only the run on the EKF
    }
    rms_mm = [float(table[f"RMS e_{a} (mm)"]) for a in "xyz"]
    assert all(0.0 < v < 10.0 for v in rms_mm), table  # mocap (1 mm): well under 1 cm
    assert 0.0 < float(table["RMS ‖e‖ 3-D (mm)"]) < 10.0
    assert all(0.0 < float(table[f"RMS e_{a} (deg)"]) < 1.0 for a in ("φ", "θ", "ψ")), table
    assert 50.0 < float(table["within ±3σ (%)"]) <= 100.0  # the reported variances mean something
    assert int(table["samples with an estimate"]) > 1500


@pytest.mark.timeout(30)
def test_analyze_without_estimator_columns_draws_no_estimate_figures(tmp_path: Path) -> None:
    times = control_times(0.0, 500)
    paths = analyze([_direct_record(times).write_parquet(tmp_path / "t.parquet")], tmp_path / "o")
    assert not any("estimate" in p.name for p in paths)
    assert "## Estimation" not in (tmp_path / "o" / "comparison.md").read_text()
