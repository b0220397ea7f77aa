"""Soak while flying: missions back to back for an hour of simulated time, recorded and viewed.

One vehicle (instance 66: simulator + autopilot, lockstep, ``--speed max`` by default) flies the
same mission again and again (takeoff to 2.5 m, a 4 m square at 2.5 m, land; uploaded once,
flown, disarmed, flown again) until ``--sim-hours`` of simulation time have passed, on a 100 Ah
pack (``paper_quad`` otherwise: about 11 hours of hover; the shipped 2.2 Ah pack would refuse to
arm after a quarter of an hour), with the
recorder (``python -m gcs_scripts.record``: tlog + Parquet) and the live view server
(``python -m gcs_scripts.view``: zenoh truth + controller, the MAVLink telemetry, pushing to any
page) attached for the whole run. ``--impair LINK:SPEC`` passes faults to ``quadsitl up``'s
processes as ``--impair`` does.

Every ``--sample-wall-s`` it samples each process's resident memory (``VmRSS`` of
``/proc/PID/status``) and the simulator's simulation time (its ``quadsitl/<N>/info``). At the end
it prints:

* each process's memory over simulated time (one line per 10 simulated minutes), and its growth
  from the end of the warm-up (the first 10 simulated minutes) to the end, per hour;
* the recorder's rows against the frames flown in its window (time stamps contiguous, one row per
  control step: nothing lost) and the tlog's size;
* the lockstep speed (simulated seconds per wall second) per 10 simulated minutes;
* the frames the simulator resent (lost datagrams under ``--impair``).

Run (in a network namespace of its own, so its fixed ports meet nobody's)::

    unshare -n sh -c 'ip link set lo up && exec "$0" "$@"' .venv/bin/python benchmarks/soak.py

Not part of the test suite. Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gcs_scripts import upload_mission  # noqa: E402
from quadcommon import bus, wire  # noqa: E402
from quadcommon.config import config_path  # noqa: E402
from sitl.launcher import Launcher, VehicleSpec  # noqa: E402

INSTANCE = 66
BUCKET_S = 600.0  # simulated seconds per line of the report
SQUARE = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0), (0.0, 0.0)]
ALTITUDE_M = 2.5


def mission_items() -> list:
    entries = [{"type": "takeoff", "altitude_m": ALTITUDE_M}]
    entries += [{"type": "waypoint", "position": [x, y, ALTITUDE_M]} for x, y in SQUARE]
    entries.append({"type": "land"})
    return upload_mission.items_from_list({"frame": "paper", "items": entries})


def _interrupt(*_args) -> None:
    raise KeyboardInterrupt


def fly_mission(link, items, sample) -> None:
    """From the first item: arm, AUTO.MISSION, until the vehicle has landed and disarmed."""
    last = len(items) - 1
    link.set_current(0)
    link.reached.clear()
    link.arm()
    link.set_mode("AUTO.MISSION")
    link.wait_until(lambda lk: sample() or (bool(lk.reached) and lk.reached[-1][1] == last and not lk.armed),
                    600.0, what="the mission to end disarmed")  # fmt: skip


def rss_mb(pid: int) -> float:
    """Resident memory of ``pid`` (MB), NaN if it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def simulator_info(session, timeout_s: float = 5.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for reply in session.get(wire.zenoh_key(INSTANCE, "info"), timeout=1.0):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        time.sleep(0.1)
    raise RuntimeError("the simulator's info queryable did not answer")


def start(cmd: list[str], ready: str, log: Path) -> subprocess.Popen:
    """A helper process, its output to ``log``; returns once ``ready`` appears in it."""
    out = log.open("w")
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=out, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 60.0
    while ready not in log.read_text():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{cmd[3]} did not start: {log.read_text()[-2000:]}")
        time.sleep(0.1)
    return proc


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--sim-hours", type=float, default=1.0, help="simulated time to fly (default 1 h)")
    parser.add_argument("--speed", default="max", help="SITL pacing (default max)")
    parser.add_argument("--sample-wall-s", type=float, default=5.0, help="wall seconds between samples")
    parser.add_argument("--impair", action="append", default=[], metavar="LINK:SPEC",
                        help="faults on a link, as quadsitl up --impair")  # fmt: skip
    parser.add_argument("--out", default=None, help="directory for the recording (default: a temporary one)")
    args = parser.parse_args()
    target_s = args.sim_hours * 3600.0
    out = Path(args.out or tempfile.mkdtemp(prefix="quadsitl-soak-"))
    out.mkdir(parents=True, exist_ok=True)
    vehicle = out / "soak_quad.toml"  # paper_quad on a pack that lasts the soak
    vehicle.write_text(config_path("vehicle", "paper_quad").read_text()
                       .replace('name = "paper_quad"', 'name = "soak_quad"')
                       .replace("capacity_mah = 2200.0", "capacity_mah = 100000.0"))  # fmt: skip
    spec = VehicleSpec(instance=INSTANCE, vehicle=str(vehicle), scenario="hover", speed=args.speed,
                       impair=tuple(args.impair))  # fmt: skip
    python = [sys.executable, "-u", "-m"]
    env_note = f"speed {args.speed}, impair {' '.join(args.impair) or 'none'}"
    print(f"soak: {args.sim_hours:g} h simulated, {env_note}; recording in {out}", flush=True)
    samples: list[tuple[float, float, dict[str, float]]] = []  # (wall, sim, rss by process)
    missions = 0
    with Launcher() as launcher:
        launcher.start_vehicles([spec], 30.0)
        pids = {"simulator": launcher.child(f"simulator[{INSTANCE}]").pid,
                "autopilot": launcher.child(f"autopilot[{INSTANCE}]").pid}  # fmt: skip
        recorder = start([*python, "gcs_scripts.record", "--instance", str(INSTANCE), "--out",
                          str(out / "soak")], "record: ", out / "recorder.log")  # fmt: skip
        view = start([*python, "gcs_scripts.view", "--instance", str(INSTANCE), "--port", "0"],
                     "quadsitl view: open", out / "view.log")  # fmt: skip
        pids["recorder"], pids["view"] = recorder.pid, view.pid
        session = bus.open_peer(wire.ports(INSTANCE).zenoh)
        link = upload_mission.connect(None, INSTANCE, 30.0)
        items = mission_items()
        link.upload(items)
        wall0 = time.monotonic()
        next_sample = [0.0]
        start_info = simulator_info(session)

        def sample(_link=None) -> bool:
            now = time.monotonic()
            if now >= next_sample[0]:
                next_sample[0] = now + args.sample_wall_s
                sim_s = simulator_info(session)["sim_time_s"]
                samples.append((now - wall0, sim_s, {k: rss_mb(p) for k, p in pids.items()}))
            return False

        signal.signal(signal.SIGTERM, _interrupt)  # stopped early: still report what was flown
        try:
            while True:
                next_sample[0] = 0.0
                sample()
                if samples[-1][1] >= target_s:
                    break
                try:
                    fly_mission(link, items, sample)
                except KeyboardInterrupt:
                    print("soak: interrupted; reporting what was flown", flush=True)
                    break
                missions += 1
                if missions % 10 == 0:
                    s = samples[-1]
                    print(f"soak: {missions} missions, t={s[1]:.0f} s simulated after {s[0]:.0f} s wall; "
                          + ", ".join(f"{k} {v:.1f} MB" for k, v in s[2].items()), flush=True)  # fmt: skip
            end_info = simulator_info(session)
        finally:
            signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second stop waits for the recorder's merge
            link.close()
            session.close()
            recorder.send_signal(signal.SIGINT)
            recorder_code = recorder.wait(600.0)  # it merges its parts into one Parquet file
            view.terminate()
            view.wait(30.0)
    report(samples, out, start_info, end_info, missions, recorder_code)
    return 0


def report(samples, out: Path, start_info: dict, end_info: dict, missions: int, recorder_code: int) -> None:
    import numpy as np
    import pyarrow.parquet as pq

    names = list(samples[0][2])
    wall = np.array([s[0] for s in samples])
    sim = np.array([s[1] for s in samples])
    print(f"\n{missions} missions flown; {sim[-1]:.0f} s simulated in {wall[-1]:.0f} s wall "
          f"({sim[-1] / wall[-1]:.1f}x overall)")  # fmt: skip
    print("\nresident memory (MB) by simulated time:")
    print("  sim min  " + "  ".join(f"{n:>10}" for n in names))
    rows = [i for b in np.arange(0.0, sim[-1] + 1.0, BUCKET_S) for i in [int(np.searchsorted(sim, b))]
            if i < len(sim)]  # fmt: skip
    for i in sorted(set(rows + [len(sim) - 1])):
        print(f"  {sim[i] / 60:7.1f}  " + "  ".join(f"{samples[i][2][n]:10.1f}" for n in names))
    # Growth: the median of the samples in the first 10 simulated minutes after the warm-up
    # against those of the last 10 (single samples swing with a garbage collection or a batch)
    first = (sim >= BUCKET_S) & (sim < 2 * BUCKET_S)
    last = sim >= sim[-1] - BUCKET_S
    hours = (np.median(sim[last]) - np.median(sim[first])) / 3600.0 if first.any() else 0.0
    growth = {}
    for n in names:
        rss = np.array([s[2][n] for s in samples])
        growth[n] = (np.median(rss[last]) - np.median(rss[first])) / hours if hours > 0 else float("nan")
        print(f"  {n}: {growth[n]:+.1f} MB per simulated hour after the warm-up (medians of the first "
              f"10 minutes after it and of the last 10); peak {np.nanmax(rss):.1f} MB")  # fmt: skip
    print("\nlockstep speed (simulated s per wall s) per 10 simulated minutes:")
    speeds = []
    for b in np.arange(0.0, sim[-1] - BUCKET_S / 2, BUCKET_S):  # full buckets (a last half one too)
        i, j = int(np.searchsorted(sim, b)), int(np.searchsorted(sim, b + BUCKET_S))
        j = min(j, len(sim) - 1)
        if j > i and wall[j] > wall[i]:
            speeds.append((sim[j] - sim[i]) / (wall[j] - wall[i]))
            print(f"  {b / 60:5.0f}-{(b + BUCKET_S) / 60:3.0f} min: {speeds[-1]:6.1f}x")
    merged = out / "soak.parquet"
    table = pq.read_table(merged, columns=["time_s"]) if merged.exists() else None
    lost = split = 0
    if table is not None:
        t = table.column("time_s").to_numpy()
        keys = np.round(t * 500.0).astype(np.int64)  # frame numbers (500 Hz)
        frames = int(keys.max() - keys.min()) + 1
        unique = len(np.unique(keys))
        lost, split = frames - unique, len(keys) - unique
        tlog_mb = os.path.getsize(out / "soak.tlog") / 1e6
        print(f"\nrecorder (exit {recorder_code}): {len(t)} rows for the {frames} frames flown from "
              f"t={t.min():.3f} s to t={t.max():.3f} s: {lost} frames without a row, {split} frames "
              f"written as more than one row; tlog {tlog_mb:.0f} MB")  # fmt: skip
    else:
        print(f"\nrecorder (exit {recorder_code}): no soak.parquet in {out}")
    resent = end_info.get("resends", 0) - start_info.get("resends", 0)
    print(f"frames resent by the simulator: {resent}")
    print()
    for n in names:
        print(f"soak_memory_growth_{n}: {growth[n]:+.1f} MB/h")
    print(f"soak_recorder_frames_missing: {lost} frames")
    print(f"soak_recorder_frames_split: {split} frames")
    print(f"soak_lockstep_speed_min: {min(speeds) if speeds else float('nan'):.1f} x")
    print(f"soak_lockstep_speed_max: {max(speeds) if speeds else float('nan'):.1f} x")
    print(f"soak_simulated: {sim[-1]:.0f} s")


if __name__ == "__main__":
    sys.exit(main())
