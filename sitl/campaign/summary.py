"""The campaign's Markdown summary: distributions of the paper's indices per controller.

Per controller: runs, failures and their reasons; for each index its median, 95th percentile and
worst value over the runs that completed (a failed run stops early, so its indices are not
comparable; failures are counted separately); which sampled parameters drive the worst runs
(Spearman rank correlation of the position ISE with each parameter or with its distance from
its median, over completed runs) and the worst runs
themselves with their parameters.

A campaign that draws faults (:attr:`~.spec.CampaignSpec.draws_faults`) gets a section of its own
first: the controllers ranked by the share of runs they survived, then by the median of their
largest excursion after the fault's onset, with their time to recover, the reasons of the runs
lost and the fault parameters those runs have in common (:func:`fault_ranking`).

Indices (CONTROL.md, Tables I-III): final position error (norm, mm), ISE of position (x + y + z,
m^2 s) and attitude (phi + theta + psi, rad^2 s), IADU of U1 and of the torques, the largest
position error (mm) and tilt (deg) along the run, the time an actuator limit was active; on the
estimate also the filter's: the RMS error of its position, its worst innovation test ratio, the
time it was not converged and the samples it rejected.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pyarrow as pa

from .spec import CampaignSpec

TITLES = {
    "intbs_nlhinf": "IntBS-NLH∞",
    "intbs": "IntBS",
    "bs_nlhinf": "BS-NLH∞",
}

PARAMETER_COLUMNS_END = "final_error_x_m"  # the first metric column: parameters come before it


def title(controller: str) -> str:
    """The controller's display title (e.g. the paper's name for it), else its name."""
    return TITLES.get(controller, controller)


def derived_columns(table: pa.Table) -> dict[str, np.ndarray]:
    """The summary's indices as arrays (one value per row of ``table``)."""
    col = {name: np.array(table.column(name).to_pylist(), dtype=float) for name in table.column_names
           if table.schema.field(name).type == pa.float64()}  # fmt: skip
    return {
        "ise_position": col["ise_x"] + col["ise_y"] + col["ise_z"],
        "ise_attitude": col["ise_phi"] + col["ise_theta"] + col["ise_psi"],
        "final_error_mm": col["final_error_m"] * 1000.0,
        "max_position_error_mm": col["max_position_error_m"] * 1000.0,
        "max_tilt_deg": np.degrees(col["max_tilt_rad"]),
        "iadu_U1": col["iadu_U1"],
        "iadu_torque": col["iadu_tau_phi"] + col["iadu_tau_theta"] + col["iadu_tau_psi"],
        "time_saturated_s": col["time_saturated_s"],
        **(
            {
                "estimate_rms_error_mm": col["estimate_rms_error_m"] * 1000.0,
                "worst_test_ratio": col["worst_test_ratio"],
                "time_not_converged_s": col["time_not_converged_s"],
                "rejected_samples": col["rejected_samples"],
            }
            if "estimate_rms_error_m" in col
            else {}
        ),
    }


INDEX_LABELS = {
    "ise_position": "ISE position x+y+z (m² s)",
    "ise_attitude": "ISE attitude φ+θ+ψ (rad² s)",
    "final_error_mm": "final position error |e(T)| (mm)",
    "max_position_error_mm": "max position error (mm)",
    "max_tilt_deg": "max tilt (deg)",
    "iadu_U1": "IADU U1 (N)",
    "iadu_torque": "IADU τφ+τθ+τψ (N m)",
    "time_saturated_s": "time in saturation (s)",
}
# On the estimate (estimator = "ekf"): the filter's own figures per run.
ESTIMATION_LABELS = {
    "estimate_rms_error_mm": "estimate's RMS position error (mm)",
    "worst_test_ratio": "worst innovation test ratio (gate: 1)",
    "time_not_converged_s": "time not converged (s)",
    "rejected_samples": "samples rejected (gates, checks)",
}


def parameter_names(table: pa.Table) -> list[str]:
    """Sampled-parameter columns that actually vary in this table."""
    names = table.column_names
    params = names[names.index("controller") + 1 : names.index(PARAMETER_COLUMNS_END)]
    out = []
    for name in params:
        if name == "sensor_seed":  # a noise stream's seed: no quantity to correlate with
            continue
        values = np.array(table.column(name).to_pylist(), dtype=float)
        if np.nanmax(values) != np.nanmin(values):
            out.append(name)
    return out


def _fmt(value: float) -> str:
    if not math.isfinite(value):
        return "—"
    if value == 0.0:
        return "0"
    magnitude = abs(value)
    if magnitude >= 100:
        return f"{value:.1f}"
    if magnitude >= 1:
        return f"{value:.3g}"
    return f"{value:.3g}" if magnitude >= 1e-3 else f"{value:.2e}"


def _stats(values: np.ndarray) -> tuple[float, float, float]:
    if values.size == 0:
        return math.nan, math.nan, math.nan
    return float(np.median(values)), float(np.percentile(values, 95)), float(np.max(values))


def _driver(name: str, x: np.ndarray, y: np.ndarray) -> tuple[float, str, str] | None:
    """How strongly parameter ``x`` drives index ``y``: Spearman's rho with x itself, or with its
    distance from its median (an index that grows with |mass error| either way is U-shaped in x,
    which a plain rank correlation misses). ``(|rho|, description, name)``."""
    direct = _spearman(x, y)
    spread = _spearman(np.abs(x - np.median(x)), y)
    if not (math.isfinite(direct) or math.isfinite(spread)):
        return None
    if math.isfinite(spread) and (not math.isfinite(direct) or abs(spread) > abs(direct)):
        return abs(spread), f"|{name} - {np.median(x):.3g}| (ρ = {spread:+.2f})", name
    return abs(direct), f"{name} (ρ = {direct:+.2f})", name


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    if x.size < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan
    from scipy.stats import spearmanr

    return float(spearmanr(x, y).statistic)


def summary_markdown(
    table: pa.Table, spec: CampaignSpec, controllers: Sequence[str] | None = None, extra: str = ""
) -> str:
    """The whole summary as Markdown."""
    controllers = list(controllers or spec.controller_names)
    names = np.array(table.column("controller").to_pylist())
    failed = np.array(table.column("failed").to_pylist(), dtype=bool)
    reasons = np.array(table.column("failure").to_pylist(), dtype=object)
    runs_col = np.array(table.column("run").to_pylist())
    derived = derived_columns(table)
    params = parameter_names(table)
    pvals = {p: np.array(table.column(p).to_pylist(), dtype=float) for p in params}
    n_runs = len(set(runs_col.tolist()))

    lines = [f"# Campaign `{spec.name}`", ""]
    if spec.description:
        lines += [spec.description, ""]
    lines += [
        f"- scenario `{spec.scenario.name}` ({spec.duration_s:g} s), vehicle `{spec.vehicle.name}` "
        f"(actuation {spec.vehicle.actuation.mode}), {n_runs} runs per controller, seed {spec.seed}",
        f"- physics {spec.rates.physics_hz:g} Hz (RK4, float64), control {spec.rates.control_hz:g} Hz, "
        f"MAVLink wire float32 emulation {'on' if spec.wire_float32 else 'off'}",
        f"- randomised: {', '.join(params) if params else 'nothing'}",
        *(
            [
                f"- flown on the estimate: sensors `{spec.estimation.sensors_name}` (each run its own noise "
                "stream), the autopilot's EKF"
            ]
            if spec.estimation is not None
            else []
        ),  # fmt: skip
        *(["- faults drawn per run: see the next section"] if "survived" in table.column_names else []),
        f"- failure: position error > {spec.failure.max_position_error_m:g} m, tilt > "
        f"{spec.failure.max_tilt_rad:g} rad, non-finite state, a controller's non-finite output, or ground "
        "contact after take-off; a failed run stops there and is left out of the statistics below (counted "
        "in the failure rate)",
        "",
        *([*fault_section(table, spec, controllers), ""] if "survived" in table.column_names else []),
        "## Headline",
        "",
        "| controller | median ISE pos | p95 ISE pos | median ISE att | p95 ISE att | median "
        "final err (mm) | worst final err (mm) | p95 max err (mm) | failure rate |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for c in controllers:
        sel = (names == c) & ~failed
        n = int((names == c).sum())
        nf = int(((names == c) & failed).sum())
        ip = _stats(derived["ise_position"][sel])
        ia = _stats(derived["ise_attitude"][sel])
        fe = _stats(derived["final_error_mm"][sel])
        me = _stats(derived["max_position_error_mm"][sel])
        rate = f"{nf}/{n} ({100.0 * nf / n:.1f} %)" if n else "—"
        lines.append(
            f"| {title(c)} | {_fmt(ip[0])} | {_fmt(ip[1])} | {_fmt(ia[0])} | {_fmt(ia[1])} | {_fmt(fe[0])} | "
            f"{_fmt(fe[2])} | {_fmt(me[1])} | {rate} |"
        )
    lines += ["", "## Every index (completed runs: median / p95 / worst)", ""]
    lines.append("| index | " + " | ".join(title(c) for c in controllers) + " |")
    lines.append("|---|" + "---:|" * len(controllers))
    for key, label in {
        **INDEX_LABELS,
        **{k: v for k, v in ESTIMATION_LABELS.items() if k in derived},
    }.items():
        cells = []
        for c in controllers:
            med, p95, worst = _stats(derived[key][(names == c) & ~failed])
            cells.append(f"{_fmt(med)} / {_fmt(p95)} / {_fmt(worst)}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")

    lines += ["", "## Failures", ""]
    any_failure = False
    for c in controllers:
        sel = (names == c) & failed
        if not sel.any():
            continue
        any_failure = True
        counts: dict[str, int] = {}
        for r in reasons[sel]:
            counts[r] = counts.get(r, 0) + 1
        detail = ", ".join(f"{k}: {v}" for k, v in sorted(counts.items()))
        lines.append(f"- {title(c)}: {int(sel.sum())} failed ({detail}); runs {_run_list(runs_col[sel])}")
        if params:
            drivers = []
            for p in params:
                allv = pvals[p][names == c]
                fv = pvals[p][sel]
                lo, hi = float(np.min(allv)), float(np.max(allv))
                if hi > lo:
                    drivers.append(
                        (abs(np.median(fv) - np.median(allv)) / (hi - lo), p, np.median(fv), np.median(allv))
                    )
            drivers.sort(reverse=True)
            text = "; ".join(f"{p} median {fm:.4g} (all runs {am:.4g})" for _, p, fm, am in drivers[:3])
            lines.append(f"  - parameters most shifted in the failed runs: {text}")
    if not any_failure:
        lines.append("No run failed.")

    lines += ["", "## What drives the worst runs", ""]
    if not params:
        lines.append("Nothing is randomised.")
    for c in controllers:
        sel = (names == c) & ~failed
        if not sel.any() or not params:
            continue
        y = derived["ise_position"][sel]
        ranked = sorted((d for p in params if (d := _driver(p, pvals[p][sel], y)) is not None), reverse=True)
        top = ", ".join(text for _, text, _ in ranked[:3]) or "—"
        lines.append(f"- **{title(c)}**: Spearman correlation with the position ISE: {top}")
        order = np.argsort(-y)[:5]
        shown = [p for _, _, p in ranked[:4]]
        cells = [
            f"run {int(runs_col[sel][i])}: ISE {_fmt(float(y[i]))}"
            + ("" if not shown else " (" + ", ".join(f"{p} {pvals[p][sel][i]:.4g}" for p in shown) + ")")
            for i in order
        ]
        lines.append("  - worst: " + "; ".join(cells))
    if extra:
        lines += ["", extra]
    return "\n".join(lines) + "\n"


def fault_ranking(table: pa.Table, controllers: Sequence[str]) -> list[tuple[str, float, float]]:
    """The controllers ranked by what they survive: ``(controller, survival share, median
    excursion)``, the highest share first, ties by the smaller median largest excursion after the
    fault's onset (over every run, the lost ones with the excursion they reached before they ended;
    runs that ended before the onset are left out of the median)."""
    names = np.array(table.column("controller").to_pylist())
    survived = np.array(table.column("survived").to_pylist(), dtype=bool)
    excursion = np.array(table.column("max_excursion_m").to_pylist(), dtype=float)
    out = []
    for c in controllers:
        sel = names == c
        if not sel.any():
            continue
        reached = excursion[sel][np.isfinite(excursion[sel])]
        median = float(np.median(reached)) if reached.size else math.inf
        out.append((c, float(survived[sel].mean()), median))
    return sorted(out, key=lambda item: (-item[1], item[2]))


def fault_section(table: pa.Table, spec: CampaignSpec, controllers: Sequence[str]) -> list[str]:
    """The summary's section on the faults drawn: the ranking and what the lost runs share."""
    names = np.array(table.column("controller").to_pylist())
    survived = np.array(table.column("survived").to_pylist(), dtype=bool)
    failed = np.array(table.column("failed").to_pylist(), dtype=bool)
    reasons = np.array(table.column("failure").to_pylist(), dtype=object)
    excursion = np.array(table.column("max_excursion_m").to_pylist(), dtype=float)
    recover = np.array(table.column("time_to_recover_s").to_pylist(), dtype=float)
    failed_at = np.array(table.column("failure_time_s").to_pylist(), dtype=float)
    early = failed & (failed_at < np.array(table.column("fault_onset_s").to_pylist(), dtype=float))
    limits = spec.survival
    drawn = [
        f"{', '.join(f.types)} of motor {f.motor.describe()} (effectiveness {f.effectiveness.describe()}) "
        f"from {f.start_s.describe()} s"
        for f in spec.actuator_faults
    ]
    if spec.estimation is not None:
        drawn += [f"{' or '.join(f.kinds)} from {f.start_s.describe()} s" for f in spec.estimation.faults]
    lines = [
        "## Faults: what each controller survives",
        "",
        f"Drawn per run: {'; '.join(drawn)}. Survived: the run flew to its end (no failure) and its "
        f"position error stayed within {limits.envelope_m:g} m of the reference; excursion: the largest "
        f"position error from the fault's onset on; recovered: back within {limits.recovery_bound_m:g} m "
        "for the rest of the run (the time from the onset). Ranked by survival over every run (a run lost "
        "before its fault's onset counts too: the column of the runs lost says how many), then by the "
        "median excursion.",
        "",
        "| rank | controller | survived | excursion, median / p95 / worst (m) | recovered | time to recover, "
        "median / p95 (s) | lost: failed (reasons; before the onset) / outside the envelope |",
        "|---:|---|---:|---:|---:|---:|---|",
    ]
    for rank, (c, share, _) in enumerate(fault_ranking(table, controllers), 1):
        sel = names == c
        n = int(sel.sum())
        ex = excursion[sel][np.isfinite(excursion[sel])]
        med, p95, worst = _stats(ex)
        rec = recover[sel][np.isfinite(recover[sel])]
        rmed, rp95, _ = _stats(rec)
        counts: dict[str, int] = {}
        for r in reasons[sel & failed]:
            counts[r] = counts.get(r, 0) + 1
        detail = ", ".join(f"{k}: {v}" for k, v in sorted(counts.items()))
        if detail:
            detail += f"; {int((sel & early).sum())} before the onset"
        outside = int((sel & ~failed & ~survived).sum())
        lost = f"{int((sel & failed).sum())}" + (f" ({detail})" if detail else "") + f" / {outside}"
        lines.append(
            f"| {rank} | {title(c)} | {int(survived[sel].sum())}/{n} ({100.0 * share:.1f} %) | {_fmt(med)} / "
            f"{_fmt(p95)} / {_fmt(worst)} | {rec.size}/{n} | {_fmt(rmed)} / {_fmt(rp95)} | {lost} |"
        )
    groups = _drawn_groups(table, spec)
    if groups:
        lines += ["", "Survived, by the fault drawn:", "",
                  "| fault drawn | runs | " + " | ".join(title(c) for c in controllers) + " |",
                  "|---|---:|" + "---:|" * len(controllers)]  # fmt: skip
        for label, which in groups:
            cells = []
            for c in controllers:
                sel = (names == c) & which
                cells.append(f"{int(survived[sel].sum())}/{int(sel.sum())}")
            runs = int(((names == controllers[0]) & which).sum())
            lines.append(f"| {label} | {runs} | " + " | ".join(cells) + " |")
    params = [p for p in parameter_names(table) if p.startswith(("actuator_fault", "fault"))
              and not p.endswith(("_kind_index", "_type_index")) and "_value_" not in p]  # fmt: skip
    if params:
        lines += ["", "Fault parameters in the runs lost (median, against all runs):", ""]
        for c in controllers:
            sel = names == c
            lost = sel & ~survived
            if not lost.any() or lost.sum() == sel.sum():
                continue
            cells = []
            for p in params:
                values = np.array(table.column(p).to_pylist(), dtype=float)
                cells.append(f"{p} {np.median(values[lost]):.4g} ({np.median(values[sel]):.4g})")
            lines.append(f"- {title(c)}: " + "; ".join(cells))
    return lines


def _drawn_groups(table: pa.Table, spec: CampaignSpec) -> list[tuple[str, np.ndarray]]:
    """The rows by what was drawn among several: each sensor fault's kind, each actuator fault's
    type and motor (``(label, rows)``)."""
    out = []

    def column(name: str) -> np.ndarray | None:
        return np.array(table.column(name).to_pylist(), dtype=float) if name in table.column_names else None

    for i, f in enumerate(spec.actuator_faults):
        for key, labels in ((f"actuator_fault{i}_type_index", f.types),
                            (f"actuator_fault{i}_motor", None)):  # fmt: skip
            values = column(key)
            if values is None or np.all(values == values[0]):
                continue
            for v in sorted(set(values.tolist())):
                label = labels[int(v)] if labels is not None else ("all motors" if v == 0 else f"motor {v:g}")
                out.append((label, values == v))
    if spec.estimation is not None:
        for i, f in enumerate(spec.estimation.faults):
            values = column(f"fault{i}_kind_index")
            if values is not None:
                out += [(kind, values == k) for k, kind in enumerate(f.kinds) if (values == k).any()]
    return out


def _run_list(runs: np.ndarray, limit: int = 12) -> str:
    values = sorted(int(r) for r in runs)
    text = ", ".join(str(r) for r in values[:limit])
    return text + (f", ... ({len(values)} in all)" if len(values) > limit else "")


def worst_runs(table: pa.Table, controllers: Sequence[str]) -> dict[str, int]:
    """Per controller, its worst run: the first failure if any, else the largest position ISE."""
    names = np.array(table.column("controller").to_pylist())
    failed = np.array(table.column("failed").to_pylist(), dtype=bool)
    runs = np.array(table.column("run").to_pylist())
    ise = derived_columns(table)["ise_position"]
    out = {}
    for c in controllers:
        sel = names == c
        if not sel.any():
            continue
        if (sel & failed).any():
            out[c] = int(runs[sel & failed].min())
        else:
            idx = np.flatnonzero(sel)
            out[c] = int(runs[idx[np.argmax(ise[idx])]])
    return out
