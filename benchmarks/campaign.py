"""Campaign speed: 1,000 runs of the coupled plant, wall time on this machine.

Run: ``.venv/bin/python benchmarks/campaign.py [--runs 1000] [--workers 2] [--controller NAME]
[--spec NAME] [--config-dir DIR]``.

What is flown: the runs of a campaign spec (``config/campaigns/paper_box.toml`` by default) with
one controller (IntBS-NLHinf by default). ``--controller NAME`` takes any controller found by
name, a researcher's own included (``controllers/NAME.toml`` and its laws in ``--config-dir DIR``
or ``QUADSITL_CONFIG_DIR``): one in the spec's list flies as the spec gives it, one not in the
spec's list flies the spec's runs alone (the runs' plants and disturbances do not depend on the
controllers); a name found nowhere is refused before anything is flown. paper_box is the helix
of Section IV, 40 s, the paper's disturbances on six axes, the true plant's mass and each inertia
uniform within +-30 %, RK4 in float64 at 1 kHz physics, 500 Hz control, the MAVLink wire's float32
quantisation on. Everything a user's ``quadsitl campaign`` does is counted: spec loading, sampling,
the process pool, numba compilation, the flights, the Parquet parts and the final table.

Measured twice, each in a fresh process: with an empty cache (the controller's law pair compiled
from scratch: ``numba_compile_time`` is what a new law costs once), then with the cache the first
measurement left (what every later campaign pays). A measurement that fails stops the benchmark
with that process's error. With ``--estimator ekf --sensors NAME`` two
more fresh processes fly the same campaign on the estimate (the sensor profile NAME and the
autopilot's EKF, each run with its own noise): the first compiles the flight on the estimate (an
entry of its own), the second's wall time is printed beside the truth campaign's warm one with
their ratio, measured in the same run. A spec that draws faults (``--spec paper_box_faults``) is
flown a third time, in a fresh process with the cache warm, without its faults (no
``[[actuator_faults]]``: the same runs, healthy), and the two wall
times are printed with their ratio: what the faults cost. The machine is
shared: the CPU seconds (this process and its workers) and the load average before each
measurement are printed too, so a wall time taken under someone else's load can be read. Last
lines ``name: value unit``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NAMES = {"cold": "cold numba cache", "warm": "warm numba cache", "ekf_cold": "on the EKF, cold numba cache",
         "ekf": "on the EKF, warm numba cache", "healthy": "without its faults, warm numba cache"}


def _cpu_s() -> float:
    """CPU seconds of this process and of its waited-for children (the pool's workers)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _project_on_path() -> None:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))


def flown_spec(args: argparse.Namespace):
    """The campaign the benchmark flies: the spec's runs with ``--controller`` alone
    (:func:`sitl.campaign.spec.flown_by`), the wire and the estimator as asked."""
    from sitl.campaign.spec import estimation_spec, flown_by, load_campaign

    spec = flown_by(load_campaign(args.spec, runs=args.runs), args.controller)
    spec = replace(
        spec,
        wire_float32=args.wire == "on",
        estimation=estimation_spec(args.sensors) if args.estimator == "ekf" else None,
    )
    return replace(spec, actuator_faults=()) if args.healthy else spec  # the same runs without their faults


def child(args: argparse.Namespace) -> None:
    start = time.perf_counter()
    load_before = os.getloadavg()[0]
    from sitl.campaign.runner import run_campaign

    spec = flown_spec(args)
    with tempfile.TemporaryDirectory() as out:
        result = run_campaign(spec, out, workers=args.workers, progress=False)
    wall = time.perf_counter() - start
    failed = sum(result.table.column("failed").to_pylist())
    report = {
        "wall_s": wall,
        "cpu_s": _cpu_s(),
        "warm_up_s": result.warm_up_s,
        "rows": result.table.num_rows,
        "failed": failed,
        "load_before": load_before,
    }
    print(json.dumps(report))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="benchmarks/campaign.py", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--runs", type=int, default=1000, help="runs of the spec flown (default 1000)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--spec", default="paper_box", metavar="NAME",
                        help="the campaign spec whose runs are flown (config/campaigns; default paper_box)")
    parser.add_argument("--controller", default="intbs_nlhinf", metavar="NAME",
                        help="the controller flown (default intbs_nlhinf): any found by name, yours "
                        "included; one not in the spec's list flies the spec's runs alone")  # fmt: skip
    parser.add_argument("--config-dir", metavar="DIR", default=None,
                        help="a configuration directory looked in first, as quadsitl --config-dir "
                        "(your controllers/ and laws/; default: QUADSITL_CONFIG_DIR, then the shipped)")
    parser.add_argument("--wire", choices=("on", "off"), default="on", help="float32 wire emulation")
    parser.add_argument(
        "--estimator",
        choices=("truth", "ekf"),
        default="truth",
        help="ekf: also fly the campaign on the EKF and print it beside the truth's",
    )
    parser.add_argument("--sensors", default="gps", help="the EKF campaign's sensor profile (default gps)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--healthy", action="store_true", help=argparse.SUPPRESS)
    return parser


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    _project_on_path()
    from quadcommon.config import with_config_dir
    from quadcommon.schema import ConfigError

    try:
        if args.config_dir is not None:  # in the environment: the measurements' processes look there too
            os.environ.update(with_config_dir(args.config_dir, os.environ))
        if args.child:
            child(args)
            return
        spec = flown_spec(args)  # refused here, before any measurement, when it names what does not exist
    except ConfigError as exc:
        print(f"benchmarks/campaign.py: configuration error: {exc}", file=sys.stderr)
        sys.exit(2)

    cmd = [
        sys.executable, __file__, "--child", "--runs", str(args.runs), "--workers", str(args.workers),
        "--spec", args.spec, "--controller", args.controller, "--wire", args.wire, "--sensors", args.sensors,
    ]  # fmt: skip
    results = {}
    # A flight on the estimate is a compiled entry of its own (the truth's holds no filter): its
    # first run compiles it, the second is the figure.
    labels = ("cold", "warm", "ekf_cold", "ekf") if args.estimator == "ekf" else ("cold", "warm")
    if spec.draws_faults:  # the same runs without their faults, for what the faults cost
        labels = (*labels[:1], "healthy", *labels[1:])
    with tempfile.TemporaryDirectory() as cache:
        # An empty cache for both the generated entry modules and numba's compiled code: the first
        # child compiles the law pair's flight from scratch (what a new law costs once).
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, QUADSITL_KERNEL_CACHE=cache)
        for label in labels:
            estimator = ["--estimator", "ekf" if label.startswith("ekf") else "truth"]
            healthy = ["--healthy"] if label == "healthy" else []
            out = subprocess.run(cmd + estimator + healthy, env=env, capture_output=True, text=True,
                                 timeout=3600)  # fmt: skip
            if out.returncode != 0:
                sys.stderr.write(out.stderr)
                print(f"benchmarks/campaign.py: the {NAMES[label]} measurement failed "
                      f"(exit {out.returncode})", file=sys.stderr)  # fmt: skip
                sys.exit(1)
            results[label] = json.loads(out.stdout.strip().splitlines()[-1])
            r = results[label]
            print(
                f"{NAMES[label]}: {r['wall_s']:.1f} s wall for {r['rows']} runs "
                f"({r['warm_up_s']:.1f} s of it compiling or loading the kernels; {r['failed']} failed); "
                f"{r['cpu_s']:.1f} CPU s in all; load average before {r['load_before']:.2f}",
                flush=True,
            )
    rates = spec.rates
    physics_steps = spec.runs * round(spec.duration_s * rates.control_hz * rates.physics_steps_per_control)
    cold, warm = results["cold"], results["warm"]
    print(
        f"runs: {spec.runs} of {spec.name} x {args.controller}, {args.workers} workers, "
        f"wire float32 {args.wire}, RK4 float64"
    )
    print(f"campaign_wall_time_cold_cache: {cold['wall_s']:.1f} s")
    print(f"campaign_wall_time_warm_cache: {warm['wall_s']:.1f} s")
    print(f"numba_compile_time: {cold['warm_up_s']:.1f} s")  # the law pair's batch kernel, cold
    print(f"numba_cache_load_time: {warm['warm_up_s']:.2f} s")
    print(f"campaign_cpu_time_warm_cache: {warm['cpu_s']:.1f} s")
    print(f"campaign_vehicle_steps_per_s_warm: {physics_steps / warm['wall_s']:.3g} steps/s")
    if "healthy" in results:
        healthy = results["healthy"]
        print(f"with its faults: {warm['failed']} failed; without: {healthy['failed']} failed")
        print(f"campaign_wall_time_faults: {warm['wall_s']:.1f} s")
        print(f"campaign_wall_time_without_faults: {healthy['wall_s']:.1f} s")
        print(f"campaign_cpu_time_without_faults: {healthy['cpu_s']:.1f} s")
        print(f"campaign_faults_to_healthy_ratio: {warm['wall_s'] / healthy['wall_s']:.2f} x")
    if "ekf" in results:
        ekf = results["ekf"]
        print(f"on the estimate: sensors {args.sensors}, the autopilot's EKF; {ekf['failed']} failed")
        print(f"campaign_wall_time_truth: {warm['wall_s']:.1f} s")
        print(f"numba_compile_time_ekf: {results['ekf_cold']['warm_up_s']:.1f} s")
        print(f"campaign_wall_time_ekf: {ekf['wall_s']:.1f} s")
        print(f"campaign_cpu_time_ekf: {ekf['cpu_s']:.1f} s")
        print(f"campaign_ekf_to_truth_ratio: {ekf['wall_s'] / warm['wall_s']:.2f} x")


if __name__ == "__main__":
    main()
