"""``quadsitl demo`` (``make demo``): the paper's experiment flown through the SITL.

First the paper's circle, with its disturbance schedule, streamed as OFFBOARD position + velocity +
acceleration setpoints by ``gcs_scripts/fly_trajectory.py`` while ``gcs_scripts/record.py``
records; its indices from the log beside the in-process run (``circle_offboard.md``,
``sitl_circle_*.png``).

Then, for each cascade (IntBS-NLH∞, IntBS, BS-NLH∞), it starts the SITL (simulator + autopilot,
two processes linked over MAVLink/UDP, ``--speed max``) with the helix scenario (plant mass and
inertia +30 %), runs ``gcs_scripts/fly_paper.py`` against it, which uploads the helix as a timed
mission and the paper's disturbance schedule as a gust profile, flies it and records the session,
and stops the SITL. From the recorded logs only, it computes the paper's indices over the 40 s of
the curve and writes:

* ``comparison.md``: one table, final errors / ISE / IADU, a column per cascade (SITL);
* ``sitl_vs_inprocess.md``: the same indices beside the in-process runs of the same scenario,
  over t in [4, 40] s (the SITL flies the curve from a hover at p_d(0), the in-process run from
  the paper's initial state: their first seconds differ by construction);
* ``sitl_helix_{path3d,position,position_error,orientation,controls}.png``;
* ``logs/``: the recorded sessions (``.parquet``, ``.tlog``; ``quadsitl analyze`` reads them).
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

from autopilot.control.config import CONTROLLER_NAMES, load_controller
from gcs_scripts.analysis.figures import paper_figures
from gcs_scripts.analysis.log_reader import read_session
from gcs_scripts.analysis.metrics import STATE_NAMES, indices
from gcs_scripts.analysis.tables import CONTROLLER_TITLES, comparison_markdown
from quadcommon.config import load_scenario

from .inprocess import run_scenario
from .launcher import Launcher, LaunchError, VehicleSpec, python_script

REPO = Path(__file__).resolve().parents[1]
T0 = re.compile(r"^t0=([0-9.]+)", re.MULTILINE)
TRANSIENT_S = 4.0


def fly_one(controller: str, scenario: str, instance: int, log_base: Path, speed: str) -> float:
    """One SITL run of ``scenario`` with ``controller``; returns the curve's start time t0."""
    spec = VehicleSpec(instance=instance, controller=controller, scenario=scenario, speed=speed)
    with Launcher() as launcher:
        launcher.start_vehicles([spec])
        args = ("--instance", str(instance), "--scenario", scenario, "--out", str(log_base))
        script = launcher.spawn("fly_paper.py", python_script("gcs_scripts/fly_paper.py", *args))
        return _t0_of(script, f"fly_paper.py ({controller})")


def _t0_of(script, what: str, timeout_s: float = 900.0) -> float:
    """The ``t0=`` a flying script prints, once it has finished successfully."""
    code = script.wait(timeout_s)
    if code != 0:
        raise RuntimeError(f"{what} failed (exit code {code}):\n{script.tail(60)}")
    match = T0.search(script.output)
    if match is None:
        raise RuntimeError(f"{what} did not report t0:\n{script.tail(40)}")
    return float(match.group(1))


def fly_offboard(scenario: str, instance: int, log_base: Path, speed: str) -> float:
    """The scenario streamed as OFFBOARD setpoints (p, v, a) by fly_trajectory.py, recorded by
    record.py, with the paper's gusts uploaded to start with the trajectory; returns t0."""
    spec = VehicleSpec(instance=instance, scenario=scenario, speed=speed)
    n = str(instance)
    with Launcher() as launcher:
        launcher.start_vehicles([spec])
        recorder = launcher.spawn("record.py", python_script(
            "gcs_scripts/record.py", "--instance", n, "--out", str(log_base), "--until-disarmed"
        ))  # fmt: skip
        script = launcher.spawn("fly_trajectory.py", python_script(
            "gcs_scripts/fly_trajectory.py", "--instance", n, "--scenario", scenario, "--gusts", "paper_steps"
        ))  # fmt: skip
        t0 = _t0_of(script, "fly_trajectory.py")
        recorder.wait(60.0)  # --until-disarmed: it ends (and merges its parts) by itself
        return t0


def run_demo(
    out_dir: Path,
    scenario: str = "helix",
    controllers: tuple[str, ...] = CONTROLLER_NAMES,
    instance: int = 0,
    speed: str = "max",
    log=print,
) -> Path:
    """The demo: fly the paper's circle as OFFBOARD setpoints and ``scenario`` with each of
    ``controllers`` through the SITL processes (vehicle ``instance``, at ``speed``), record them,
    compare with in-process runs; write tables and figures into ``out_dir`` and return the path of
    the comparison table."""
    out_dir = Path(out_dir)
    logs = out_dir / "logs"
    logs.mkdir(parents=True, exist_ok=True)

    # The paper's circle streamed in OFFBOARD by a ground-station script, recorded, analysed.
    started = time.perf_counter()
    log("[0] SITL: the paper's circle streamed as OFFBOARD setpoints (fly_trajectory.py), recorded ...")
    circle_log = logs / "circle_offboard"
    for stale in (circle_log.with_suffix(".parquet"), circle_log.with_suffix(".tlog")):
        stale.unlink(missing_ok=True)
    t0 = fly_offboard("circle", instance, circle_log, speed)
    circle_duration = load_scenario("circle").duration_s
    circle = read_session(
        circle_log.with_suffix(".parquet"), window=(t0, circle_duration), label="SITL, offboard"
    )
    circle_inproc = run_scenario(load_scenario("circle"), load_controller("intbs_nlhinf"))
    circle_inproc.label = "in-process"
    circle_md = out_dir / "circle_offboard.md"
    circle_md.write_text(
        "# The paper's circle, IntBS-NLH∞: streamed through the SITL vs in-process (t in [0, 40] s)\n\n"
        "The SITL run starts from a hover at p_d(0), the in-process run from the paper's initial state\n"
        "(on the ground, yaw 0.5 rad): their first seconds differ by construction.\n\n"
        + comparison_markdown({"SITL, offboard": indices(circle), "in-process": indices(circle_inproc)})
    )
    paper_figures([circle, circle_inproc], out_dir, "sitl_circle")
    log(f"    flown, recorded and analysed in {time.perf_counter() - started:.1f} s wall -> {circle_md}")

    duration = load_scenario(scenario).duration_s
    t0s: dict[str, float] = {}
    for k, controller in enumerate(controllers, 1):
        started = time.perf_counter()
        log(f"[{k}/{len(controllers)}] SITL: {scenario} with {controller} (speed {speed}) ...")
        base = logs / f"{scenario}_{controller}"
        for stale in (base.with_suffix(".parquet"), base.with_suffix(".tlog")):
            stale.unlink(missing_ok=True)
        t0s[controller] = fly_one(controller, scenario, instance, base, speed)
        log(f"      flown and recorded in {time.perf_counter() - started:.1f} s wall -> {base}.parquet")

    log("analysing the recorded logs ...")
    sitl = {
        c: read_session(logs / f"{scenario}_{c}.parquet", window=(t0s[c], duration), label=c)
        for c in controllers
    }
    table = {CONTROLLER_TITLES.get(c, c): indices(r) for c, r in sitl.items()}
    comparison = out_dir / "comparison.md"
    comparison.write_text(
        f"# Paper's {scenario} through the SITL (recorded logs, t in [0, {duration:g}] s of the curve)\n\n"
        + comparison_markdown(table)
    )
    paper_figures(list(sitl.values()), out_dir, f"sitl_{scenario}")

    log(f"in-process runs of the same scenario for comparison over [{TRANSIENT_S:g}, {duration:g}] s ...")
    lines = [
        f"# SITL vs in-process, {scenario}, ISE over t in [{TRANSIENT_S:g}, {duration:g}] s",
        "",
        "| cascade | run | " + " | ".join(f"ISE {n}" for n in STATE_NAMES) + " | final x (mm) | y | z |",
        "|---|---|" + "---:|" * (len(STATE_NAMES) + 3),
    ]
    for c in controllers:
        inproc = run_scenario(load_scenario(scenario), load_controller(c))
        for name, rec in (("SITL", sitl[c]), ("in-process", inproc)):
            ind = indices(rec.window(TRANSIENT_S, duration))
            final = [1000 * e for e in ind.final_error_m]
            lines.append(
                f"| {CONTROLLER_TITLES.get(c, c)} | {name} | "
                + " | ".join(f"{ind.ise[n]:.5f}" for n in STATE_NAMES)
                + " | "
                + " | ".join(f"{v:+.3f}" for v in final)
                + " |"
            )
    side = out_dir / "sitl_vs_inprocess.md"
    side.write_text("\n".join(lines) + "\n")

    log("")
    log(comparison.read_text())
    log(side.read_text())
    log(f"tables:  {comparison}, {side}, {circle_md}")
    log(
        f"figures: {out_dir}/sitl_{{{scenario},circle}}_"
        "{path3d,position,position_error,orientation,controls}.png"
    )
    log(f"logs:    {logs}/  (quadsitl analyze LOG --t0 T0 --duration {duration:g})")
    return comparison


def main_demo(out: str, instance: int, speed: str) -> int:
    """``quadsitl demo``: :func:`run_demo`; 2 when the processes cannot start, 1 when a flight fails."""
    try:
        run_demo(Path(out), instance=instance, speed=speed)
    except LaunchError as exc:
        print(f"quadsitl demo: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        print(f"quadsitl demo: {exc}", file=sys.stderr)
        return 1
    return 0
