"""The summary's numbers are the table's statistics; the drivers found are the real ones."""

import math

import numpy as np
import pyarrow as pa
import pytest

from sitl.campaign.engine import METRIC_COLUMNS
from sitl.campaign.spec import load_campaign
from sitl.campaign.summary import derived_columns, summary_markdown, worst_runs

from . import specs

pytestmark = pytest.mark.timeout(120)


def _table(n: int = 200) -> pa.Table:
    """A synthetic campaign table: the position ISE grows with the mass scale, not the inertia."""
    rng = np.random.default_rng(0)
    rows = []
    for run in range(n):
        mass, inertia = float(rng.uniform(0.7, 1.3)), float(rng.uniform(0.7, 1.3))
        for k, controller in enumerate(("intbs_nlhinf", "intbs", "bs_nlhinf")):
            row = {
                "run": run,
                "controller": controller,
                "mass_scale": mass,
                "inertia_scale": inertia,
                "fixed": 1.0,
            }
            row.update({name: 0.0 for name in METRIC_COLUMNS})
            row["ise_x"] = (10.0**k) * mass**4
            row["final_error_m"] = 0.001 * (k + 1) * mass
            failed = controller == "bs_nlhinf" and mass > 1.25
            row.update(failed=failed, failure="diverged: tilt above the limit" if failed else "",
                       failure_time_s=3.0 if failed else math.nan)  # fmt: skip
            rows.append(row)
    # the summary reads the metric columns after the parameters, as the engine writes them
    order = ["run", "controller", "mass_scale", "inertia_scale", "fixed", *METRIC_COLUMNS, "final_error_m",
             "failed", "failure", "failure_time_s"]  # fmt: skip
    return pa.Table.from_pylist([{k: r[k] for k in order} for r in rows])


def test_headline_is_median_p95_worst_and_failure_rate(tmp_path):
    table = _table()
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box"))
    text = summary_markdown(table, spec)
    names = np.array(table.column("controller").to_pylist())
    failed = np.array(table.column("failed").to_pylist())
    ise = derived_columns(table)["ise_position"]
    sel = (names == "intbs") & ~failed
    line = next(x for x in text.splitlines() if x.startswith("| IntBS |"))
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert float(cells[1]) == pytest.approx(np.median(ise[sel]), rel=5e-3)
    assert float(cells[2]) == pytest.approx(np.percentile(ise[sel], 95), rel=5e-3)
    n_failed = int(((names == "bs_nlhinf") & failed).sum())
    assert 0 < n_failed < 200
    bs = next(x for x in text.splitlines() if x.startswith("| BS-NLH∞ |"))
    assert f"{n_failed}/200" in bs
    assert "IntBS-NLH∞ | " in text and "0/200 (0.0 %)" in text


def test_drivers_are_found_and_constants_ignored(tmp_path):
    table = _table()
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box"))
    text = summary_markdown(table, spec)
    drivers = [x for x in text.splitlines() if "Spearman" in x]
    assert len(drivers) == 3
    for line in drivers:
        first = line.split("position ISE: ")[1].split(",")[0]
        assert first.startswith("mass_scale (ρ = +1.00)"), line
    assert "fixed" not in text.split("randomised: ")[1].splitlines()[0]
    assert "parameters most shifted in the failed runs: mass_scale" in text
    worst = worst_runs(table, ["intbs_nlhinf", "bs_nlhinf"])
    masses = dict(zip(table.column("run").to_pylist(), table.column("mass_scale").to_pylist(), strict=True))
    assert masses[worst["intbs_nlhinf"]] == max(masses.values())  # largest ISE
    assert masses[worst["bs_nlhinf"]] > 1.25  # a failed run comes first


def test_a_u_shaped_driver_is_found(tmp_path):
    """An index that grows with |mass error| on both sides has no monotone rank correlation."""
    table = _table()
    names = table.column("controller").to_pylist()
    mass = table.column("mass_scale").to_pylist()
    old = table.column("ise_x").to_pylist()
    ise = [(m - 1.0) ** 2 if n == "intbs" else v for n, m, v in zip(names, mass, old, strict=True)]
    table = table.set_column(table.column_names.index("ise_x"), "ise_x", pa.array(ise))
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box"))
    line = next(x for x in summary_markdown(table, spec).splitlines() if x.startswith("- **IntBS**"))
    assert line.split("position ISE: ")[1].startswith("|mass_scale - "), line
