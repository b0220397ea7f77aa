"""`quadsitl paper` end to end: tables (Markdown and CSV), figures, run files."""

import csv

from autopilot.control.config import CONTROLLER_NAMES
from gcs_scripts.analysis.record import FlightRecord
from sitl.cli import main


def test_paper_command_writes_tables_figures_and_runs(tmp_path, capsys):
    """The command's outputs, on short runs (the paper's pattern itself: test_inprocess.py)."""
    assert main(["paper", "--out", str(tmp_path), "--workers", "2", "--duration", "6"]) == 0
    printed = capsys.readouterr().out
    runs = 2 * len(CONTROLLER_NAMES)  # circle and helix, every shipped cascade (the baselines too)
    assert f"[{runs}/{runs}]" in printed and "tables.md" in printed
    expected_columns = {
        "table1_final_errors.csv": ["scenario", "controller", "x", "y", "z"],
        "table2_ise.csv": ["scenario", "controller", "x", "y", "z", "phi", "theta", "psi"],
        "table3_iadu.csv": ["scenario", "controller", "U1", "tau_phi", "tau_theta", "tau_psi"],
    }
    for name, columns in expected_columns.items():
        with (tmp_path / name).open() as handle:
            rows = list(csv.reader(handle))
        assert rows[0] == columns
        keys = {(r[0], r[1]) for r in rows[1:]}
        assert keys == {(s, c) for s in ("circle", "helix") for c in CONTROLLER_NAMES}
    with (tmp_path / "table1_final_errors.csv").open() as handle:
        finals = {(r["scenario"], r["controller"]): r for r in csv.DictReader(handle)}
    assert all(abs(float(finals[("helix", "intbs_nlhinf")][a])) < 0.05 for a in "xyz")
    md = (tmp_path / "tables.md").read_text()
    assert "0.0581" in md  # the paper's ISE x for IntBS-NLHinf stands beside ours
    for scenario in ("circle", "helix"):
        for fig in ("path3d", "position", "position_error", "orientation", "controls"):
            png = tmp_path / f"{scenario}_{fig}.png"
            assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rec = FlightRecord.read_parquet(tmp_path / "runs" / "helix_bs_nlhinf.parquet")
    assert rec.controller == "bs_nlhinf" and rec.scenario == "helix"
    assert abs(rec.time_s[-1] - 6.0) < 1e-9
