"""Record a SITL session: the MAVLink .tlog and a Parquet table joining zenoh truth with telemetry.

Listens like a ground station (default ``udpin:127.0.0.1:14550``, QGroundControl's port, where
every instance's GCS link sends; the recorder keeps vehicle N's system id 1 + N) and
subscribes to the vehicle's zenoh bus (``quadsitl/N/truth`` from the simulator,
``quadsitl/N/controller`` from the autopilot and, when it flies on its EKF,
``quadsitl/N/estimator``; their ``info`` queryables give the metadata).
Writes, for ``--out DIR/NAME`` (default ``runs/<timestamp>``):

* ``NAME.tlog``: every MAVLink message from the vehicle (system id 1 + N) received on the link
  (other vehicles on the same port left out), stamped with the wall clock
  (readable by pymavlink's mavutil, ``mavlogdump.py``, MAVExplorer); flushed every second;
* ``NAME.parts/part-000001.parquet``, ...: every second of wall time, the rows joined so far,
  each part a complete Parquet file; on a clean exit they are merged into ``NAME.parquet`` and
  deleted. If the recorder dies, the parts stay readable (``quadsitl analyze NAME.parts``).

The table has one row per control step: ``time_s`` (simulation time), the truth and controller
columns (paper frames: x north, y left, z up; joined exactly on time_s), the estimator columns
(``x_est_m``..., only in a session flown with ``--estimator ekf``; joined the same way) and ``mav_*`` columns
(MAVLink as received: NED/FRD; joined as of time_s: the latest sample at or before each row).
The schema metadata (``quadsitl.session``, JSON) holds instance, scenario, controller, vehicle,
rates, the two info answers, the recording's start simulation time and the STATUSTEXT events.

Stops after ``--duration`` seconds of SIMULATION time, when ``--until-disarmed`` and the vehicle
has been armed then disarmed, or on SIGINT/SIGTERM (Ctrl-C). Exit 0 on a clean stop, 2 on bad
arguments or when the link cannot be opened.

Several vehicles (a fleet, ``quadsitl up --count K``): ``--instance 0-9`` (or ``0..9``,
``3,5,8``) records each of them in one process, from the one ground-station port (each vehicle's
messages by its system id) and each vehicle's zenoh keys: one recording per vehicle, named by
``--out`` with ``{instance}`` in it (default ``runs/<timestamp>-{instance}``), each stopping on its
own condition; the lines it prints start with ``[N]``.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gcs_scripts import link as mavlink_link  # noqa: E402  (sets the pymavlink dialect first)
from gcs_scripts.session_log import (  # noqa: E402
    PartWriter,
    SessionAssembler,
    merge_parts,
    part_paths,
    session_metadata,
)
from gcs_scripts.tlog import TlogWriter  # noqa: E402
from quadcommon import bus, wire  # noqa: E402
from quadcommon.bus_records import CONTROLLER_CODEC, ESTIMATOR_CODEC, TRUTH_CODEC  # noqa: E402
from quadcommon.cli_help import HelpFormatter  # noqa: E402
from quadcommon.config import load_sitl  # noqa: E402

mavutil = mavlink_link.mavutil

PART_INTERVAL_WALL_S = 1.0  # a crash loses at most this much
PROGRESS_WALL_S = 10.0
STOP_GRACE_WALL_S = 0.3  # after the stop condition: collect rows still in flight
INFO_RETRY_WALL_S = 1.0
MAX_DRAIN = 20000  # messages/samples per loop turn and source: keeps every source served


@dataclass(frozen=True)
class RecorderOptions:
    instance: int = 0
    out: Path = Path("runs/session")  # NAME: NAME.tlog, NAME.parquet, NAME.parts/
    url: str | None = None
    duration_s: float | None = None  # simulation seconds
    until_disarmed: bool = False
    sitl_config: str | None = None
    quiet: bool = False
    part_interval_s: float = PART_INTERVAL_WALL_S


class Recorder:
    """One recording session (see the module docstring): the ground-station MAVLink connection, the
    zenoh subscriptions, the .tlog writer and the Parquet parts; :meth:`open`, then the loop, until
    the duration is reached or :meth:`request_stop`."""

    def __init__(self, options: RecorderOptions, label: str = "") -> None:
        self.options = options
        self.label = label  # what its lines start with ("[N] " when recording several vehicles)
        self.sitl = load_sitl(options.sitl_config)
        self.ports = self.sitl.ports(options.instance)
        self.url = options.url or f"udpin:127.0.0.1:{self.ports.gcs_remote}"
        mavlink_link._check_loopback(self.url)
        out = Path(options.out)
        if out.suffix in (".parquet", ".tlog"):
            out = out.with_suffix("")
        self.base = out
        self.tlog_path = out.with_name(out.name + ".tlog")
        self.parquet_path = out.with_name(out.name + ".parquet")
        self.parts_dir = out.with_name(out.name + ".parts")
        self.assembler = SessionAssembler(wire.system_id(options.instance), wall=time.monotonic())
        n = options.instance
        self.truth_info = bus.InfoQuery(wire.zenoh_key(n, "info"), INFO_RETRY_WALL_S)
        self.autopilot_info = bus.InfoQuery(wire.zenoh_key(n, "autopilot/info"), INFO_RETRY_WALL_S)
        self.conn: Any = None
        self.session: Any = None
        self.truth_sub: Any = None
        self.controller_sub: Any = None
        self.estimator_sub: Any = None
        self.tlog: TlogWriter | None = None
        self.parts: PartWriter | None = None
        self.stop_reason = ""
        self._stop_requested = False
        self.decode_errors = 0
        self.was_armed = False
        self._owns_conn = True  # False: the MAVLink connection is shared (several vehicles): not closed here
        # The loop's clocks (wall): the next part and progress line, the stop's deadline once asked.
        self._next_part = self._next_progress = 0.0
        self._stop_at: float | None = None
        self._stop_decided = 0.0  # (wall s) when the stop condition was met
        self.done = False  # stopped, its last part written

    def log(self, text: str) -> None:
        """Print ``text`` as a ``record:`` line stamped with the latest simulation time (unless quiet)."""
        if not self.options.quiet:
            t = self.assembler.latest_time_s
            stamp = f"t={t:.2f} s " if t is not None else ""
            print(f"record: {self.label}{stamp}{text}", flush=True)

    # -- setup / teardown --------------------------------------------------------------------------
    def check_out(self) -> None:
        """FileExistsError if the recording would overwrite a .tlog, .parquet or parts directory."""
        for path in (self.tlog_path, self.parquet_path):
            if path.exists():
                raise FileExistsError(f"{path} exists already: choose another --out")
        if self.parts_dir.exists() and part_paths(self.parts_dir):
            raise FileExistsError(f"{self.parts_dir} holds parts of another recording: choose another --out")

    def open(self, conn: Any = None) -> None:
        """Open the MAVLink connection (or take ``conn``, shared with other recordings and closed
        by its owner), the zenoh session and subscriptions and the .tlog; refuses
        (FileExistsError) to overwrite an existing .tlog, .parquet or parts directory."""
        import zenoh

        self.check_out()
        if conn is None:
            conn = open_ground_link(self.url)
        else:
            self._owns_conn = False
        self.conn = conn
        self.session = bus.open_peer(self.ports.zenoh, self.sitl.zenoh_router)
        n = self.options.instance
        self.truth_sub = self.session.declare_subscriber(
            wire.zenoh_key(n, "truth"), zenoh.handlers.FifoChannel(8192)
        )
        self.controller_sub = self.session.declare_subscriber(
            wire.zenoh_key(n, "controller"), zenoh.handlers.FifoChannel(8192)
        )
        self.estimator_sub = self.session.declare_subscriber(
            wire.zenoh_key(n, "estimator"), zenoh.handlers.FifoChannel(8192)
        )
        self.tlog = TlogWriter(self.tlog_path)
        self.parts = PartWriter(self.parts_dir)

    def close(self) -> Path | None:
        """Close every source, then merge the parts (returns the merged file, if any rows)."""
        for closer in (
            lambda: self.session.close() if self.session is not None else None,
            lambda: self.conn.close() if self.conn is not None and self._owns_conn else None,
            lambda: self.tlog.close() if self.tlog is not None else None,
        ):
            try:
                closer()
            except Exception as exc:  # closing must go on: the data matters more
                print(f"record: while closing: {exc}", file=sys.stderr)
        if self.parts is None:
            return None
        if not part_paths(self.parts_dir):
            try:
                self.parts_dir.rmdir()
            except OSError:
                pass
            return None
        return merge_parts(self.parts_dir, self.parquet_path, self.metadata(final=True))

    def metadata(self, final: bool = False) -> dict[str, Any]:
        """The recording's metadata stored with the Parquet table: the info of both processes, the
        URL, row and message counts, the last simulation time and whether the recording is ``final``."""
        a = self.assembler
        extra = {
            "url": self.url,
            "tlog": self.tlog_path.name,
            "rows": a.rows_emitted,
            "truth_rows": a.truth.count,
            "controller_rows": a.controller.count,
            "estimator_rows": a.estimator.count,
            "mavlink_messages": a.mav_messages,
            "recording_end_sim_time_s": a.last_row_time_s,
            "complete": final,
            "stopped_by": self.stop_reason,
        }
        return session_metadata(
            self.options.instance,
            self.truth_info.answer,
            self.autopilot_info.answer,
            a.first_time_s,
            extra,
            a.statustext,
        )

    # -- the loop ----------------------------------------------------------------------------------
    def request_stop(self, *_args: Any) -> None:
        """Ask the loop to stop at its next turn (a signal handler)."""
        self._stop_requested = True

    def _drain_zenoh(self, sub: Any, codec: Any, add: Any, wall: float) -> int:
        import zenoh

        n = 0
        for _ in range(MAX_DRAIN):
            try:
                sample = sub.try_recv()
            except zenoh.ZError:
                return n
            if sample is None:
                return n
            n += 1
            try:
                rows = codec.decode(sample.payload.to_bytes())
            except ValueError:
                self.decode_errors += 1
                continue
            add(rows, wall)
        return n

    def take_mavlink(self, msg: Any, wall: float, now_unix: float) -> None:
        """One message from this vehicle (its system id) into the .tlog and the table."""
        self.tlog.write(msg.get_msgbuf(), now_unix)
        self.assembler.add_mavlink(msg, wall)
        if msg.get_type() == "STATUSTEXT":
            self.log(f"vehicle: {self.assembler.statustext[-1][2]}")

    def _write_part(self, wall: float, final: bool = False) -> None:
        # Stopped by its own condition, the vehicle still streams: the last part ends where every
        # stream still flowing at the stop has arrived. Stopped by a signal, it keeps everything.
        flowing_since = self._stop_decided if final and self.stop_reason != "signal" else None
        table = self.assembler.take(wall, final=final, flowing_since=flowing_since)
        if table is not None and table.num_rows:
            self.parts.write(table, self.metadata())
        self.tlog.flush()

    def _should_stop(self) -> str:
        if self._stop_requested:
            return "signal"
        a = self.assembler
        duration = self.options.duration_s
        if duration is not None and a.first_key is not None and a.latest_time_s - a.first_time_s >= duration:
            return f"duration {duration:g} s"
        if self.options.until_disarmed:
            if a.armed:
                self.was_armed = True
            elif self.was_armed and a.armed is False:
                return "disarmed"
        return ""

    def run(self, max_wall_s: float | None = None) -> int:
        """Record until a stop condition (or ``max_wall_s`` of wall time, for tests)."""
        record([self], max_wall_s)
        return 0

    def start(self, wall: float) -> None:
        """The loop begins (:func:`record`): the first part and progress line due from ``wall``."""
        self.log(
            f"recording instance {self.options.instance}: MAVLink {self.url}, zenoh "
            f"{bus.hub_endpoint(self.ports.zenoh)} -> {self.tlog_path}, {self.parquet_path} "
            f"(parts in {self.parts_dir}/)"
        )
        self._next_part = wall + self.options.part_interval_s
        self._next_progress = wall + PROGRESS_WALL_S

    def drain_bus(self, wall: float) -> int:
        """The zenoh rows waiting, into the table; how many samples."""
        a = self.assembler
        n = self._drain_zenoh(self.truth_sub, TRUTH_CODEC, a.add_truth, wall)
        n += self._drain_zenoh(self.controller_sub, CONTROLLER_CODEC, a.add_controller, wall)
        return n + self._drain_zenoh(self.estimator_sub, ESTIMATOR_CODEC, a.add_estimator, wall)

    def after_drain(self, wall: float, wall_limit_s: float | None = None) -> None:
        """One turn's rest: the info answers, a part when due, progress, the stop condition
        (``wall_limit_s``: the loop's ``max_wall_s``, once it has passed); the last part once
        stopped."""
        for name, request in (("simulator", self.truth_info), ("autopilot", self.autopilot_info)):
            if request.poll(self.session, wall):
                self.log(f"{name} info: {json.dumps(request.answer)}")
        if wall >= self._next_part:
            self._write_part(wall)
            self._next_part = wall + self.options.part_interval_s
        if wall >= self._next_progress:
            self._next_progress = wall + PROGRESS_WALL_S
            a = self.assembler
            if a.mav_messages == 0 and a.first_time_s is None:  # (the vehicle may not be up yet)
                n = self.options.instance
                self.log(f"nothing heard from instance {n} yet (system id {wire.system_id(n)} on {self.url}, "
                         f"zenoh {wire.zenoh_key(n, '*')}): waiting for it; Ctrl-C stops")  # fmt: skip
            else:
                self.log(f"{a.rows_emitted} rows, {a.mav_messages} MAVLink messages, {self.parts.index} "
                         "parts")  # fmt: skip
        if self._stop_at is None:
            reason = self._should_stop()
            if not reason and wall_limit_s is not None:
                reason = f"wall limit {wall_limit_s:g} s"
            if reason:
                self.stop_reason = reason
                self._stop_decided = wall
                # Rows of the last instants may still be in flight on the other streams.
                self._stop_at = wall + (0.0 if reason == "signal" else STOP_GRACE_WALL_S)
        if self._stop_at is not None and wall >= self._stop_at:
            self._write_part(time.monotonic(), final=True)
            self.done = True


def open_ground_link(url: str) -> Any:
    """The ground station's MAVLink connection the recordings read (pymavlink)."""
    return mavutil.mavlink_connection(
        url, source_system=mavlink_link.GCS_SYSTEM_ID, source_component=191, dialect="common"
    )


def record(recorders: list[Recorder], max_wall_s: float | None = None) -> None:
    """Record every vehicle of ``recorders`` (opened, sharing one MAVLink connection) until each
    has stopped: every turn the zenoh rows of each, the MAVLink messages waiting (each to the
    recording of its system id; other vehicles' left out), then each one's parts and stop."""
    start_wall = time.monotonic()
    conn = recorders[0].conn
    for recorder in recorders:
        recorder.start(start_wall)
    by_system = {recorder.assembler.system_id: recorder for recorder in recorders}
    while True:
        wall = time.monotonic()
        active = [recorder for recorder in recorders if not recorder.done]
        if not active:
            return
        n = sum(recorder.drain_bus(wall) for recorder in active)
        n += _drain_mavlink(conn, by_system, wall)
        passed = max_wall_s if max_wall_s is not None and wall - start_wall > max_wall_s else None
        for recorder in active:
            recorder.after_drain(wall, passed)
        if n == 0:
            time.sleep(0.001)


def _drain_mavlink(conn: Any, by_system: dict[int, Recorder], wall: float) -> int:
    """The messages waiting on ``conn``, each to the recording of its system id (a vehicle not
    recorded: left out, every instance's GCS link sends to the one port 14550); how many."""
    n = 0
    now_unix = time.time()
    for _ in range(MAX_DRAIN):
        msg = conn.recv_msg()
        if msg is None:
            break
        if msg.get_type() == "BAD_DATA":
            continue
        n += 1
        recorder = by_system.get(msg.get_srcSystem())
        if recorder is not None and not recorder.done:
            recorder.take_mavlink(msg, wall, now_unix)
    return n


def default_out() -> Path:
    """``runs/<YYYYmmdd-HHMMSS>`` (local time): the default output base name."""
    return Path("runs") / time.strftime("%Y%m%d-%H%M%S")


def build_parser(prog: str = "record.py") -> argparse.ArgumentParser:
    """The ``record.py`` command line (instance, output, URL, duration, router)."""
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__, formatter_class=HelpFormatter
    )
    parser.add_argument("--instance", default="0",
                        help="vehicle instance N (default 0), or several: 0-9, 0..9, 3,5,8 (one recording "
                        "each, from the one ground-station port)")  # fmt: skip
    parser.add_argument(
        "--out", default=None, help="output DIR/NAME without suffix (default runs/<timestamp>; with "
        "several instances {instance} in it, default runs/<timestamp>-{instance})"
    )
    parser.add_argument(
        "--url", default=None, help="MAVLink URL (default udpin:127.0.0.1:14550, kept: system id 1+N)"
    )
    parser.add_argument(
        "--duration", type=float, default=None, help="stop after S seconds of simulation time"
    )
    parser.add_argument(
        "--until-disarmed", action="store_true", help="stop once the vehicle has been armed and then disarmed"
    )
    parser.add_argument("--sitl-config", default=None, help="alternative sitl.toml (ports, zenoh router)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    return parser


def main(argv: list[str] | None = None, prog: str = "record.py") -> int:
    """Record until ``--duration`` s of simulation time or Ctrl-C; the exit status. Refuses an instance
    outside [0, 249] and a non-positive duration."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    try:
        instances = wire.parse_instances(args.instance)
    except ValueError as exc:
        parser.error(str(exc))
    if args.duration is not None and not (args.duration > 0.0 and math.isfinite(args.duration)):
        parser.error(f"--duration must be > 0 s, got {args.duration}")
    several = len(instances) > 1
    out = str(args.out) if args.out is not None else str(default_out()) + ("-{instance}" if several else "")
    if several and "{instance}" not in out:
        parser.error(f"--out {out}: with several instances it must contain {{instance}} (one recording "
                     "per vehicle), e.g. runs/fleet-{instance}")  # fmt: skip
    recorders = []
    for n in instances:
        options = RecorderOptions(
            instance=n,
            out=Path(out.replace("{instance}", str(n))),
            url=args.url,
            duration_s=args.duration,
            until_disarmed=args.until_disarmed,
            sitl_config=args.sitl_config,
            quiet=args.quiet,
        )
        try:
            recorders.append(Recorder(options, label=f"[{n}] " if several else ""))
        except ValueError as exc:
            parser.error(str(exc))

    def stop_all(*_args: Any) -> None:
        for recorder in recorders:
            recorder.request_stop()

    signal.signal(signal.SIGINT, stop_all)
    signal.signal(signal.SIGTERM, stop_all)
    opened: list[Recorder] = []
    try:
        for recorder in recorders:
            recorder.check_out()  # (every name before any file is written)
        for recorder in recorders:
            recorder.open(opened[0].conn if opened else None)
            opened.append(recorder)
    except (FileExistsError, OSError, bus.BusError) as exc:
        print(f"record: {exc}", file=sys.stderr)
        for recorder in opened:
            recorder.close()
        return 2
    merged: list[Path | None] = []
    try:
        record(recorders)
    finally:
        merged = [recorder.close() for recorder in recorders]
    for recorder, path in zip(recorders, merged, strict=True):
        a = recorder.assembler
        span = ""
        if a.first_time_s is not None:
            span = f" covering t={a.first_time_s:.3f}..{a.latest_time_s:.3f} s"
        print(
            f"record: {recorder.label}stopped ({recorder.stop_reason or 'error'}): {a.rows_emitted} rows"
            f"{span}, {recorder.tlog.records if recorder.tlog else 0} MAVLink messages -> "
            f"{path or '(no rows)'}, {recorder.tlog_path}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
