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
