"""Campaign speed: 1,000 runs of the coupled plant, wall time on this machine.

Run: ``.venv/bin/python benchmarks/campaign.py [--runs 1000] [--workers 2] [--controller NAME]``.

What is flown: ``config/campaigns/paper_box.toml`` restricted to one controller (IntBS-NLHinf by
default; any controller, a researcher's own included, with ``--controller``): the helix of
Section IV, 40 s, the paper's disturbances on six axes, the true plant's mass and each inertia
uniform within +-30 %, RK4 in float64 at 1 kHz physics, 500 Hz control, the MAVLink wire's float32
quantisation on. Everything a user's ``quadsitl campaign`` does is counted: spec loading, sampling,
the process pool, numba compilation, the flights, the Parquet parts and the final table.

Measured twice, each in a fresh process: with an empty cache (the controller's law pair compiled
from scratch: ``numba_compile_time`` is what a new law costs once), then with the cache the first
measurement left (what every later campaign pays). With ``--estimator ekf --sensors NAME`` two
more fresh processes fly the same campaign on the estimate (the sensor profile NAME and the
autopilot's EKF, each run with its own noise): the first compiles the flight on the estimate (an
entry of its own), the second's wall time is printed beside the truth campaign's warm one with
their ratio, measured in the same run. The machine is
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
         "ekf": "on the EKF, warm numba cache"}


def _cpu_s() -> float:
    """CPU seconds of this process and of its waited-for children (the pool's workers)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def child(args: argparse.Namespace) -> None:
    sys.path.insert(0, str(ROOT))
    start = time.perf_counter()
    load_before = os.getloadavg()[0]
    from sitl.campaign.runner import run_campaign
    from sitl.campaign.spec import estimation_spec, load_campaign

    spec = load_campaign(args.spec, runs=args.runs)
    spec = replace(
        spec,
        controllers=tuple(c for c in spec.controllers if c.name == args.controller),
        wire_float32=args.wire == "on",
        estimation=estimation_spec(args.sensors) if args.estimator == "ekf" else None,
    )
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


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--spec", default="paper_box")
    parser.add_argument("--controller", default="intbs_nlhinf")
    parser.add_argument("--wire", choices=("on", "off"), default="on", help="float32 wire emulation")
    parser.add_argument(
        "--estimator",
        choices=("truth", "ekf"),
        default="truth",
        help="ekf: also fly the campaign on the EKF and print it beside the truth's",
    )
    parser.add_argument("--sensors", default="gps", help="the EKF campaign's sensor profile (default gps)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return

    cmd = [
        sys.executable, __file__, "--child", "--runs", str(args.runs), "--workers", str(args.workers),
        "--spec", args.spec, "--controller", args.controller, "--wire", args.wire, "--sensors", args.sensors,
    ]  # fmt: skip
    results = {}
    # A flight on the estimate is a compiled entry of its own (the truth's holds no filter): its
    # first run compiles it, the second is the figure.
    labels = ("cold", "warm", "ekf_cold", "ekf") if args.estimator == "ekf" else ("cold", "warm")
    with tempfile.TemporaryDirectory() as cache:
        # An empty cache for both the generated entry modules and numba's compiled code: the first
        # child compiles the law pair's flight from scratch (what a new law costs once).
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, QUADSITL_KERNEL_CACHE=cache)
        for label in labels:
            estimator = ["--estimator", "ekf" if label.startswith("ekf") else "truth"]
            out = subprocess.run(cmd + estimator, env=env, capture_output=True, text=True, check=True,
                                 timeout=3600)  # fmt: skip
            results[label] = json.loads(out.stdout.strip().splitlines()[-1])
            r = results[label]
            print(
                f"{NAMES[label]}: {r['wall_s']:.1f} s wall for {r['rows']} runs "
                f"({r['warm_up_s']:.1f} s of it compiling or loading the kernels; {r['failed']} failed); "
                f"{r['cpu_s']:.1f} CPU s in all; load average before {r['load_before']:.2f}",
                flush=True,
            )
    physics_steps = args.runs * 40_000
    cold, warm = results["cold"], results["warm"]
    print(
        f"runs: {args.runs} x {args.controller}, {args.workers} workers, "
        f"wire float32 {args.wire}, RK4 float64"
    )
    print(f"campaign_wall_time_cold_cache: {cold['wall_s']:.1f} s")
    print(f"campaign_wall_time_warm_cache: {warm['wall_s']:.1f} s")
    print(f"numba_compile_time: {cold['warm_up_s']:.1f} s")  # the law pair's batch kernel, cold
    print(f"numba_cache_load_time: {warm['warm_up_s']:.2f} s")
    print(f"campaign_cpu_time_warm_cache: {warm['cpu_s']:.1f} s")
    print(f"campaign_vehicle_steps_per_s_warm: {physics_steps / warm['wall_s']:.3g} steps/s")
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
