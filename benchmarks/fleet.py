"""A fleet in one process (``quadsitl fleet``, :mod:`sitl.fleet`): what a vehicle costs.

For each fleet size K of ``--counts`` it builds K vehicles on their own MAVLink ports (the
instances from ``--instance``), binds them, and flies them ``--seconds`` of simulation as fast as
the one process goes (one core), at 1 kHz physics and 500 Hz control, either idle on the ground
(``--flight idle``: the commander, telemetry and the plant run, the cascade does not), every
vehicle hovering at 2.5 m (``--flight hover``: armed at t = 0, the climb and the hold) or every
vehicle flying the paper's circle from t = 0 (``--flight circle``, the default: a mission's cost,
the vehicle in AUTO.MISSION).
It reports, per K:

* the real-time factor one process holds (simulated over wall seconds): K vehicles hold real time
  on one core while it is at least 1; the largest K measured that held it, and how many the
  processes' cores would hold at the largest K's CPU per vehicle;
* the CPU per vehicle per simulated second, and from it the largest fleet one core holds at real
  time (1 / that);
* the resident memory per vehicle (the process's growth over K vehicles, after they flew);
* the start-up: building and binding the K vehicles (to "all linked": each answers on its ports
  from its first frame).

``--processes P`` splits each fleet over P processes flown side by side (``quadsitl fleet
--processes P``): the real-time factor is the slowest process's. ``--compare-up K`` flies the same
for K vehicles with ``quadsitl up --count K`` (two processes per vehicle, lockstep over UDP, at
``--speed max``) in the same run: its real-time factor, CPU and memory per vehicle, start-up.

Run: ``.venv/bin/python benchmarks/fleet.py [--counts 1 10 20] [--seconds 10] [--flight circle]
[--instance 0] [--processes 1]``. The ports of instances ``--instance`` .. + K - 1 must be free. Last lines:
``name: value unit`` (for the largest K).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import subprocess
import sys
import time

from sitl.fleet import Fleet, FleetOptions, make_vehicle
from sitl.fleet_processes import shares


def resident_mb(pid: int | str = "self") -> float:
    """A process's resident set now (MB), from /proc (ru_maxrss is the peak); 0 once it is gone."""
    try:
        with open(f"/proc/{pid}/statm") as statm:
            return int(statm.read().split()[1]) * resource.getpagesize() / 1e6
    except OSError:
        return 0.0


def fly(count: int, args: argparse.Namespace) -> dict:
    """K vehicles built, bound and flown in this process: its figures."""
    options = FleetOptions()  # idle: on the ground, disarmed
    if args.flight in ("circle", "hover"):  # armed at t = 0, the scenario's flight (AUTO.MISSION)
        options = FleetOptions(scenario=args.flight, autostart=args.flight)
    make_vehicle(args.instance, options).close()  # imports, kernels loaded: not a vehicle's cost
    gc.collect()
    before = resident_mb()
    start = time.perf_counter()
    fleet = Fleet([make_vehicle(args.instance + k, options) for k in range(count)])
    fleet.open()
    startup_s = time.perf_counter() - start
    frames = int(round(args.seconds / fleet.dt))
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for _ in range(frames):
        fleet.step()
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    memory_mb = (resident_mb() - before) / count
    fleet.close()
    simulated = frames * fleet.dt
    return {"count": count, "rtf": simulated / wall, "cpu_per_vehicle_s": cpu / (count * simulated),
            "memory_mb": memory_mb, "startup_s": startup_s, "baseline_mb": before}  # fmt: skip


def up_figures(count: int, args: argparse.Namespace) -> dict:
    """The same flight with today's process-per-vehicle launch (``quadsitl up --count K``: two
    processes per vehicle, lockstep over UDP), at ``--speed max`` for ``--seconds``: its real-time
    factor (the whole launch's wall time from "linked" to exit), CPU per vehicle per simulated
    second (every process, ``RUSAGE_CHILDREN``, less what they had spent starting), resident
    memory per vehicle (its two processes, once linked) and start-up to all linked."""
    command = [sys.executable, "-u", "-m", "sitl.cli", "up", "--count", str(count),
               "--instance", str(args.instance), "--speed", "max", "--duration", str(args.seconds),
               "--no-log", "--no-restart"]  # fmt: skip
    if args.flight == "circle":
        command += ["--scenario", "circle", "--autostart"]
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    launch = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert launch.stdout is not None
    for line in launch.stdout:
        if "Ctrl-C stops every process" in line:
            break
    linked = time.perf_counter()
    processes = _descendants(launch.pid)
    memory_mb = sum(resident_mb(pid) for pid in processes) / count
    startup_cpu = sum(_cpu_s_of(pid) for pid in [launch.pid, *processes])  # (not the flight's)
    for _ in launch.stdout:
        pass
    launch.wait()
    wall = time.perf_counter() - linked
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime) - startup_cpu
    return {"count": count, "rtf": args.seconds / wall, "cpu_per_vehicle_s": cpu / (count * args.seconds),
            "memory_mb": memory_mb, "startup_s": linked - start}  # fmt: skip


def _descendants(pid: int) -> list[int]:
    """Every process under ``pid`` (Linux /proc)."""
    parent_of = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as stat:
                    parent_of[int(entry)] = int(stat.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
    found, frontier = [], [pid]
    while frontier:
        below = [p for p, parent in parent_of.items() if parent in frontier]
        found += below
        frontier = below
    return found


def _cpu_s_of(pid: int) -> float:
    """User + system CPU seconds of ``pid`` so far (Linux /proc; 0 once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--counts", type=int, nargs="+", default=[1, 10, 20])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per fleet")
    parser.add_argument("--flight", choices=("circle", "hover", "idle"), default="circle")
    parser.add_argument("--instance", type=int, default=0, help="the first vehicle's instance")
    parser.add_argument("--processes", type=int, default=1, help="the fleet split over P processes")
    parser.add_argument("--compare-up", type=int, default=0, metavar="K",
                        help="also the same flight with quadsitl up --count K (two processes per vehicle)")
    parser.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)  # one K, JSON out
    args = parser.parse_args()
    if args.child is not None:
        print(json.dumps(fly(args.child, args)), flush=True)
        return
    results = []
    for count in args.counts:  # each fleet in processes of its own: their memory is their own
        children = []
        for at, share in shares(args.instance, count, args.processes):  # as quadsitl fleet --processes P
            command = [sys.executable, __file__, "--child", str(share), "--seconds", str(args.seconds),
                       "--flight", args.flight, "--instance", str(at)]  # fmt: skip
            children.append(subprocess.Popen(command, stdout=subprocess.PIPE, text=True))
        parts = []
        for child in children:
            out, _ = child.communicate()
            if child.returncode != 0:
                raise SystemExit(f"a fleet process failed (exit {child.returncode})")
            parts.append(json.loads(out.strip().splitlines()[-1]))
        r = {"count": count, "rtf": min(p["rtf"] for p in parts),
             "cpu_per_vehicle_s": sum(p["cpu_per_vehicle_s"] * p["count"] for p in parts) / count,
             "memory_mb": sum(p["memory_mb"] * p["count"] for p in parts) / count,
             "startup_s": max(p["startup_s"] for p in parts),
             "baseline_mb": parts[0]["baseline_mb"]}  # fmt: skip
        results.append(r)
        per = r["cpu_per_vehicle_s"]
        where = "one process" if args.processes == 1 else f"{args.processes} processes side by side"
        print(f"K={count:4d} ({args.flight}): {r['rtf']:6.2f}x real time in {where}, "
              f"CPU {per * 1e3:6.1f} ms per vehicle per simulated s (one core holds "
              f"{1.0 / per:5.1f} vehicles at 1x), {r['memory_mb']:5.1f} MB per vehicle "
              f"(process {r['baseline_mb']:.0f} MB before them), start-up {r['startup_s']:5.2f} s",
              flush=True)  # fmt: skip
    if args.compare_up:
        u = up_figures(args.compare_up, args)
        print(f"K={u['count']:4d} ({args.flight}) with quadsitl up (two processes per vehicle): "
              f"{u['rtf']:6.2f}x real time, CPU {u['cpu_per_vehicle_s'] * 1e3:6.1f} ms per vehicle "
              f"per simulated s, "
              f"{u['memory_mb']:5.1f} MB per vehicle, start-up to all linked {u['startup_s']:5.2f} s",
              flush=True)  # fmt: skip
    r = results[-1]
    name = f"fleet_{args.flight}" + (f"_{args.processes}_processes" if args.processes > 1 else "")
    held = [x["count"] for x in results if x["rtf"] >= 1.0]
    print(f"{name}_largest_k_measured_at_1x: {max(held) if held else 0} vehicles")
    cores = args.processes
    print(f"{name}_vehicles_at_1x_on_{cores}_cores: {cores / r['cpu_per_vehicle_s']:.0f} vehicles")
    print(f"{name}_k: {r['count']} vehicles")
    print(f"{name}_real_time_factor: {r['rtf']:.2f} x")
    print(f"{name}_cpu_per_vehicle_per_sim_s: {r['cpu_per_vehicle_s'] * 1e3:.1f} ms")
    print(f"{name}_vehicles_per_core_at_1x: {1.0 / r['cpu_per_vehicle_s']:.1f} vehicles")
    print(f"{name}_memory_per_vehicle: {r['memory_mb']:.1f} MB")
    print(f"{name}_startup: {r['startup_s']:.2f} s")
    if args.compare_up:
        print(f"up_{args.flight}_k: {u['count']} vehicles")
        print(f"up_{args.flight}_real_time_factor: {u['rtf']:.2f} x")
        print(f"up_{args.flight}_cpu_per_vehicle_per_sim_s: {u['cpu_per_vehicle_s'] * 1e3:.1f} ms")
        print(f"up_{args.flight}_memory_per_vehicle: {u['memory_mb']:.1f} MB")
        print(f"up_{args.flight}_startup: {u['startup_s']:.2f} s")


if __name__ == "__main__":
    main()
