"""SITL speed: lockstep real-time factor with both processes and MAVLink on the wire.

For each control rate (250, 500, 1000 Hz; physics 1 kHz) it starts the simulator
(``--speed max --duration 40``, the paper's circle with its disturbances) and the autopilot
(``--autostart circle``: armed at t = 0, flying the paper's trajectory), and measures the wall
time of the simulator's frame loop; the simulator reports the HIL round trip (frame
sent -> matching HIL_ACTUATOR_CONTROLS received) per frame: median and p99.

Run: ``.venv/bin/python benchmarks/sitl_rtf.py [--duration 40] [--rates 250 500 1000] [--profile]
[--estimator truth ekf] [--sensors mocap] [--instance N] [--log] [--repeat K]``.
``--estimator``: what the autopilot flies on, one run per rate for each (truth, its EKF over the
``--sensors`` profile; default: truth only), so the cost of the EKF is a ratio within one run.
Besides the wall time, the CPU time of both processes (user + system, start-up included) per
simulated second is reported: on a shared machine it moves less than the wall time.
``--log``: each run three times, with the autopilot's flight log (ULog, SDLOG_MODE 0: the flight
is armed from t = 0, so the whole run is logged) off, on and off again (the order rotates),
``--repeat`` times; the last lines add the ratio of the real-time factors (on over the mean of the
two offs, the median of the repetitions), the same ratio of two runs with the log off (off over
off: what this machine's noise alone gives, the resolution of the first figure), the ratio of
the two processes' CPU time (steadier than the wall time on a shared machine) and the log's size
per simulated second. In every run this process subscribes to the simulator's
truth on zenoh, as a recorder would: whether the truth has a subscriber changes the simulator's
timing by itself (measured: with none, the HIL round trip sat at ~1 ms in some runs).
The wall time of a run is the simulator's own clock on its frame loop (its exit summary):
waiting for the process to exit polls, up to 50 ms a look, several per cent of a short run.
``--profile`` also runs both processes under cProfile at 500 Hz (with the last ``--estimator``)
and prints where the time goes. The machine is shared and noisy:
compare the rates with each other, measured in one run. Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import contextlib
import pstats
import re
import resource
import tempfile
import time
from pathlib import Path

from quadcommon import bus, wire
from sitl.launcher import LINKED, Launcher, VehicleSpec

REPO = Path(__file__).resolve().parents[1]
INSTANCE = 30
RTT = re.compile(r"HIL round trip median (\d+) us, p99 (\d+) us")
FRAME_LOOP = re.compile(r"simulated in ([0-9.]+) s of frame loop")


def sitl_toml(directory: Path, control_hz: int) -> Path:
    text = (REPO / "config" / "sitl.toml").read_text()
    text = re.sub(r"control_hz = [0-9.]+", f"control_hz = {control_hz}.0", text)
    path = directory / f"sitl_{control_hz}.toml"
    path.write_text(text)
    return path


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_once(
    config: Path,
    duration: float,
    profile_dir: Path | None = None,
    estimator: str = "truth",
    sensors: str | None = None,
    instance: int = INSTANCE,
    log_dir: Path | None = None,
    truth_subscriber: bool = False,
) -> tuple[float, int, int, float]:
    """One SITL run through the project's launcher; (wall seconds from linked to the end, RTT median
    and p99 in µs as the simulator reports them, CPU seconds of both processes). ``truth_subscriber``:
    this process subscribes to the simulator's truth on zenoh during the run (as a recorder does)."""
    def profiled(spec_cmd: list[str], name: str) -> list[str]:
        if profile_dir is None:
            return spec_cmd
        return [spec_cmd[0], "-u", "-m", "cProfile", "-o", str(profile_dir / f"{name}.prof"), *spec_cmd[2:]]

    spec = VehicleSpec(instance=instance, scenario="circle", speed="max", autostart=True, duration_s=duration,
                       sitl_config=str(config), extra_autopilot_args=("--quiet",), estimator=estimator,
                       sensors=sensors if estimator == "ekf" else None,
                       log_dir=str(log_dir) if log_dir is not None else None)  # fmt: skip
    cpu_before = _children_cpu_s()
    with Launcher() as launcher, contextlib.ExitStack() as taps:
        sim = launcher.spawn("simulator", profiled(spec.simulator_command(), "simulator"))
        sim.wait_line("waiting for the autopilot", 30.0)
        if truth_subscriber:
            import zenoh

            session = taps.enter_context(contextlib.closing(bus.open_peer(spec.ports().zenoh)))
            session.declare_subscriber(wire.zenoh_key(instance, "truth"), zenoh.handlers.RingChannel(64))
        launcher.spawn("autopilot", profiled(spec.autopilot_command(), "autopilot"))
        sim.wait_line(LINKED, 30.0)
        start = time.perf_counter()
        sim.wait(600.0)
        elapsed = time.perf_counter() - start
        match = RTT.search(sim.output)
        loop = FRAME_LOOP.search(sim.output)
    rtt = (int(match.group(1)), int(match.group(2))) if match else (0, 0)
    # The simulator's own clock on its frame loop (see the module's docstring), when it reports it.
    if loop is not None:
        elapsed = float(loop.group(1))
    return elapsed, *rtt, _children_cpu_s() - cpu_before


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
    parser.add_argument("--estimator", nargs="+", choices=("truth", "ekf"), default=["truth"])
    parser.add_argument("--sensors", default="mocap", help="sensor profile of the EKF runs (default mocap)")
    parser.add_argument("--instance", type=int, default=INSTANCE, help=f"SITL instance (default {INSTANCE})")
    parser.add_argument("--log", action="store_true", help="each run with the flight log off and on")
    parser.add_argument("--repeat", type=int, default=1, help="--log: pairs of runs per rate (default 1)")
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        if args.log:
            log_pairs(args, tmpdir)
            return
        for rate in args.rates:
            for estimator in args.estimator:
                elapsed, median, p99, cpu = run_once(
                    sitl_toml(tmpdir, rate), args.duration, None, estimator, args.sensors, args.instance
                )
                results[rate, estimator] = (args.duration / elapsed, median, p99, cpu / args.duration)
                on = "truth" if estimator == "truth" else f"ekf+{args.sensors}"
                print(
                    f"{rate:5d} Hz control on {on}: {args.duration:.0f} s simulated in {elapsed:.2f} s wall "
                    f"({args.duration / elapsed:.1f}x), CPU {cpu:.1f} s, HIL round trip median {median} us, "
                    f"p99 {p99} us",
                    flush=True,
                )
        if args.profile:
            profile_s = min(args.duration, 20.0)
            last = args.estimator[-1]
            run_once(sitl_toml(tmpdir, 500), profile_s, tmpdir, last, args.sensors, args.instance)
            print_profile(tmpdir / "simulator.prof", "simulator")
            print_profile(tmpdir / "autopilot.prof", "autopilot")
    print()
    for (rate, estimator), (rtf, median, p99, cpu_per_s) in results.items():
        suffix = "" if estimator == "truth" else "_ekf"
        print(f"sitl_rtf_{rate}hz{suffix}: {rtf:.1f} x")
        print(f"cpu_per_sim_s_{rate}hz{suffix}: {cpu_per_s:.3f} s")
        print(f"hil_rtt_median_{rate}hz{suffix}: {median} us")
        print(f"hil_rtt_p99_{rate}hz{suffix}: {p99} us")


def log_pairs(args, tmpdir: Path) -> None:
    """The flight log's cost: runs with it off, on and off again (the machine's load moves slowly,
    so neighbours compare; the order rotates so that no run is always first), per rate and
    estimator. The two offs of a repetition give the noise floor: their ratio would be 1 on a
    quiet, steady machine."""
    import statistics

    orders = (("off", "on", "off2"), ("on", "off", "off2"), ("off", "off2", "on"))
    lines = []
    for rate in args.rates:
        for estimator in args.estimator:
            ratios, floor, cpu_ratios, sizes = [], [], [], []
            for k in range(args.repeat):
                rtf, cpu_s = {}, {}
                for run in orders[k % len(orders)]:
                    on = run == "on"
                    log_dir = tmpdir / f"log_{rate}_{estimator}_{k}" if on else None
                    config = sitl_toml(tmpdir, rate)
                    elapsed, median, p99, cpu = run_once(config, args.duration, None, estimator, args.sensors,
                                                         args.instance, log_dir,
                                                         truth_subscriber=True)  # fmt: skip
                    rtf[run], cpu_s[run] = args.duration / elapsed, cpu
                    state = "on " if on else "off"
                    print(f"{rate:5d} Hz on {estimator}, flight log {state}: {rtf[run]:.1f}x, "
                          f"CPU {cpu:.1f} s, HIL round trip median {median} us, p99 {p99} us", flush=True)
                    if on:
                        sizes += [f.stat().st_size for f in log_dir.rglob("*.ulg")]
                ratios.append(rtf["on"] / statistics.mean((rtf["off"], rtf["off2"])))
                floor.append(rtf["off2"] / rtf["off"])
                cpu_ratios.append(cpu_s["on"] / statistics.mean((cpu_s["off"], cpu_s["off2"])))
            suffix = "" if estimator == "truth" else "_ekf"
            name = f"{rate}hz{suffix}_log_on_over_off"
            print(f"{rate} Hz on {estimator}, per repetition: off over off (the noise floor) "
                  f"{min(floor):.3f} to {max(floor):.3f}, on over off {min(ratios):.3f} to {max(ratios):.3f}")
            lines.append(f"sitl_rtf_{rate}hz{suffix}_log_off_over_off: {statistics.median(floor):.3f} ratio")
            lines.append(f"sitl_cpu_{name}: {statistics.median(cpu_ratios):.3f} ratio")
            if sizes:
                per_s = statistics.median(sizes) / args.duration
                lines.append(f"ulog_bytes_per_sim_s_{rate}hz{suffix}: {per_s:.0f} B")
            lines.append(f"sitl_rtf_{name}: {statistics.median(ratios):.3f} ratio")
    print()
    print("\n".join(lines))


if __name__ == "__main__":
    main()
