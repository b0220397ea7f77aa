"""``quadsitl campaign`` end to end, as a user types it."""

import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

pytest.importorskip("numba")

from . import specs  # noqa: E402

QUADSITL = str(Path(sys.executable).with_name("quadsitl"))


def _run(*args, timeout=600):
    return subprocess.run([QUADSITL, "campaign", *args], capture_output=True, text=True, timeout=timeout)


def _main(capsys, *args) -> tuple[int, str, str]:
    """``quadsitl campaign ARGS`` in this process (the refusals: no need to start one)."""
    from sitl.cli import main

    try:
        code = main(["campaign", *args])
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.timeout(600)
def test_campaign_command_writes_table_summary_and_figures(tmp_path):
    spec = specs.write(tmp_path, specs.BOX, "box", duration=8.0)
    out = tmp_path / "out"
    done = _run(str(spec), "--runs", "4", "--workers", "2", "--out", str(out), "--no-progress")
    assert done.returncode == 0, done.stderr
    assert "## Headline" in done.stdout and "IntBS-NLH∞" in done.stdout
    assert f"results: {out / 'results.parquet'}" in done.stdout
    table = pq.read_table(out / "results.parquet")
    assert table.num_rows == 4 * 3
    summary = (out / "summary.md").read_text()
    assert "| IntBS |" in summary and "failure rate" in summary
    pngs = {p.name for p in (out / "figures").glob("*.png")}
    assert {"distributions.png", "ecdf.png", "ise_vs_mass.png"} <= pngs
    assert any(name.startswith("worst_intbs_nlhinf_run") for name in pngs)
    again = _run(
        str(spec), "--runs", "4", "--workers", "1", "--out", str(out), "--no-progress", "--no-figures"
    )
    assert again.returncode == 0 and "0 runs flown, 4 already done" in again.stdout


@pytest.mark.timeout(600)
def test_full_stack_check_flies_runs_again_and_agrees(tmp_path):
    spec = specs.write(tmp_path, specs.BOX, "box", duration=3.0)
    out = tmp_path / "o"
    done = _run(
        str(spec), "--runs", "3", "--full-stack", "2", "--out", str(out), "--no-progress", "--no-figures"
    )
    assert done.returncode == 0, done.stderr + done.stdout
    assert "flying run(s) 0, 2 again through the full in-process stack" in done.stdout
    assert "full stack: 6 of 6 agree with the batch engine" in done.stdout
    summary = (out / "summary.md").read_text()
    assert "## Full-stack check" in summary and summary.count("| agrees |") == 6


@pytest.mark.timeout(120)
def test_full_stack_refuses_before_flying(tmp_path, capsys):
    spec = specs.write(tmp_path, specs.BOX, "box", duration=2.0)
    code, _, err = _main(capsys, str(spec), "--runs", "2", "--full-stack", "3", "--out", str(tmp_path / "o"))
    assert code == 2 and "--full-stack 3 is invalid; allowed: 1..2" in err
    assert not (tmp_path / "o").exists()  # nothing was flown


def test_a_bad_spec_stops_with_file_key_value_and_range(tmp_path, capsys):
    path = specs.write(tmp_path, specs.BOX.replace("[0.7, 1.3] }}\ninertia", "[0.2, 1.3] }}\ninertia"), "bad")
    code, _, err = _main(capsys, str(path), "--out", str(tmp_path / "o"))
    assert code == 2
    assert str(path) in err and "'plant.mass_scale.uniform[0]'" in err and "[0.5, 2]" in err
