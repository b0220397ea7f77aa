"""SITL speed: lockstep real-time factor with both processes and MAVLink on the wire.

For each control rate (250, 500, 1000 Hz; physics 1 kHz) it starts the simulator
(``--speed max --duration 40``, the paper's circle with its disturbances) and the autopilot
(``--autostart circle``: armed at t = 0, flying the paper's trajectory), and measures the wall
time from "linked" to the simulator's exit; the simulator reports the HIL round trip (frame
sent -> matching HIL_ACTUATOR_CONTROLS received) per frame: median and p99.

Run: ``.venv/bin/python benchmarks/sitl_rtf.py [--duration 40] [--rates 250 500 1000] [--profile]``.
``--profile`` also runs both processes under cProfile at 500 Hz and prints where the time goes.
The machine is shared and noisy: compare the rates with each other, measured in one run.
Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import pstats
import re
import tempfile
import time
from pathlib import Path

from sitl.launcher import LINKED, Launcher, VehicleSpec

REPO = Path(__file__).resolve().parents[1]
INSTANCE = 30
RTT = re.compile(r"HIL round trip median (\d+) us, p99 (\d+) us")


def sitl_toml(directory: Path, control_hz: int) -> Path:
    text = (REPO / "config" / "sitl.toml").read_text()
    text = re.sub(r"control_hz = [0-9.]+", f"control_hz = {control_hz}.0", text)
    path = directory / f"sitl_{control_hz}.toml"
    path.write_text(text)
    return path


def run_once(config: Path, duration: float, profile_dir: Path | None = None) -> tuple[float, int, int]:
    """One SITL run through the project's launcher; (wall seconds from linked to the end, RTT median
    and p99 in µs as the simulator reports them)."""
    def profiled(spec_cmd: list[str], name: str) -> list[str]:
        if profile_dir is None:
            return spec_cmd
        return [spec_cmd[0], "-u", "-m", "cProfile", "-o", str(profile_dir / f"{name}.prof"), *spec_cmd[2:]]

    spec = VehicleSpec(instance=INSTANCE, scenario="circle", speed="max", autostart=True, duration_s=duration,
                       sitl_config=str(config), extra_autopilot_args=("--quiet",))  # fmt: skip
    with Launcher() as launcher:
        sim = launcher.spawn("simulator", profiled(spec.simulator_command(), "simulator"))
        sim.wait_line("waiting for the autopilot", 30.0)
        launcher.spawn("autopilot", profiled(spec.autopilot_command(), "autopilot"))
        sim.wait_line(LINKED, 30.0)
        start = time.perf_counter()
        sim.wait(600.0)
        elapsed = time.perf_counter() - start
        match = RTT.search(sim.output)
    rtt = (int(match.group(1)), int(match.group(2))) if match else (0, 0)
    return elapsed, *rtt


def print_profile(path: Path, title: str, top: int = 14) -> None:
    print(f"\n--- {title}: top {top} by own time ---")
    stats = pstats.Stats(str(path))
    stats.sort_stats("tottime").print_stats(top)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--rates", type=int, nargs="+", default=[250, 500, 1000])
    parser.add_argument("--profile", action="store_true")
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        for rate in args.rates:
            elapsed, median, p99 = run_once(sitl_toml(tmpdir, rate), args.duration)
            results[rate] = (args.duration / elapsed, median, p99)
            print(
                f"{rate:5d} Hz control: {args.duration:.0f} s simulated in {elapsed:.2f} s wall "
                f"({args.duration / elapsed:.1f}x), HIL round trip median {median} us, p99 {p99} us"
            )
        if args.profile:
            run_once(sitl_toml(tmpdir, 500), min(args.duration, 20.0), tmpdir)
            print_profile(tmpdir / "simulator.prof", "simulator")
            print_profile(tmpdir / "autopilot.prof", "autopilot")
    print()
    for rate, (rtf, median, p99) in results.items():
        print(f"sitl_rtf_{rate}hz: {rtf:.1f} x")
        print(f"hil_rtt_median_{rate}hz: {median} us")
        print(f"hil_rtt_p99_{rate}hz: {p99} us")


if __name__ == "__main__":
    main()
