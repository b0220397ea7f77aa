"""A researcher's law, written into a configuration directory, flies a Monte Carlo campaign in the
compiled batch engine: the engine composes its flight from the law's own kernel."""

from dataclasses import replace

import pytest

from autopilot.control.config import load_controller
from quadcommon.kernel import compiling
from sitl.campaign import engine, full_stack
from sitl.campaign.runner import run_campaign
from sitl.campaign.spec import load_campaign
from tests.own_law import laws_forgotten_afterwards, nan_above, write_overlay


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


@pytest.mark.timeout(300)
def test_a_law_giving_nan_fails_its_runs_as_the_controllers_not_the_plants(tmp_path):
    """The cascade's own check in the batch engine: a non-finite U1 or torque ends the run as the
    controller's failure, named as the autopilot names it; the full stack, flying the same run,
    fails it too."""
    with laws_forgotten_afterwards(tmp_path / "config"):
        name = write_overlay(tmp_path / "config", "toy_nan_campaign", failure=nan_above(1.2))
        spec = replace(load_campaign("paper_box", runs=2), duration_s=4.0,
                       controllers=(load_controller(name), load_controller("bs_nlhinf")))  # fmt: skip
        result = run_campaign(spec, tmp_path / "out", workers=1, progress=False)
        rows = result.table.to_pylist()
        ours = [r for r in rows if r["controller"] == name]
        assert len(ours) == 2
        for row in ours:
            assert row["failed"] and row["failure"] == f"controller {name}: non-finite output", row
            assert 0.0 < row["failure_time_s"] < 4.0  # in flight: it loads at 1 m, as the helix starts
        assert not any(r["failed"] for r in rows if r["controller"] == "bs_nlhinf")
        checked = full_stack.check(spec, result.table, [0])
        assert all(c.batch_failed and c.stack_failed for c in checked if c.controller == name)
        assert all(c.agrees for c in checked)
