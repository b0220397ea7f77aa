"""What the live view costs the SITL: real-time factor with and without it, in one run.

One vehicle (``quadsitl`` instance 65: simulator + autopilot, lockstep, ``--speed max`` by
default, the paper's circle flown from t = 0 then a hover) runs for the whole benchmark. Its
real-time factor (simulation seconds per wall second, read from the simulator's
``quadsitl/<N>/info`` answer at the start and end of each phase) is measured in phases of
``--phase-s`` wall seconds, interleaved ``--rounds`` times so that the machine's drift hits every
condition alike:

* ``none``: nothing attached;
* ``server``: ``python -m gcs_scripts.view --instance 65`` running (zenoh truth + controller
  subscribers, MAVLink peer of the autopilot's GCS link, pushing at 30 Hz), no page open;
* ``page``: the same with the page open in headless Chromium (Debian's, through Playwright),
  drawing the scene and the plots as a person would see them.

The view server is started and stopped for each phase (so ``none`` really has no subscriber), and
each phase starts ``--settle-s`` after the change. A round is none, server, page, none; a
condition's cost in a round is 1 - its real-time factor over the mean of that round's two
``none`` phases (the machine is shared: a load that comes and goes cancels out), and the median
over the rounds is reported, and the same from the 80th percentiles of each condition's phases
(other processes only ever slow the simulation down, so the upper quantiles are its quiet
moments). On a
2-core machine at ``--speed max`` the simulator and the autopilot each keep a core busy, so
anything else that runs takes from them: that is the worst case; at ``--speed 1`` (what
``quadsitl up`` runs) the question is only whether real time is kept.

Run: ``.venv/bin/python benchmarks/view_cost.py [--speed max|1] [--rounds 3] [--phase-s 8]``.
Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from quadcommon import bus, wire  # noqa: E402
from sitl.launcher import Launcher, VehicleSpec  # noqa: E402

INSTANCE = 65
CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync",
]  # fmt: skip


def sim_time(session, timeout_s: float = 5.0) -> float:
    """The simulator's own simulation time, from its info queryable."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for reply in session.get(wire.zenoh_key(INSTANCE, "info"), timeout=1.0):
            if reply.ok is not None:
                return float(json.loads(reply.ok.payload.to_bytes())["sim_time_s"])
        time.sleep(0.05)
    raise RuntimeError("the simulator did not answer its info query")


def cpu_seconds(match) -> float:
    """CPU time (user + system, s) of every process whose command line ``match`` accepts."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if match(cmdline):
            total += (int(fields[11]) + int(fields[12])) / tick
    return total


def is_view(cmdline: str) -> bool:
    return "-m gcs_scripts.view" in cmdline and f"--instance {INSTANCE}" in cmdline


def is_chromium(cmdline: str) -> bool:
    return cmdline.startswith(("/usr/lib/chromium/", "/usr/bin/chromium"))


def is_sitl(cmdline: str) -> bool:
    return f"--instance {INSTANCE}" in cmdline and ("-m simulator" in cmdline or "-m autopilot" in cmdline)


WHO = {"sitl": is_sitl, "view": is_view, "chromium": is_chromium}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class View:
    """The view server process (and optionally a browser page on it)."""

    def __init__(self, with_page: bool, playwright) -> None:
        self.port = free_port()
        self.proc = subprocess.Popen(
            [sys.executable, "-u", "-m", "gcs_scripts.view", "--instance", str(INSTANCE),
             "--port", str(self.port)],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        assert self.proc.stdout is not None
        deadline = time.monotonic() + 30.0
        for line in self.proc.stdout:
            if "quadsitl view: open" in line:
                break
            if time.monotonic() > deadline:
                raise RuntimeError("the view did not start")
        self.browser = self.page = None
        if with_page:
            self.browser = playwright.chromium.launch(
                executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS, headless=True
            )
            self.page = self.browser.new_page(viewport={"width": 1280, "height": 900})
            self.page.goto(f"http://127.0.0.1:{self.port}/")
            self.page.wait_for_function(
                "() => window.quadsitlView.connected && window.quadsitlView.frames > 10", timeout=20000
            )

    def frames(self) -> int:
        return int(self.page.evaluate("() => window.quadsitlView.frames")) if self.page else 0

    def close(self) -> None:
        if self.browser is not None:
            self.browser.close()
        self.proc.terminate()
        try:
            self.proc.wait(10.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--speed", default="max", help="SITL pacing: max (default) or a factor")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--phase-s", type=float, default=5.0, help="wall seconds measured per phase")
    parser.add_argument(
        "--settle-s", type=float, default=1.5, help="wall seconds after a change, not measured"
    )
    args = parser.parse_args(argv)

    from playwright.sync_api import sync_playwright

    spec = VehicleSpec(instance=INSTANCE, scenario="circle", autostart=True, speed=args.speed)
    ratios: dict[str, list[float]] = {"server": [], "page": []}
    rtf: dict[str, list[float]] = {"none": [], "server": [], "page": []}
    page_rates: list[float] = []
    cpu = {c: {k: [] for k in WHO} for c in ("none", "server", "page")}
    with Launcher() as launcher, sync_playwright() as pw:
        launcher.start_vehicles([spec])
        session = bus.open_peer(wire.ports(INSTANCE).zenoh)
        try:
            sim_time(session)
            for rnd in range(args.rounds):
                measured: dict[str, list[float]] = {"none": [], "server": [], "page": []}
                # none, server, page, none: each condition's ratio is to the mean of the two
                # "none" phases around it, so a load that comes and goes cancels out.
                for condition in ("none", "server", "page", "none"):
                    view = None if condition == "none" else View(condition == "page", pw)
                    try:
                        time.sleep(args.settle_s)
                        f0, s0, w0 = (view.frames() if view else 0), sim_time(session), time.monotonic()
                        c0 = {k: cpu_seconds(m) for k, m in WHO.items()}
                        time.sleep(args.phase_s)
                        s1, w1 = sim_time(session), time.monotonic()
                        c1 = {k: cpu_seconds(m) for k, m in WHO.items()}
                        f1 = view.frames() if view else 0
                    finally:
                        if view is not None:
                            view.close()
                    measured[condition].append((s1 - s0) / (w1 - w0))
                    for k in WHO:
                        cpu[condition][k].append(100.0 * (c1[k] - c0[k]) / (w1 - w0))
                    if condition == "page":
                        page_rates.append((f1 - f0) / (w1 - w0))
                base = statistics.fmean(measured["none"])
                for key in ("server", "page"):
                    ratios[key].append(measured[key][0] / base)
                for key, values in measured.items():
                    rtf[key] += values
                none = measured["none"]
                print(
                    f"round {rnd + 1}: real-time factor none {none[0]:.2f} / {none[1]:.2f}, "
                    f"server {measured['server'][0]:.2f}, page {measured['page'][0]:.2f}",
                    flush=True,
                )
        finally:
            session.close()

    def cost(key: str) -> str:
        values = sorted(100.0 * (1.0 - r) for r in ratios[key])
        return f"{statistics.median(values):.1f} % (rounds: {', '.join(f'{v:.1f}' for v in values)})"

    print(f"speed {args.speed}, {args.rounds} rounds of none/server/page/none, {args.phase_s:g} s each")
    for condition in ("none", "server", "page"):
        parts = ", ".join(f"{k} {statistics.median(v):.1f} %" for k, v in cpu[condition].items())
        print(f"CPU (% of one core, median) with {condition:>6}: {parts}")
    print(f"cost of the view server alone: {cost('server')}")
    print(f"cost of the view server with the page open: {cost('page')}")

    def p80(values: list[float]) -> float:
        return sorted(values)[int(0.8 * (len(values) - 1))]

    # Others' work only ever lowers the real-time factor: the upper quantiles are the quiet moments.
    print(
        "80th percentiles (quiet moments): "
        + ", ".join(f"{k} {p80(v):.2f}x" for k, v in rtf.items())
        + f"; cost server {100.0 * (1.0 - p80(rtf['server']) / p80(rtf['none'])):.1f} %, "
        f"page {100.0 * (1.0 - p80(rtf['page']) / p80(rtf['none'])):.1f} %"
    )
    print(f"rtf_without_view: {statistics.median(rtf['none']):.3f} x")
    print(f"rtf_with_view_server: {statistics.median(rtf['server']):.3f} x")
    print(f"rtf_with_view_and_page: {statistics.median(rtf['page']):.3f} x")
    print(f"cost_view_server: {100.0 * (1.0 - statistics.median(ratios['server'])):.1f} %")
    print(f"cost_view_and_page: {100.0 * (1.0 - statistics.median(ratios['page'])):.1f} %")
    print(f"page_update_rate: {statistics.median(page_rates):.1f} Hz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
