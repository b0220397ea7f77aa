"""``quadsitl paper``: the paper's experiment, both scenarios x three cascades, in-process.

Writes to the output directory:

* ``tables.md``: Tables I-III per scenario, our numbers beside the paper's (helix);
* ``table1_final_errors.csv``, ``table2_ise.csv``, ``table3_iadu.csv``;
* ``<scenario>_{path3d,position,position_error,orientation,controls}.png`` (Figs 3-10 in spirit,
  the three cascades overlaid, disturbance instants dotted);
* ``runs/<scenario>_<controller>.parquet``: the time series of every run (readable by
  ``quadsitl analyze``).

A run whose law fails in flight (the autopilot terminates the flight: a non-finite output) ends the
experiment with :class:`~autopilot.control.registry.ControllerFailure` naming the scenario and the
controller (``quadsitl paper`` exits 1); no table is written.
"""

from __future__ import annotations

import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from autopilot.control.config import CONTROLLER_NAMES, load_controller
from autopilot.control.registry import ControllerFailure
from gcs_scripts.analysis.figures import paper_figures
from gcs_scripts.analysis.metrics import Indices, indices
from gcs_scripts.analysis.record import FlightRecord
from gcs_scripts.analysis.tables import paper_tables_markdown, write_paper_csvs
from quadcommon.config import load_scenario

from .inprocess import RunOptions, run_scenario

PAPER_SCENARIOS = ("circle", "helix")


@dataclass(frozen=True)
class PaperResults:
    records: dict[tuple[str, str], FlightRecord]
    indices: dict[tuple[str, str], Indices]
    outputs: list[Path]


def run_job(args: tuple) -> tuple[str, str, FlightRecord, float]:
    """One run: (scenario, controller, nominal, duration[, estimator, sensors])."""
    scenario, controller, nominal, duration, *estimation = args
    estimator, sensors = (estimation + [None, None])[:2]
    start = time.perf_counter()
    options = RunOptions(nominal_plant=nominal, duration_s=duration, estimator=estimator, sensors=sensors)
    record = run_scenario(load_scenario(scenario), load_controller(controller), options)
    return scenario, controller, record, time.perf_counter() - start


def run_paper(
    out_dir: Path,
    scenarios: tuple[str, ...] = PAPER_SCENARIOS,
    controllers: tuple[str, ...] = CONTROLLER_NAMES,
    nominal_plant: bool = False,
    workers: int = 2,
    log=print,
    duration_s: float | None = None,
    estimator: str | None = None,
    sensors: str | None = None,
) -> PaperResults:
    """``estimator`` / ``sensors``: "ekf" flies every run on the autopilot's EKF over the
    ``sensors`` profile (None: each scenario's own, the paper's truth and ideal sensors)."""
    out_dir = Path(out_dir)
    (out_dir / "runs").mkdir(parents=True, exist_ok=True)
    jobs = [(s, c, nominal_plant, duration_s, estimator, sensors) for s in scenarios for c in controllers]
    plant = "nominal Section II model" if nominal_plant else "coupled plant"
    if estimator == "ekf":
        plant += f", on the EKF over {sensors or 'the scenario'}'s sensors"
    log(f"flying {len(jobs)} runs in-process ({plant}, {workers} worker(s)) ...")
    records: dict[tuple[str, str], FlightRecord] = {}
    started = time.perf_counter()
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            results = pool.map(run_job, jobs)
            try:
                for done, (scenario, controller, record, seconds) in enumerate(results, 1):
                    records[(scenario, controller)] = record
                    _report(log, done, len(jobs), scenario, controller, record, seconds)
            except ControllerFailure:  # the runs not started yet are not flown
                pool.shutdown(wait=False, cancel_futures=True)
                raise
    else:
        for done, job in enumerate(jobs, 1):
            scenario, controller, record, seconds = run_job(job)
            records[(scenario, controller)] = record
            _report(log, done, len(jobs), scenario, controller, record, seconds)
    log(f"all runs done in {time.perf_counter() - started:.1f} s; writing tables and figures ...")

    table = {key: indices(rec) for key, rec in records.items()}
    outputs: list[Path] = []
    md = out_dir / "tables.md"
    md.write_text(paper_tables_markdown(table, scenarios, controllers))
    outputs.append(md)
    outputs += write_paper_csvs(table, out_dir)
    for scenario in scenarios:
        recs = [records[(scenario, c)] for c in controllers]
        outputs += paper_figures(recs, out_dir, scenario)
    for (scenario, controller), rec in records.items():
        outputs.append(rec.write_parquet(out_dir / "runs" / f"{scenario}_{controller}.parquet"))
    return PaperResults(records, table, outputs)


def _report(log, done, total, scenario, controller, record, seconds) -> None:
    err = record.position_error_m[-1] * 1000.0
    rtf = record.time_s[-1] / seconds if seconds > 0 else float("inf")
    log(
        f"  [{done}/{total}] {scenario:<6} {controller:<13} {seconds:5.1f} s "
        f"({rtf:4.1f}x real time)"
        f"  final error x={err[0]:+8.3f} y={err[1]:+8.3f} z={err[2]:+8.3f} mm"
    )
    sys.stdout.flush()
