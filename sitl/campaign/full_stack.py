"""``quadsitl campaign --full-stack K``: fly K sampled runs through the whole in-process stack.

The batch engine (:mod:`.kernels`) flies the same kernels as the flight stack (the plant, the laws,
on the estimate the sensor models and the filter), and is tested equal to it
(``tests/sitl/campaign/test_agreement.py``). This check repeats that proof on the user's own
campaign: K of its runs, spread evenly over the campaign, are flown again by
:func:`sitl.inprocess.paper_stack` (simulator core, every frame MAVLink-encoded and decoded,
autopilot core with its commander and cascade, the run's drawn plant, initial state and
disturbances; on the estimate, the run's sensors and the autopilot's EKF) and their indices are
compared with the campaign's table.

Two runs agree when every index matches to ``rel_tol`` (default 1e-6: the two paths agree to
rounding, measured ~1e-12) and the failure verdict is the same. A run that failed in the batch
engine stops there; the full stack flies on, so for those only the verdict is compared (the
full-stack record is judged by the same limits: position error, tilt, non-finite state; a flight the
autopilot terminates because the law's output is non-finite fails it, as the batch engine fails a
run on the same check).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from .spec import CampaignSpec

#: The indices compared (columns of the results table, see :data:`.engine.METRIC_COLUMNS`).
COMPARED = (
    "final_error_x_m", "final_error_y_m", "final_error_z_m",
    "ise_x", "ise_y", "ise_z", "ise_phi", "ise_theta", "ise_psi",
    "iadu_U1", "iadu_tau_phi", "iadu_tau_theta", "iadu_tau_psi",
    "max_position_error_m", "max_tilt_rad",
)  # fmt: skip


class FullStackRefused(ValueError):
    """The campaign cannot be checked against the full stack (the message says why)."""


@dataclass(frozen=True)
class Comparison:
    run: int
    controller: str
    batch_failed: bool
    stack_failed: bool
    worst_index: str  # the index that differs most (relative), "" when not compared
    worst_relative: float  # its relative difference (0 when not compared)

    @property
    def agrees(self) -> bool:
        """Batch engine and full stack agree: the same failure verdict and every compared index within
        ``rel_tol`` (relative)."""
        return self.batch_failed == self.stack_failed and self.worst_relative <= self.rel_tol

    rel_tol: float = 1e-6


def pick_runs(total: int, k: int) -> list[int]:
    """K runs spread evenly over ``0 .. total - 1`` (first and last included)."""
    if not 0 < k <= total:
        raise FullStackRefused(f"--full-stack {k} is invalid; allowed: 1..{total}")
    if k == 1:
        return [0]
    return sorted({round(i * (total - 1) / (k - 1)) for i in range(k)})


def refusal(spec: CampaignSpec) -> str | None:
    """Why ``spec`` cannot be checked against the full stack, or None."""
    if not spec.wire_float32:
        return (
            "--full-stack needs wire_float32 = true in the spec: the full stack always crosses the "
            "MAVLink wire (float32 pose and controls), so a wire-off campaign differs from it by design"
        )
    return None


def fly_full_stack(spec: CampaignSpec, run: int, controller: str) -> dict[str, float | bool]:
    """Run ``run`` of ``spec`` with ``controller`` through the in-process flight stack: its indices."""
    from gcs_scripts.analysis.metrics import indices
    from sitl.inprocess import RunOptions, flight_record, paper_stack

    from .sampling import sample_run

    sample = sample_run(spec, run)
    law = next(c for c in spec.controllers if c.name == controller)
    est = spec.estimation
    options = RunOptions(
        duration_s=spec.duration_s, rates=spec.rates, gusts=sample.gusts, estimator=spec.estimator,
        sensors=est.sensors_name if est is not None else None, sensor_config=sample.sensors,
        true_plant=sample.plant_vehicle, initial_velocity_m_s=sample.initial_velocity_m_s,
    )  # fmt: skip
    stack = paper_stack(sample.scenario, law, options, sample.vehicle)
    steps = int(round(spec.duration_s / stack.sim.dt_control))
    diverged = False
    for _ in range(steps):
        try:
            stack.step()
        except Exception:  # noqa: BLE001 - PlantDiverged, a non-finite state, a law's failure: a failed run
            diverged = True
            break
    if not diverged:
        stack.final_frame()
    record = flight_record(stack, sample.scenario.name, controller)
    error = np.linalg.norm(record.position_error_m, axis=1)
    tilt = np.arccos(np.clip(np.cos(record.euler_rad[:, 0]) * np.cos(record.euler_rad[:, 1]), -1.0, 1.0))
    limits = spec.failure
    failed = bool(
        diverged
        or not np.all(np.isfinite(record.position_m))
        or error.max() > limits.max_position_error_m
        or tilt.max() > limits.max_tilt_rad
    )
    ref = indices(record)
    out: dict[str, float | bool] = {"failed": failed}
    for i, axis in enumerate("xyz"):
        out[f"final_error_{axis}_m"] = float(ref.final_error_m[i])
    out.update({f"ise_{name}": float(v) for name, v in ref.ise.items()})
    out.update({f"iadu_{name}": float(v) for name, v in ref.iadu.items()})
    out["max_position_error_m"] = float(error.max())
    out["max_tilt_rad"] = float(tilt.max())
    return out


def compare(batch_row: dict, stack: dict, rel_tol: float = 1e-6) -> Comparison:
    """One run x controller: the batch table's row against the full stack's indices."""
    batch_failed, stack_failed = bool(batch_row["failed"]), bool(stack["failed"])
    worst_name, worst = "", 0.0
    if not batch_failed and not stack_failed:
        for name in COMPARED:
            a, b = float(batch_row[name]), float(stack[name])
            scale = max(abs(a), abs(b), 1e-12)
            rel = abs(a - b) / scale if math.isfinite(a) and math.isfinite(b) else math.inf
            if rel > worst or not worst_name:
                worst_name, worst = name, rel
    return Comparison(int(batch_row["run"]), str(batch_row["controller"]), batch_failed, stack_failed,
                      worst_name, worst, rel_tol)  # fmt: skip


def check(
    spec: CampaignSpec,
    table: pa.Table,
    runs: Sequence[int],
    rel_tol: float = 1e-6,
    progress: Callable[[str], None] = lambda text: None,
) -> list[Comparison]:
    """Fly ``runs`` through the full stack and compare with the campaign's ``table``."""
    why = refusal(spec)
    if why:
        raise FullStackRefused(why)
    rows = {(r["run"], r["controller"]): r for r in table.to_pylist()}
    results = []
    for run in runs:
        for controller in spec.controller_names:
            row = rows.get((run, controller))
            if row is None:
                raise FullStackRefused(f"run {run} / {controller} is not in the results table")
            result = compare(row, fly_full_stack(spec, run, controller), rel_tol)
            if result.worst_index:
                detail = f"largest difference {result.worst_index} {result.worst_relative:.1e}"
            else:
                detail = f"failed: batch {result.batch_failed}, full stack {result.stack_failed}"
            verdict = "agrees" if result.agrees else "DIFFERS"
            progress(f"full stack: run {run} {controller}: {verdict} ({detail})")
            results.append(result)
    return results


def markdown(results: Sequence[Comparison], rel_tol: float) -> str:
    """The check as a Markdown section (appended to the campaign's summary)."""
    lines = [
        "## Full-stack check",
        "",
        f"{len({r.run for r in results})} run(s) flown again through the whole in-process flight stack "
        "(simulator core, MAVLink frames, autopilot core: commander, cascade) and compared index by "
        f"index with the batch engine (relative tolerance {rel_tol:g}).",
        "",
        "| run | controller | verdict | largest relative difference | failed (batch / stack) |",
        "|---:|---|---|---|---|",
    ]
    for r in results:
        worst = f"{r.worst_index} {r.worst_relative:.1e}" if r.worst_index else "-"
        lines.append(f"| {r.run} | {r.controller} | {'agrees' if r.agrees else '**differs**'} | {worst} "
                     f"| {r.batch_failed} / {r.stack_failed} |")  # fmt: skip
    return "\n".join(lines) + "\n"
