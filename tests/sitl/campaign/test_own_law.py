"""A researcher's law, written into a configuration directory, flies a Monte Carlo campaign in the
compiled batch engine: the engine composes its flight from the law's own kernel."""

from dataclasses import replace

import pytest

from autopilot.control.config import load_controller
from quadcommon.kernel import compiling
from sitl.campaign import engine
from sitl.campaign.runner import run_campaign
from sitl.campaign.spec import load_campaign
from tests.own_law import write_overlay


@pytest.mark.timeout(300)
def test_a_law_from_a_configuration_directory_flies_a_100_run_campaign_compiled(tmp_path, monkeypatch):
    monkeypatch.setenv("QUADSITL_CONFIG_DIR", str(tmp_path / "config"))
    name = write_overlay(tmp_path / "config", "toy_pd_campaign")
    spec = load_campaign("paper_box", runs=100)
    spec = replace(spec, controllers=(load_controller(name), load_controller("bs_nlhinf")), duration_s=10.0)
    result = run_campaign(spec, tmp_path / "out", workers=2, progress=False)
    rows = result.table.to_pylist()
    assert len(rows) == 200 and {r["controller"] for r in rows} == {name, "bs_nlhinf"}
    assert not any(r["failed"] for r in rows)
    ours = [r for r in rows if r["controller"] == name]
    # A PD on position without integral: it keeps an offset under the paper's step disturbances,
    # as BS-NLHinf does; and the runs differ (each flew its own drawn plant).
    assert all(0.005 < r["final_error_m"] < 1.0 for r in ours)
    assert len({round(r["ise_z"], 12) for r in ours}) == 100
    if compiling():
        assert type(engine.entry(name, "nlhinf")).__name__ == "CPUDispatcher"
