"""Tables I-III as Markdown (ours beside the paper's) and as CSV."""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from pathlib import Path

from .metrics import CONTROL_NAMES, STATE_NAMES, Indices

CONTROLLER_TITLES = {
    "intbs_nlhinf": "IntBS-NLH∞",
    "intbs": "IntBS",
    "bs_nlhinf": "BS-NLH∞",
    "px4_pid": "PX4 PID",
    "px4_pid_tuned": "PX4 PID, autotuned",
    "se3": "SE(3)",
}

# Raffo, Ortega & Rubio, Tables I-III (helix scenario, Section IV).
PAPER_FINAL_ERRORS_M = {
    "intbs_nlhinf": (0.000, 0.000, 0.000),
    "intbs": (-0.005, -0.012, -0.004),
    "bs_nlhinf": (-0.036, -0.013, -0.076),
}
PAPER_ISE = {
    "intbs_nlhinf": (0.0581, 0.0757, 0.3157, 3.3139, 0.7943, 6.3049),
    "intbs": (1.7184, 1.3414, 11.8193, 5.3811, 1.6494, 7.9193),
    "bs_nlhinf": (2.6305, 0.4271, 22.9256, 20.0234, 10.9833, 29.3531),
}
PAPER_IADU = {
    "intbs_nlhinf": (6.1642, 29.8298, 33.0568, 17.5876),
    "intbs": (6.0747, 95.0931, 108.4128, 12.3266),
    "bs_nlhinf": (6.1033, 28.7654, 31.7607, 16.5672),
}
PAPER_SCENARIO = "helix"

Results = Mapping[tuple[str, str], Indices]  # (scenario, controller) -> indices


def _title(controller: str) -> str:
    return CONTROLLER_TITLES.get(controller, controller)


def _fmt(value: float, digits: int) -> str:
    return f"{value:.{digits}f}"


def _paper_table(
    results: Results,
    scenario: str,
    controllers: Sequence[str],
    rows: Sequence[str],
    ours,
    paper: Mapping[str, Sequence[float]] | None,
    digits: int,
    unit: str,
) -> list[str]:
    header = f"| {unit} |"
    rule = "|---|"
    for c in controllers:  # the paper's column beside ours for the controllers it flew
        in_paper = paper is not None and c in paper
        header += f" {_title(c)} (ours) |" + (f" {_title(c)} (paper) |" if in_paper else "")
        rule += "---:|" + ("---:|" if in_paper else "")
    lines = [header, rule]
    for i, row in enumerate(rows):
        line = f"| {row} |"
        for c in controllers:
            line += f" {_fmt(ours(results[(scenario, c)])[i], digits)} |"
            if paper is not None and c in paper:
                line += f" {_fmt(paper[c][i], digits)} |"
        lines.append(line)
    return lines


def paper_tables_markdown(results: Results, scenarios: Sequence[str], controllers: Sequence[str]) -> str:
    """Tables I-III for each scenario; the paper's numbers stand beside ours for its helix."""
    out = ["# Tables I-III: ours beside the paper's", ""]
    out.append(
        "Errors are actual − desired. ISE = ∫e² dt over the run (m²s, rad²s); IADU = ∫|du/dt| dt "
        "(total variation of the control sampled at the control rate). The paper's tables are for "
        "its helix experiment; its absolute values are not reproducible from what it prints "
        "(see the documentation, The paper in code: 'How our numbers differ from the paper's')."
    )
    for scenario in scenarios:
        paper = scenario == PAPER_SCENARIO
        out += ["", f"## Scenario `{scenario}`", "", "### Table I — final position errors (m)", ""]
        out += _paper_table(
            results,
            scenario,
            controllers,
            ("x", "y", "z"),
            lambda r: r.final_error_m,
            PAPER_FINAL_ERRORS_M if paper else None,
            4,
            "Axis",
        )
        out += ["", "### Table II — ISE", ""]
        out += _paper_table(
            results,
            scenario,
            controllers,
            STATE_NAMES,
            lambda r: [r.ise[n] for n in STATE_NAMES],
            PAPER_ISE if paper else None,
            4,
            "State",
        )
        out += ["", "### Table III — IADU", ""]
        out += _paper_table(
            results,
            scenario,
            controllers,
            CONTROL_NAMES,
            lambda r: [r.iadu[n] for n in CONTROL_NAMES],
            PAPER_IADU if paper else None,
            4,
            "Input",
        )
    return "\n".join(out) + "\n"


def write_paper_csvs(results: Results, out_dir: Path) -> list[Path]:
    """Tables I-III as CSV files, a row per (scenario, controller)."""
    out_dir = Path(out_dir)
    specs = [
        ("table1_final_errors.csv", ("x", "y", "z"), lambda r: r.final_error_m),
        ("table2_ise.csv", STATE_NAMES, lambda r: [r.ise[n] for n in STATE_NAMES]),
        ("table3_iadu.csv", CONTROL_NAMES, lambda r: [r.iadu[n] for n in CONTROL_NAMES]),
    ]
    paths = []
    for filename, columns, values in specs:
        path = out_dir / filename
        with path.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["scenario", "controller", *columns])
            for (scenario, controller), ind in results.items():
                writer.writerow([scenario, controller, *(f"{v:.9g}" for v in values(ind))])
        paths.append(path)
    return paths


def comparison_markdown(indices_by_label: Mapping[str, Indices]) -> str:
    """One Markdown table comparing several runs: a column per run, a row per index."""
    labels = list(indices_by_label)
    lines = ["| Index | " + " | ".join(labels) + " |", "|---|" + "---:|" * len(labels)]

    def row(name: str, values: Sequence[float], digits: int = 4) -> None:
        lines.append(f"| {name} | " + " | ".join(_fmt(v, digits) for v in values) + " |")

    for i, axis in enumerate(("x", "y", "z")):
        row(f"final error {axis} (m)", [indices_by_label[k].final_error_m[i] for k in labels])
    for n in STATE_NAMES:
        row(f"ISE {n}", [indices_by_label[k].ise[n] for k in labels])
    for n in CONTROL_NAMES:
        row(f"IADU {n}", [indices_by_label[k].iadu[n] for k in labels])
    return "\n".join(lines) + "\n"
