"""Estimate vs truth: the EKF's errors, their reported 3-sigma bands and its innovation test ratios.

Pure functions of a :class:`FlightRecord` flown on the EKF (``record.estimator`` is not None);
errors are estimate - truth, paper frames. Rows where the filter had no estimate yet (NaN)
are left out of every statistic.

The filter reports one horizontal accuracy, ``sqrt(Pxx + Pyy)`` (PX4's eph); the per-axis
1-sigma of x and y is taken as that over sqrt(2) (equal horizontal variances), z's is the
vertical accuracy (epv).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from quadcommon.bus_records import ESTIMATOR_FIELDS

from .record import FlightRecord

_E = {name: i for i, name in enumerate(ESTIMATOR_FIELDS)}
POSITION = ("x_est_m", "y_est_m", "z_est_m")
EULER = ("phi_est_rad", "theta_est_rad", "psi_est_rad")
RATIOS = ("vel_ratio", "pos_horiz_ratio", "pos_vert_ratio", "mag_ratio")


class EstimationErrors(NamedTuple):
    time_s: np.ndarray  # (M,) rows with an estimate
    position_m: np.ndarray  # (M, 3) estimate - truth
    position_sigma_m: np.ndarray  # (M, 3) the filter's 1-sigma per axis (NaN if not reported)
    euler_rad: np.ndarray  # (M, 3) estimate - truth, wrapped to [-pi, pi)
    ratios: dict[str, np.ndarray]  # PX4's test ratios (> 1: the sample was rejected)


def _column(record: FlightRecord, name: str) -> np.ndarray:
    assert record.estimator is not None
    return record.estimator[:, _E[name]]


def estimation_errors(record: FlightRecord) -> EstimationErrors | None:
    """Errors of the estimate at every row where there is one; None when flown on truth."""
    if record.estimator is None:
        return None
    est = record.estimator
    have = ~np.isnan(est[:, [_E[n] for n in (*POSITION, *EULER)]]).any(axis=1)
    pos = est[have][:, [_E[n] for n in POSITION]] - record.position_m[have]
    eul = est[have][:, [_E[n] for n in EULER]] - record.euler_rad[have]
    eul = (eul + np.pi) % (2.0 * np.pi) - np.pi
    horiz = _column(record, "pos_horiz_accuracy_m")[have] / math.sqrt(2.0)
    sigma = np.column_stack([horiz, horiz, _column(record, "pos_vert_accuracy_m")[have]])
    ratios = {name: _column(record, name)[have] for name in RATIOS}
    return EstimationErrors(record.time_s[have], pos, sigma, eul, ratios)


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else math.nan


class EstimationStats(NamedTuple):
    samples: int
    position_rms_m: tuple[float, float, float]
    position_rms_3d_m: float
    euler_rms_rad: tuple[float, float, float]
    within_3sigma: float  # fraction of (sample, axis) with |error| <= 3 sigma (NaN: no sigma)
    max_ratio: float  # the largest test ratio reported (NaN: none)
    rejected: dict[str, int]  # per test ratio, rows where it exceeded 1


def estimation_stats(record: FlightRecord) -> EstimationStats | None:
    """How well the autopilot's EKF tracked the truth over ``record``: RMS position (m, per axis and
    3-D) and Euler angle errors (rad), the share of position errors within the filter's reported
    3-sigma, the largest of PX4's innovation test ratios and the samples each rejected (ratio > 1);
    None when the record has no estimator columns (flown on truth)."""
    errors = estimation_errors(record)
    if errors is None:
        return None
    pos, eul, sigma = errors.position_m, errors.euler_rad, errors.position_sigma_m
    reported = ~np.isnan(sigma)
    within = float(np.mean(np.abs(pos[reported]) <= 3.0 * sigma[reported])) if reported.any() else math.nan
    all_ratios = np.concatenate([r[~np.isnan(r)] for r in errors.ratios.values()])
    return EstimationStats(
        samples=len(errors.time_s),
        position_rms_m=(_rms(pos[:, 0]), _rms(pos[:, 1]), _rms(pos[:, 2])),
        position_rms_3d_m=_rms(np.linalg.norm(pos, axis=1)),
        euler_rms_rad=(_rms(eul[:, 0]), _rms(eul[:, 1]), _rms(eul[:, 2])),
        within_3sigma=within,
        max_ratio=float(all_ratios.max()) if len(all_ratios) else math.nan,
        rejected={name: int(np.sum(r > 1.0)) for name, r in errors.ratios.items()},
    )


def estimation_markdown(stats: Mapping[str, EstimationStats]) -> str:
    """One column per run flown on the EKF; '' when there is none."""
    if not stats:
        return ""
    labels: Sequence[str] = list(stats)
    rows: list[tuple[str, list[str]]] = [
        ("samples with an estimate", [str(s.samples) for s in stats.values()]),
    ]
    for i, axis in enumerate("xyz"):
        rows.append((f"RMS e_{axis} (mm)", [f"{1e3 * s.position_rms_m[i]:.3f}" for s in stats.values()]))
    rows.append(("RMS ‖e‖ 3-D (mm)", [f"{1e3 * s.position_rms_3d_m:.3f}" for s in stats.values()]))
    for i, angle in enumerate(("φ", "θ", "ψ")):
        rows.append(
            (f"RMS e_{angle} (deg)", [f"{math.degrees(s.euler_rms_rad[i]):.4f}" for s in stats.values()])
        )
    rows.append(("within ±3σ (%)", [f"{100.0 * s.within_3sigma:.1f}" for s in stats.values()]))
    rows.append(("max test ratio", [f"{s.max_ratio:.3f}" for s in stats.values()]))
    for name in RATIOS:
        rows.append((f"rows with {name} > 1", [str(s.rejected[name]) for s in stats.values()]))
    lines = [
        "## Estimation (estimate − truth)",
        "",
        "RMS over the rows where the filter had an estimate; ±3σ from the variances it reports "
        "(horizontal σ per axis = eph/√2, vertical = epv); a test ratio > 1 means the sample was rejected.",
        "",
        "| | " + " | ".join(labels) + " |",
        "|---|" + "---:|" * len(labels),
    ]
    lines += [f"| {name} | " + " | ".join(values) + " |" for name, values in rows]
    return "\n".join(lines) + "\n"
