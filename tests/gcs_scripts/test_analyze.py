"""analyze(): comparison table and overlaid figures from logs; the quadsitl analyze entry point."""

from __future__ import annotations

from pathlib import Path

from gcs_scripts.analysis.analyze import analyze, main

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
