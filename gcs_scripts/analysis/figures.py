"""Paper-style figures (Figs 3-10) as PNG, for one run or overlaid runs.

Disturbance instants are marked by dotted vertical lines. Matplotlib runs headless (Agg).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .record import FlightRecord  # noqa: E402
from .tables import _title  # noqa: E402


def _mark_events(ax, times: Sequence[float]) -> None:
    for t in times:
        ax.axvline(t, color="0.6", linestyle=":", linewidth=0.8)


def _label(rec: FlightRecord) -> str:
    return _title(rec.label)


def plot_path_3d(records: Sequence[FlightRecord], path: Path, title: str) -> Path:
    """Plot the reference (dashed, from the first record) and each record's path in the world frame
    (x, y, z in m, z up); save to ``path`` and return it."""
    fig = plt.figure(figsize=(6.5, 5.5))
    ax = fig.add_subplot(projection="3d")
    ref = records[0].position_ref_m
    ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], "k--", linewidth=1.0, label="reference")
    for rec in records:
        p = rec.position_m
        ax.plot(p[:, 0], p[:, 1], p[:, 2], linewidth=1.0, label=_label(rec))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _series_figure(
    records: Sequence[FlightRecord],
    path: Path,
    title: str,
    names: Sequence[str],
    series,
    reference=None,
    ylabel_unit: str = "",
) -> Path:
    rows = len(names)
    fig, axes = plt.subplots(rows, 1, figsize=(7.5, 1.9 * rows + 0.6), sharex=True)
    axes = np.atleast_1d(axes)
    for i, (ax, name) in enumerate(zip(axes, names, strict=True)):
        if reference is not None:
            ref = reference(records[0])
            ax.plot(records[0].time_s, ref[:, i], "k--", linewidth=1.0, label="reference")
        for rec in records:
            ax.plot(rec.time_s, series(rec)[:, i], linewidth=1.0, label=_label(rec))
        _mark_events(ax, records[0].event_times_s)
        ax.set_ylabel(f"{name}{ylabel_unit}")
        ax.grid(True, linewidth=0.3)
    axes[0].set_title(title)
    axes[0].legend(loc="best", fontsize=7, ncol=4)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def paper_figures(records: Sequence[FlightRecord], out_dir: Path, prefix: str) -> list[Path]:
    """Path in 3-D, position, position error, orientation, control inputs."""
    out_dir = Path(out_dir)
    scenario = records[0].scenario
    paths = [
        plot_path_3d(records, out_dir / f"{prefix}_path3d.png", f"{scenario}: path tracking"),
        _series_figure(
            records,
            out_dir / f"{prefix}_position.png",
            f"{scenario}: position",
            ("x", "y", "z"),
            lambda r: r.position_m,
            lambda r: r.position_ref_m,
            " (m)",
        ),
        _series_figure(
            records,
            out_dir / f"{prefix}_position_error.png",
            f"{scenario}: position error (actual − desired)",
            ("e_x", "e_y", "e_z"),
            lambda r: r.position_error_m,
            None,
            " (m)",
        ),
        _series_figure(
            records,
            out_dir / f"{prefix}_orientation.png",
            f"{scenario}: orientation",
            ("φ", "θ", "ψ"),
            lambda r: r.euler_rad,
            lambda r: r.euler_ref_rad,
            " (rad)",
        ),
        _series_figure(
            records,
            out_dir / f"{prefix}_controls.png",
            f"{scenario}: control inputs",
            ("U1 (N)", "τ_φ (N m)", "τ_θ (N m)", "τ_ψ (N m)"),
            lambda r: r.controls,
        ),
    ]
    return paths


def estimation_figures(records: Sequence[FlightRecord], out_dir: Path, prefix: str) -> list[Path]:
    """Estimate vs truth of the runs flown on the EKF: position error with the filter's ±3σ,
    attitude error, innovation test ratios. None when no run has estimator rows."""
    from .estimation import RATIOS, estimation_errors

    runs = [(rec, e) for rec in records if (e := estimation_errors(rec)) is not None]
    if not runs:
        return []
    out_dir = Path(out_dir)
    scenario = runs[0][0].scenario
    paths: list[Path] = []

    fig, axes = plt.subplots(3, 1, figsize=(7.5, 6.3), sharex=True)
    for i, (ax, axis) in enumerate(zip(axes, "xyz", strict=True)):
        for rec, e in runs:
            (line,) = ax.plot(e.time_s, 1e3 * e.position_m[:, i], linewidth=0.8, label=_label(rec))
            band = 3e3 * e.position_sigma_m[:, i]
            if not np.isnan(band).all():
                ax.fill_between(e.time_s, -band, band, color=line.get_color(), alpha=0.15, linewidth=0)
        first = runs[0][0]
        _mark_events(ax, [t for t in first.event_times_s if first.time_s[0] <= t <= first.time_s[-1]])
        ax.set_ylabel(f"ê_{axis} (mm)")
        ax.grid(True, linewidth=0.3)
    axes[0].set_title(f"{scenario}: position estimate − truth (band: the filter's ±3σ)")
    axes[0].legend(loc="best", fontsize=7, ncol=4)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}_estimate_position_error.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(3, 1, figsize=(7.5, 6.3), sharex=True)
    for i, (ax, angle) in enumerate(zip(axes, ("φ", "θ", "ψ"), strict=True)):
        for rec, e in runs:
            ax.plot(e.time_s, np.degrees(e.euler_rad[:, i]), linewidth=0.8, label=_label(rec))
        ax.set_ylabel(f"ê_{angle} (deg)")
        ax.grid(True, linewidth=0.3)
    axes[0].set_title(f"{scenario}: attitude estimate − truth")
    axes[0].legend(loc="best", fontsize=7, ncol=4)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}_estimate_attitude_error.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(len(RATIOS), 1, figsize=(7.5, 1.8 * len(RATIOS) + 0.6), sharex=True)
    for ax, name in zip(axes, RATIOS, strict=True):
        for rec, e in runs:
            ax.plot(e.time_s, e.ratios[name], linewidth=0.8, label=_label(rec))
        ax.axhline(1.0, color="r", linestyle="--", linewidth=0.8)  # above: rejected
        ax.set_ylabel(name, fontsize=8)
        ax.grid(True, linewidth=0.3)
    axes[0].set_title(f"{scenario}: innovation test ratios (> 1: rejected)")
    axes[0].legend(loc="best", fontsize=7, ncol=4)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}_estimate_test_ratios.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths
