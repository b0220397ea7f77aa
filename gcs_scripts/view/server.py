"""``quadsitl view``: the live view (and replays) served to a browser on 127.0.0.1.

One asyncio process, one port: the page and its JavaScript (``static/``, libraries vendored by
:mod:`.build`) over HTTP, and the data over a WebSocket at ``/ws`` (the ``websockets`` library:
one pure-Python dependency without transitive ones; its ``process_request`` hook serves the
handful of static files, so no web framework is needed).

Live (``--instance N ...`` / ``--count K``): every ``1/rate`` wall seconds (``--rate``, at most
30 Hz) each vehicle's zenoh streams and MAVLink socket are drained (:class:`.live.LiveVehicle`),
and one JSON ``frame`` with the newest sample of each vehicle that moved, its status, the new
disturbance onsets and STATUSTEXT goes to every page. Between ticks the process sleeps, niced
(``os.nice(10)``, and ``SCHED_IDLE`` while the vehicles run more than 4x faster than real time:
:class:`.live.CpuPriority`), so on a 2-core machine it yields to the lockstep loop. A page that cannot keep
up skips frames (its socket's write buffer is checked first); it never slows the tick.

Replay (``quadsitl view LOG [LOG ...]``): the logs are read once (:mod:`.replay`) and sent whole
when a page connects; the page plays them back itself (play/pause, speed, time slider).

Messages (JSON text): ``{"type": "hello", "kind": "live"|"replay", "tracks": [...]}`` first,
then (live) ``{"type": "frame", "seq", "wall", "v": [{"id", "s": sample|null, "st": status}],
"events": [[id, t]], "texts": [[id, t, severity, text]], "rtf", "yielding"}`` (``rtf``: simulation
seconds per wall second; ``yielding``: the view runs at SCHED_IDLE, see :class:`.live.CpuPriority`)
and ``{"type": "tracks"}`` when a vehicle's description (controller, scenario) arrives.
"""

from __future__ import annotations

import argparse
import asyncio
import errno
import json
import mimetypes
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from quadcommon import frames, wire
from quadcommon.cli_help import HelpFormatter

from . import build as vendor_build

STATIC = Path(__file__).resolve().parent / "static"
MAX_RATE_HZ = 30.0
YIELD_RATE_HZ = 10.0  # pushes per wall second while the view yields the CPU (see CpuPriority)
KEEPALIVE_WALL_S = 0.5  # a frame at least this often, so the page sees the link is alive
CLIENT_BUFFER_LIMIT = 1 << 20  # bytes queued for a page before its frames are skipped
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#17becf", "#8c564b", "#e377c2")
CONTENT_TYPES = {".js": "text/javascript", ".css": "text/css", ".html": "text/html; charset=utf-8"}


def track_color(index: int) -> str:
    """The ``index``-th track's colour (CSS hex), cycling through :data:`COLORS`."""
    return COLORS[index % len(COLORS)]


# --------------------------------------------------------------------------------------------
# Sources
# --------------------------------------------------------------------------------------------

def home_offset_m(home: tuple[float, float, float] | None,
                  origin: tuple[float, float, float] | None) -> list[float] | None:  # fmt: skip
    """Where ``home`` sits in the local frame about ``origin`` (paper frame: x north, y west, z up;
    m), None when either is unknown."""
    if home is None or origin is None:
        return None
    ned = frames.geodetic_to_ned(home[0], home[1], home[2], origin)
    return [round(value, 4) for value in frames.vector_from_ned(ned)]


class LiveSource:
    """Live vehicles; :meth:`tick` drains them and returns the frame to push (or None)."""

    kind = "live"

    def __init__(
        self, instances: Sequence[int], sitl_config: str | None = None, adaptive: bool = False
    ) -> None:
        from quadcommon.config import load_sitl

        from .live import CpuPriority, LiveVehicle

        sitl = load_sitl(sitl_config)
        self.vehicles = [LiveVehicle(n, sitl) for n in instances]
        self.priority = CpuPriority(enabled=adaptive)
        self.seq = 0
        self._last_sent = 0.0
        self._last_status: list[dict[str, Any] | None] = [None] * len(self.vehicles)

    def open(self) -> None:
        """Open every vehicle; on a failure close those opened and re-raise."""
        try:
            for v in self.vehicles:
                v.open()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close every vehicle."""
        for v in self.vehicles:
            v.close()

    def tracks(self) -> list[dict[str, Any]]:
        """Each vehicle's description with its track id, colour and where its local frame's origin
        (its home) sits in the first vehicle's (``offset_m``, paper frame; None until its home is
        known): vehicles with homes apart (``quadsitl fleet --spacing``) are drawn apart."""
        homes = [v.home() for v in self.vehicles]
        origin = next((home for home in homes if home is not None), None)
        return [{"id": i, "color": track_color(i), "offset_m": home_offset_m(home, origin), **v.describe()}
                for i, (v, home) in enumerate(zip(self.vehicles, homes, strict=True))]  # fmt: skip

    def hello(self) -> list[dict[str, Any]]:
        """The first messages a page receives: the source kind and its tracks."""
        return [{"type": "hello", "kind": self.kind, "rate_hz": None, "tracks": self.tracks()}]

    def tick(self, wall: float) -> list[dict[str, Any]]:
        """Poll every vehicle at wall time ``wall`` (s); the messages to broadcast: new samples, status,
        events and texts, and the tracks again when a description changed."""
        out: list[dict[str, Any]] = []
        entries, events, texts = [], [], []
        changed = False
        described = False
        for i, v in enumerate(self.vehicles):
            v.poll(wall)
            if v.info_changed:
                v.info_changed = False
                described = True
            sample = v.sampler.take()
            status = v.status()
            if sample is not None or status != self._last_status[i]:
                changed = True
            self._last_status[i] = status
            entries.append({"id": i, "s": None if sample is None else sample.to_json(), "st": status})
            events += [[i, round(t, 6)] for t in v.sampler.take_events()]
            texts += [[i, round(t, 6), sev, text] for t, sev, text in v.telemetry.take_texts()]
        times = [t for t in (v.sampler.latest_time_s for v in self.vehicles) if t is not None]
        self.priority.update(wall, max(times) if times else None)
        if described:
            out.append({"type": "tracks", "tracks": self.tracks()})
        if changed or events or texts or wall - self._last_sent >= KEEPALIVE_WALL_S:
            self.seq += 1
            self._last_sent = wall
            out.append(
                {
                    "type": "frame",
                    "seq": self.seq,
                    "wall": round(wall, 4),
                    "v": entries,
                    "events": events,
                    "texts": texts,
                    "rtf": None if self.priority.rtf is None else round(self.priority.rtf, 2),
                    "yielding": self.priority.idle,
                }
            )
        return out


class ReplaySource:
    """Recorded logs, sent whole to each page."""

    kind = "replay"

    def __init__(
        self,
        paths: Sequence[str],
        labels: Sequence[str] = (),
        align: str = "sim",
        rate_hz: float = MAX_RATE_HZ,
    ) -> None:
        from .replay import load_track

        if labels and len(labels) != len(paths):
            raise ValueError(f"--labels: {len(labels)} labels for {len(paths)} logs")
        self.loaded = [
            load_track(p, labels[i] if labels else None, rate_hz=rate_hz, align=align)
            for i, p in enumerate(paths)
        ]
        self.align = align
        self._hello = [
            {
                "type": "hello",
                "kind": self.kind,
                "align": align,
                "tracks": [
                    {"id": i, "color": track_color(i), **t.to_json()} for i, t in enumerate(self.loaded)
                ],
            }
        ]
        self._hello_text = [json.dumps(m, separators=(",", ":")) for m in self._hello]

    def open(self) -> None:
        """Nothing to open: the logs were read when the source was made."""
        pass

    def close(self) -> None:
        """Nothing to close."""
        pass

    def hello(self) -> list[dict[str, Any]]:
        """The whole replay, as the messages a page receives first."""
        return self._hello

    def hello_texts(self) -> list[str]:
        """The :meth:`hello` messages as JSON text, encoded once."""
        return self._hello_text

    def tick(self, wall: float) -> list[dict[str, Any]]:
        """Nothing: a replay is sent whole in :meth:`hello`."""
        return []


# --------------------------------------------------------------------------------------------
# The server
# --------------------------------------------------------------------------------------------
class ViewServer:
    """Static files + ``/ws`` on 127.0.0.1:``port``; pushes the source's frames at ``rate_hz``."""

    def __init__(
        self,
        source: LiveSource | ReplaySource,
        port: int = 8080,
        rate_hz: float = MAX_RATE_HZ,
        static_dir: Path = STATIC,
    ) -> None:
        if not 0.0 < rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"--rate must be in (0, {MAX_RATE_HZ:g}] Hz, got {rate_hz:g}")
        self.source = source
        self.port = port
        self.rate_hz = rate_hz
        self.static_dir = static_dir.resolve()
        self.clients: set[Any] = set()
        self.frames_sent = 0
        self.frames_skipped = 0
        self.ticks = 0
        self._files: dict[str, tuple[bytes, str]] = {}
        self.url = ""

    # -- HTTP --------------------------------------------------------------------------------------
    def _static(self, path: str) -> tuple[bytes, str] | None:
        path = path.split("?", 1)[0]
        if path in ("", "/"):
            path = "/index.html"
        cached = self._files.get(path)
        if cached is not None:
            return cached
        target = (self.static_dir / path.lstrip("/")).resolve()
        if not target.is_relative_to(self.static_dir) or not target.is_file():
            return None
        kind = (
            CONTENT_TYPES.get(target.suffix)
            or mimetypes.guess_type(target.name)[0]
            or "application/octet-stream"
        )
        entry = (target.read_bytes(), kind)
        self._files[path] = entry  # a handful of small files: read once
        return entry

    def process_request(self, connection: Any, request: Any) -> Any:
        """Serve the page's static files over HTTP (404 for anything else) and let ``/ws`` go on to the
        WebSocket handshake."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        if request.path.split("?", 1)[0] == "/ws":
            return None  # the WebSocket handshake goes on
        found = self._static(request.path)
        if found is None:
            return connection.respond(404, f"not found: {request.path}\n")
        body, kind = found
        headers = Headers(
            [
                ("Content-Type", kind),
                ("Content-Length", str(len(body))),
                ("Cache-Control", "no-cache"),
                ("Connection", "close"),
            ]
        )
        return Response(200, "OK", headers, body)

    # -- WebSocket ---------------------------------------------------------------------------------
    async def handler(self, ws: Any) -> None:
        """One page's WebSocket: send the hello, then keep it among the broadcast clients until it closes."""
        import websockets

        try:
            if isinstance(self.source, ReplaySource):
                for text in self.source.hello_texts():
                    await ws.send(text)
            else:
                for msg in self.source.hello():
                    await ws.send(json.dumps(msg, separators=(",", ":")))
            self.clients.add(ws)
            async for _ in ws:  # the page sends nothing we need; keep reading until it closes
                pass
        except websockets.ConnectionClosed:
            pass
        finally:
            self.clients.discard(ws)

    async def _send(self, ws: Any, text: str) -> None:
        import websockets

        try:
            await ws.send(text)
        except websockets.ConnectionClosed:
            self.clients.discard(ws)

    def broadcast(self, message: dict[str, Any]) -> None:
        """Send ``message`` as JSON to every page, skipping a page whose send buffer is behind (counted)."""
        text = json.dumps(message, separators=(",", ":"))
        for ws in list(self.clients):
            transport = getattr(ws, "transport", None)
            if transport is not None and transport.get_write_buffer_size() > CLIENT_BUFFER_LIMIT:
                self.frames_skipped += 1  # this page is behind: it gets the next frame instead
                continue
            self.frames_sent += 1
            asyncio.ensure_future(self._send(ws, text))

    # -- the loop ----------------------------------------------------------------------------------
    async def run(self, stop: asyncio.Event, ready: Callable[[str], None] | None = None) -> None:
        """Open the source, serve on 127.0.0.1:``port`` and broadcast the source's ticks until ``stop``
        is set; ``ready`` receives the page's URL once listening."""
        from websockets.asyncio.server import serve

        self.source.open()
        try:
            async with serve(
                self.handler,
                wire.LOOPBACK,
                self.port,
                process_request=self.process_request,
                max_size=1 << 16,
                compression=None,
                ping_interval=20,
                ping_timeout=20,
            ) as server:
                port = next(iter(server.sockets)).getsockname()[1]
                self.url = f"http://{wire.LOOPBACK}:{port}/"
                if ready is not None:
                    ready(self.url)
                period = 1.0 / self.rate_hz
                loop = asyncio.get_running_loop()
                next_tick = loop.time()
                while not stop.is_set():
                    wall = time.monotonic()
                    self.ticks += 1
                    for message in self.source.tick(wall):
                        self.broadcast(message)
                    priority = getattr(self.source, "priority", None)
                    yielding = priority is not None and priority.idle
                    # A batch run far faster than real time: 10 pushes a second are plenty.
                    next_tick += max(period, 1.0 / YIELD_RATE_HZ) if yielding else period
                    now = loop.time()
                    if next_tick < now:  # fell behind (machine busy): no burst of catch-up ticks
                        next_tick = now + period
                    try:
                        await asyncio.wait_for(stop.wait(), timeout=next_tick - now)
                    except TimeoutError:
                        pass
        finally:
            self.source.close()


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------
def build_parser(prog: str = "quadsitl view") -> argparse.ArgumentParser:
    """The ``quadsitl view`` command line (logs to replay, or instances to watch; port, rate, labels)."""
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Live 3-D view and time plots of running vehicles in the browser, or replays of "
        "recorded logs (served on 127.0.0.1).",
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "logs",
        nargs="*",
        metavar="LOG",
        help="replay these logs (session .parquet / .parts, in-process runs, or flight logs .ulg) instead",
    )
    parser.add_argument(
        "--instance",
        type=int,
        nargs="+",
        default=None,
        metavar="N",
        help="vehicle instance(s) to watch (default 0)",
    )
    parser.add_argument(
        "--count",
        type=int,
        default=None,
        metavar="K",
        help="watch K vehicles: instances N..N+K-1 from the (first) --instance",
    )
    parser.add_argument(
        "--port",
        type=int,
        default=8080,
        help="HTTP/WebSocket port on 127.0.0.1 (default 8080; 0 = any free port)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=MAX_RATE_HZ,
        help=f"pushes per wall second to the page (default and maximum {MAX_RATE_HZ:g})",
    )
    parser.add_argument("--sitl-config", default=None, help="alternative sitl.toml (ports, zenoh router)")
    parser.add_argument("--labels", nargs="+", default=[], help="replay: one label per log")
    parser.add_argument(
        "--align",
        choices=("sim", "start", "armed"),
        default="sim",
        help="replay: time zero of each log: simulation time as recorded (default), its "
        "first sample, or the instant it armed (overlays runs started at different times)",
    )
    parser.add_argument(
        "--no-nice",
        action="store_true",
        help="keep the normal CPU priority (default: nice 10, and SCHED_IDLE while the vehicles run "
        "more than 4x faster than real time)",
    )
    return parser


def instances_from(args: argparse.Namespace, parser: argparse.ArgumentParser) -> list[int]:
    """The vehicle instances to watch from ``--instance`` / ``--count`` (default vehicle 0); a parser
    error outside [0, 99], for duplicates or a non-positive count."""
    instances = list(args.instance) if args.instance else [0]
    if args.count is not None:
        if args.count < 1:
            parser.error(f"--count must be >= 1, got {args.count}")
        if args.instance and len(args.instance) > 1:
            parser.error("--count goes with one --instance N (the first of the K vehicles)")
        instances = [instances[0] + k for k in range(args.count)]
    for n in instances:
        if not wire.INSTANCE_MIN <= n <= wire.INSTANCE_MAX:
            parser.error(f"--instance must be in [{wire.INSTANCE_MIN}, {wire.INSTANCE_MAX}], got {n}")
    if len(set(instances)) != len(instances):
        parser.error(f"--instance: each vehicle once, got {instances}")
    return instances


def main(argv: list[str] | None = None, prog: str = "quadsitl view") -> int:
    """``quadsitl view``: serve live vehicles or replays until Ctrl-C; the exit status."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    if args.logs and (args.instance or args.count):
        parser.error("give either logs to replay or --instance/--count to watch, not both")
    if not 0 <= args.port <= 65535:
        parser.error(f"--port must be in [0, 65535], got {args.port}")
    problem = vendor_build.vendor_problem()
    if problem is not None:
        print(
            f"quadsitl view: the page's JavaScript libraries are not built ({problem}); run "
            "`python -m gcs_scripts.view.build` (make test / make demo do it)",
            file=sys.stderr,
        )
        return 2
    try:
        if args.logs:
            source: LiveSource | ReplaySource = ReplaySource(args.logs, args.labels, args.align)
        else:
            source = LiveSource(instances_from(args, parser), args.sitl_config, adaptive=not args.no_nice)
        server = ViewServer(source, args.port, args.rate)
    except (ValueError, FileNotFoundError) as exc:
        print(f"quadsitl view: {exc}", file=sys.stderr)
        return 2
    if not args.no_nice:
        from .live import nice_self

        nice_self()
    return asyncio.run(_serve(server, args))


async def _serve(server: ViewServer, args: argparse.Namespace) -> int:
    from quadcommon.bus import BusError

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)

    def ready(url: str) -> None:
        source = server.source
        if isinstance(source, LiveSource):
            what = ", ".join(
                f"vehicle {v.instance} (MAVLink from udp {v.mavlink_port})" for v in source.vehicles
            )
        else:
            what = f"replay of {len(source.loaded)} log(s)"
        print(f"quadsitl view: {what}", flush=True)
        print(f"quadsitl view: open {url}", flush=True)

    try:
        await server.run(stop, ready)
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            print(
                f"quadsitl view: TCP port {args.port} (127.0.0.1) is already in use: choose another "
                "--port (0 = any free port)",
                file=sys.stderr,
            )
            return 2
        raise
    except BusError as exc:
        print(f"quadsitl view: {exc}", file=sys.stderr)
        return 2
    print(
        f"quadsitl view: stopped ({server.ticks} ticks, {server.frames_sent} frames sent, "
        f"{server.frames_skipped} skipped)",
        flush=True,
    )
    return 0
