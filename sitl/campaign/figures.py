"""The campaign's figures (PNG, matplotlib headless).

* ``distributions.png``: per index, one box per controller (completed runs), log scale where the
  values span decades;
* ``ecdf.png``: the empirical CDF of each index, one line per controller;
* ``ise_vs_mass.png``: position ISE against the plant's mass scale, per controller;
* ``faults.png`` (a campaign that draws faults): the share of runs each controller survived,
  against the drawn effectiveness of the first actuator fault when it varies (else per controller),
  and the distribution of the largest excursion after the fault's onset;
* ``worst_<controller>_run<N>_*.png``: the worst run of each controller re-flown by the batch
  engine with its time series recorded, in the paper's figure style
  (:func:`gcs_scripts.analysis.figures.paper_figures`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402

from gcs_scripts.analysis.figures import paper_figures  # noqa: E402

from .summary import INDEX_LABELS, derived_columns, fault_ranking, title  # noqa: E402

FIGURE_INDICES = (
    "ise_position",
    "ise_attitude",
    "final_error_mm",
    "max_position_error_mm",
    "iadu_torque",
    "max_tilt_deg",
)


def _groups(table: pa.Table, controllers: Sequence[str], key: str) -> list[np.ndarray]:
    names = np.array(table.column("controller").to_pylist())
    failed = np.array(table.column("failed").to_pylist(), dtype=bool)
    values = derived_columns(table)[key]
    return [values[(names == c) & ~failed & np.isfinite(values)] for c in controllers]


def _log_scale(groups: list[np.ndarray]) -> bool:
    data = np.concatenate([g for g in groups if g.size]) if any(g.size for g in groups) else np.array([])
    data = data[data > 0]
    return data.size > 0 and data.max() / max(data.min(), 1e-300) > 100.0


def distributions_figure(table: pa.Table, controllers: Sequence[str], path: Path) -> Path:
    """Box plots (whiskers at the 5th and 95th percentiles) of the campaign's indices per controller,
    log scale where the values span decades; saved to ``path``, which is returned."""
    fig, axes = plt.subplots(2, 3, figsize=(12, 7))
    for ax, key in zip(axes.ravel(), FIGURE_INDICES, strict=True):
        groups = _groups(table, controllers, key)
        ax.boxplot([g if g.size else [np.nan] for g in groups], whis=(5, 95), showfliers=True)
        ax.set_xticks(range(1, len(controllers) + 1), [title(c) for c in controllers], fontsize=8,
                      rotation=20, ha="right", rotation_mode="anchor")  # fmt: skip
        if _log_scale(groups):
            ax.set_yscale("log")
        ax.set_title(INDEX_LABELS[key], fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle("Index distributions over completed runs (box: quartiles; whiskers: 5-95 %)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def ecdf_figure(table: pa.Table, controllers: Sequence[str], path: Path) -> Path:
    """The empirical cumulative distribution of each index per controller, log scale where the values
    span decades; saved to ``path``, which is returned."""
    fig, axes = plt.subplots(2, 3, figsize=(12, 7))
    for ax, key in zip(axes.ravel(), FIGURE_INDICES, strict=True):
        groups = _groups(table, controllers, key)
        for c, g in zip(controllers, groups, strict=True):
            if g.size:
                x = np.sort(g)
                ax.step(x, np.arange(1, x.size + 1) / x.size, where="post", label=title(c))
        if _log_scale(groups):
            ax.set_xscale("log")
        ax.set_title(INDEX_LABELS[key], fontsize=9)
        ax.set_ylabel("fraction of runs", fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Empirical CDFs over completed runs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def mass_scatter_figure(table: pa.Table, controllers: Sequence[str], path: Path) -> Path | None:
    """The position ISE (m^2 s) of each run that did not fail against its mass scale, per controller;
    None when the campaign does not vary the mass."""
    if "mass_scale" not in table.column_names:
        return None
    names = np.array(table.column("controller").to_pylist())
    failed = np.array(table.column("failed").to_pylist(), dtype=bool)
    mass = np.array(table.column("mass_scale").to_pylist(), dtype=float)
    ise = derived_columns(table)["ise_position"]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for c in controllers:
        ok = (names == c) & ~failed
        ax.scatter(mass[ok], ise[ok], s=8, alpha=0.6, label=title(c))
        bad = (names == c) & failed
        if bad.any():
            ax.scatter(mass[bad], np.full(bad.sum(), np.nanmax(ise[~failed]) if (~failed).any() else 1.0),
                       marker="x", s=30, label=f"{title(c)} failed")  # fmt: skip
    if _log_scale([ise[~failed]]):
        ax.set_yscale("log")
    ax.set_xlabel("plant mass scale (true / nominal)")
    ax.set_ylabel(INDEX_LABELS["ise_position"])
    ax.set_title("Position ISE against the mass uncertainty")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


FAULT_BINS = 5  # bins of the drawn effectiveness in faults.png


def faults_figure(table: pa.Table, controllers: Sequence[str], path: Path) -> Path | None:
    """What each controller survives: survival against the first actuator fault's drawn
    effectiveness (binned; per controller when it does not vary), and the largest excursion after
    the onset (every run that reached it), controllers in the order of :func:`.summary.fault_ranking`."""
    if "survived" not in table.column_names:
        return None
    ranked = [c for c, _, _ in fault_ranking(table, controllers)]
    names = np.array(table.column("controller").to_pylist())
    survived = np.array(table.column("survived").to_pylist(), dtype=bool)
    excursion = np.array(table.column("max_excursion_m").to_pylist(), dtype=float)
    key = "actuator_fault0_effectiveness"
    drawn = np.array(table.column(key).to_pylist(), dtype=float) if key in table.column_names else None
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.8))
    if drawn is not None and np.nanmax(drawn) > np.nanmin(drawn):
        edges = np.linspace(np.nanmin(drawn), np.nanmax(drawn), FAULT_BINS + 1)
        centres = 0.5 * (edges[:-1] + edges[1:])
        which = np.clip(np.digitize(drawn, edges) - 1, 0, FAULT_BINS - 1)
        for c in ranked:
            share = [survived[(names == c) & (which == b)].mean() if ((names == c) & (which == b)).any()
                     else np.nan for b in range(FAULT_BINS)]  # fmt: skip
            left.plot(centres, 100.0 * np.array(share), marker="o", label=title(c))
        left.set_xlabel("effectiveness the faulty rotor keeps (drawn, binned)")
        left.legend(fontsize=8)
    else:
        shares = [100.0 * survived[names == c].mean() for c in ranked]
        left.bar(range(len(ranked)), shares)
        left.set_xticks(range(len(ranked)), [title(c) for c in ranked], fontsize=8)
    left.set_ylabel("runs survived (%)")
    left.set_ylim(-2.0, 102.0)
    left.set_title("Survival")
    left.grid(True, alpha=0.3)
    groups = [excursion[(names == c) & np.isfinite(excursion)] for c in ranked]
    right.boxplot([g if g.size else [np.nan] for g in groups], whis=(5, 95), showfliers=True)
    right.set_xticks(range(1, len(ranked) + 1), [title(c) for c in ranked], fontsize=8)
    if _log_scale(groups):
        right.set_yscale("log")
    right.set_ylabel("largest position error after the onset (m)")
    right.set_title("Excursion (box: quartiles; whiskers: 5-95 %)")
    right.grid(True, axis="y", alpha=0.3)
    fig.suptitle("Faults: controllers ranked by survival, then by median excursion (left to right)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def worst_run_figures(records, out_dir: Path, controller: str, run: int) -> list[Path]:
    """The paper's figures of one re-flown run (``records``: that run flown by each controller)."""
    return paper_figures(records, out_dir, f"worst_{controller}_run{run}")


def campaign_figures(table: pa.Table, controllers: Sequence[str], out_dir: Path) -> list[Path]:
    """Write the campaign's figures into ``out_dir`` (distributions and ECDFs always, ISE against
    mass and the fault figure when they apply); their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [
        distributions_figure(table, controllers, out_dir / "distributions.png"),
        ecdf_figure(table, controllers, out_dir / "ecdf.png"),
    ]
    for extra in (mass_scatter_figure(table, controllers, out_dir / "ise_vs_mass.png"),
                  faults_figure(table, controllers, out_dir / "faults.png")):  # fmt: skip
        if extra is not None:
            paths.append(extra)
    return paths
