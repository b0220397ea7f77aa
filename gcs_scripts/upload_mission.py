"""Upload a mission to the vehicle over MAVLink (the mission protocol, as QGC/MAVSDK do it), check
it by downloading it again, and optionally fly it.

Sources (one of):

* ``FILE.waypoints`` / ``.txt``: QGroundControl's plain-text ``QGC WPL 110`` format (one item a
  line: seq, current, frame, command, p1..p4, x/lat, y/lon, z/alt, autocontinue; tab separated).
  PX4 semantics: every line is an item, including line 0 (ArduPilot tools put home there: drop it
  with ``--skip-first``). Global frames carry degrees; MAV_FRAME_LOCAL_NED metres.
* ``FILE.toml`` / ``.json``: a simple item list in the local frame, with an explicit frame key::

      frame = "paper"          # "paper": x north, y left, z up; yaw counter-clockwise from x
                               # "ned":   x north, y east, z down; yaw clockwise from north
      [[items]]                # type: takeoff, waypoint, loiter, delay, speed, land, rtl
      type = "takeoff"
      altitude_m = 2.5         # above home
      [[items]]
      type = "waypoint"
      position = [2.0, 1.0, 2.5]   # m, in the file's frame, from the configured home
      hold_s = 1.0                 # optional; also acceptance_radius_m, yaw_deg
      [[items]]
      type = "speed"
      speed_m_s = 0.5
      [[items]]
      type = "loiter"              # position + time_s
      [[items]]
      type = "land"                # position optional: land where the vehicle is

  Positions become MAV_FRAME_LOCAL_NED items (x, y in units of 0.1 mm on the wire).
* ``--curve circle|helix``: the paper's trajectory of that scenario (``--scenario`` to pick
  another), sampled every 1/``--rate`` s for ``--duration`` s into TIMED items
  (MAV_CMD_WAYPOINT_USER_1: param1 = time after the mission start, s = ``--start-time`` + t;
  x, y, z in MAV_FRAME_LOCAL_NED; param4 = yaw, deg NED), after a NAV_TAKEOFF and before a
  NAV_LAND (``--end``).

Other actions: ``--download`` (print the vehicle's mission; ``--save FILE`` writes it as QGC WPL),
``--clear``. With ``--fly`` the script then waits until the vehicle is ready to arm (SYS_STATUS's
pre-arm bit and on the ground; the reason is printed, and after 30 s of simulation time the script
fails with it), arms, switches to AUTO.MISSION and reports every
MISSION_ITEM_REACHED until the mission is complete (and, if it ends with a landing, disarmed).

Exit status: 0 success; 1 the vehicle refused (the MAV_MISSION_RESULT is printed) or a timeout;
2 bad arguments or file; 3 no vehicle.

(One script, as the other flying scripts: the file formats, the client side of
the mission protocol and the command line a user reads together in one place.)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import tomllib
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gcs_scripts import link as mavlink_link  # noqa: E402  (sets MAVLINK20 before pymavlink)
from gcs_scripts.link import Link, LinkError, LinkTimeout  # noqa: E402
from quadcommon import frames  # noqa: E402
from quadcommon.cli_help import HelpFormatter  # noqa: E402

mavutil = mavlink_link.mavutil
m = mavutil.mavlink
say = mavlink_link.report

CMD_TIMED = 31000  # MAV_CMD_WAYPOINT_USER_1: the autopilot's timed trajectory item
LOCAL_SCALE = 1e4  # MISSION_ITEM_INT x, y in local frames: m * 1e4
GLOBAL_SCALE = 1e7  # degrees * 1e7
GLOBAL_FRAMES = {
    m.MAV_FRAME_GLOBAL,
    m.MAV_FRAME_GLOBAL_INT,
    m.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    m.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    m.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
}
STEP_TIMEOUT_S = 1.5  # mission service default timeout before a resend (wall clock)
ITEM_TIMEOUT_S = 0.5
RETRIES = 5
MISSION_MESSAGES = {
    "MISSION_REQUEST_INT",
    "MISSION_REQUEST",
    "MISSION_ACK",
    "MISSION_COUNT",
    "MISSION_ITEM_INT",
    "MISSION_CURRENT",
    "MISSION_ITEM_REACHED",
}
RESULT_NAMES = {e: v.name for e, v in m.enums["MAV_MISSION_RESULT"].items()}


class MissionFileError(ValueError):
    pass


class Item(NamedTuple):
    """One MISSION_ITEM_INT's content (x, y already scaled to int32 as on the wire)."""

    frame: int
    command: int
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = math.nan
    x: int = 0
    y: int = 0
    z: float = 0.0
    autocontinue: int = 1

    def message(self, target: tuple[int, int], seq: int):
        """The item as MISSION_ITEM_INT number ``seq`` to ``target`` (system, component); item 0 is
        marked current."""
        return m.MAVLink_mission_item_int_message(
            target[0], target[1], seq, self.frame, self.command, int(seq == 0), self.autocontinue,
            self.param1, self.param2, self.param3, self.param4, self.x, self.y, self.z,
            m.MAV_MISSION_TYPE_MISSION,
        )  # fmt: skip


def same_item(a: Item, b: Item) -> bool:
    """Bit-for-bit equal as float32 on the wire (NaN equals NaN)."""
    for u, v in zip(a, b, strict=True):
        if isinstance(u, float) and isinstance(v, float) and math.isnan(u) and math.isnan(v):
            continue
        if u != v:
            return False
    return True


def item_from_message(msg) -> Item:
    """The :class:`Item` a downloaded MISSION_ITEM_INT carries."""
    return Item(msg.frame, msg.command, msg.param1, msg.param2, msg.param3, msg.param4,
                msg.x, msg.y, msg.z, msg.autocontinue)  # fmt: skip


def _f32(value: float) -> float:
    """``value`` as the float32 the wire carries (so a download compares equal)."""
    import struct

    return struct.unpack("<f", struct.pack("<f", value))[0]


def make_item(frame: int, command: int, p: Sequence[float] = (0.0, 0.0, 0.0, math.nan),
              x: int = 0, y: int = 0, z: float = 0.0, autocontinue: int = 1) -> Item:  # fmt: skip
    """An :class:`Item` with its floats rounded to float32 as the wire carries them (so a download
    compares equal); ``x``, ``y``: latitude, longitude in degE7 (or local units as ``frame`` says)."""
    p1, p2, p3, p4 = (_f32(v) for v in p)
    return Item(frame, command, p1, p2, p3, p4, int(x), int(y), _f32(z), autocontinue)


# -- sources ------------------------------------------------------------------------------------------
def read_wpl(text: str, skip_first: bool = False) -> list[Item]:
    """QGC WPL 110 plain text -> items."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines or not lines[0].startswith("QGC WPL 110"):
        raise MissionFileError("not a QGC WPL 110 file (the first line must be 'QGC WPL 110')")
    items = []
    for number, line in enumerate(lines[1:], start=2):
        fields = line.split()
        if len(fields) != 12:
            raise MissionFileError(f"line {number}: expected 12 fields, got {len(fields)}")
        try:
            frame, command = int(fields[2]), int(fields[3])
            p = [float(v) for v in fields[4:8]]
            x, y, z = (float(v) for v in fields[8:11])
            autocontinue = int(float(fields[11]))
        except ValueError as exc:
            raise MissionFileError(f"line {number}: {exc}") from None
        scale = (
            GLOBAL_SCALE if frame in GLOBAL_FRAMES else LOCAL_SCALE if frame == m.MAV_FRAME_LOCAL_NED else 1
        )
        items.append(make_item(frame, command, p, round(x * scale), round(y * scale), z, autocontinue))
    return items[1:] if skip_first else items


def write_wpl(items: Sequence[Item]) -> str:
    """Items -> QGC WPL 110 text (the inverse of :func:`read_wpl`)."""
    out = ["QGC WPL 110"]
    for seq, it in enumerate(items):
        scale = (
            GLOBAL_SCALE
            if it.frame in GLOBAL_FRAMES
            else LOCAL_SCALE
            if it.frame == m.MAV_FRAME_LOCAL_NED
            else 1
        )
        fields = [seq, int(seq == 0), it.frame, it.command, it.param1, it.param2, it.param3, it.param4,
                  it.x / scale, it.y / scale, it.z, it.autocontinue]  # fmt: skip
        out.append("\t".join(repr(v) if isinstance(v, float) else str(v) for v in fields))
    return "\n".join(out) + "\n"


def _vector(value: Any, where: str) -> tuple[float, float, float]:
    if not (
        isinstance(value, list | tuple) and len(value) == 3 and all(isinstance(v, int | float) for v in value)
    ):
        raise MissionFileError(f"{where}: position must be [x, y, z] in metres, got {value!r}")
    return (float(value[0]), float(value[1]), float(value[2]))


def items_from_list(spec: dict) -> list[Item]:
    """The TOML/JSON item list (see the module docstring) -> MAV_FRAME_LOCAL_NED items."""
    frame_name = spec.get("frame")
    if frame_name not in ("paper", "ned"):
        raise MissionFileError(f'frame must be "paper" or "ned" (say which), got {frame_name!r}')
    entries = spec.get("items")
    if not isinstance(entries, list) or not entries:
        raise MissionFileError("no [[items]] in the file")
    paper = frame_name == "paper"

    def ned(position) -> tuple[float, float, float]:
        return frames.vector_to_ned(position) if paper else position

    def yaw_param(entry: dict) -> float:
        if "yaw_deg" not in entry:
            return math.nan
        yaw = float(entry["yaw_deg"])  # paper: counter-clockwise from x; NED: clockwise from north
        return math.degrees(frames.yaw_to_ned(math.radians(yaw))) if paper else yaw

    local = m.MAV_FRAME_LOCAL_NED
    items = []
    for k, entry in enumerate(entries):
        where = f"items[{k}]"
        kind = entry.get("type")
        try:
            if kind == "takeoff":
                alt = float(entry.get("altitude_m", math.nan))
                down = frames.vector_to_ned((0.0, 0.0, alt))[2]  # an altitude is "up" in both frames
                items.append(
                    make_item(local, m.MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, yaw_param(entry)), z=down)
                )
            elif kind in ("waypoint", "loiter"):
                n, e, d = ned(_vector(entry.get("position"), where))
                if kind == "waypoint":
                    p = (float(entry.get("hold_s", 0.0)), float(entry.get("acceptance_radius_m", 0.0)), 0.0,
                         yaw_param(entry))  # fmt: skip
                    command = m.MAV_CMD_NAV_WAYPOINT
                else:
                    p = (float(entry["time_s"]), 0.0, 0.0, 0.0)
                    command = m.MAV_CMD_NAV_LOITER_TIME
                items.append(make_item(local, command, p, round(n * LOCAL_SCALE), round(e * LOCAL_SCALE), d))
            elif kind == "delay":
                items.append(
                    make_item(m.MAV_FRAME_MISSION, m.MAV_CMD_NAV_DELAY, (float(entry["time_s"]), -1, -1, -1))
                )
            elif kind == "speed":
                speed = float(entry["speed_m_s"])
                items.append(
                    make_item(m.MAV_FRAME_MISSION, m.MAV_CMD_DO_CHANGE_SPEED, (1.0, speed, -1.0, 0.0))
                )
            elif kind == "land":
                if "position" in entry:
                    n, e, _ = ned(_vector(entry["position"], where))
                    items.append(make_item(local, m.MAV_CMD_NAV_LAND, (0.0, 0.0, 0.0, yaw_param(entry)),
                                           round(n * LOCAL_SCALE), round(e * LOCAL_SCALE), 0.0))  # fmt: skip
                else:  # land where the vehicle is: a global item at lat = lon = 0 (PX4 convention)
                    items.append(make_item(m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_CMD_NAV_LAND))
            elif kind == "rtl":
                items.append(
                    make_item(m.MAV_FRAME_MISSION, m.MAV_CMD_NAV_RETURN_TO_LAUNCH, (0.0, 0.0, 0.0, 0.0))
                )
            else:
                raise MissionFileError(f"{where}: unknown type {kind!r}")
        except KeyError as exc:
            raise MissionFileError(f"{where} ({kind}): missing {exc}") from None
        except (TypeError, ValueError) as exc:
            if isinstance(exc, MissionFileError):
                raise
            raise MissionFileError(f"{where} ({kind}): {exc}") from None
    return items


def read_mission_file(path: str | Path, skip_first: bool = False) -> list[Item]:
    """The items of a mission file: QGC WPL 110 (``.waypoints``/``.txt``), ``.toml`` or ``.json``;
    ``skip_first`` drops a QGC file's home item. Raises MissionFileError naming the file and line."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise MissionFileError(f"{path}: {exc.strerror}") from None
    suffix = path.suffix.lower()
    try:
        if suffix == ".toml":
            return items_from_list(tomllib.loads(text))
        if suffix == ".json":
            return items_from_list(json.loads(text))
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise MissionFileError(f"{path}: {exc}") from None
    return read_wpl(text, skip_first)


def curve_items(
    trajectory,
    duration_s: float,
    rate_hz: float,
    start_time_s: float = 0.0,
    takeoff_altitude_m: float | None = None,
    end: str = "land",
) -> list[Item]:
    """A NAV_TAKEOFF, the trajectory sampled into TIMED items (local NED), then ``end``
    ("land", "rtl" or "hold")."""
    local = m.MAV_FRAME_LOCAL_NED
    alt = math.nan if takeoff_altitude_m is None else takeoff_altitude_m
    down = frames.vector_to_ned((0.0, 0.0, alt))[2]
    items = [make_item(local, m.MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, math.nan), z=down)]
    count = int(math.floor(duration_s * rate_hz + 1e-9)) + 1
    for k in range(count):
        t = k / rate_hz
        ref = trajectory.sample(t)
        n, e, d = frames.vector_to_ned(ref.position_m)
        yaw_deg = math.degrees(frames.yaw_to_ned(ref.yaw_rad))
        p = (start_time_s + t, 0.0, 0.0, yaw_deg)
        items.append(make_item(local, CMD_TIMED, p, round(n * LOCAL_SCALE), round(e * LOCAL_SCALE), d))
    if end == "land":
        items.append(make_item(m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_CMD_NAV_LAND))
    elif end == "rtl":
        items.append(make_item(m.MAV_FRAME_MISSION, m.MAV_CMD_NAV_RETURN_TO_LAUNCH, (0.0, 0.0, 0.0, 0.0)))
    return items


# -- the protocol, client side ------------------------------------------------------------------------
class MissionError(LinkError):
    def __init__(self, message: str, result: int | None = None) -> None:
        super().__init__(message)
        self.result = result


class MissionLink(Link):
    """A :class:`~gcs_scripts.link.Link` that also collects the mission messages."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.mission_inbox: deque = deque(maxlen=20000)
        self.reached: list[tuple[float, int]] = []  # (sim time, seq) of MISSION_ITEM_REACHED
        self.mission_current = None

    def _handle(self, msg: Any) -> None:
        super()._handle(msg)
        if msg.get_srcSystem() != self.target_system:
            return
        kind = msg.get_type()
        if kind not in MISSION_MESSAGES:
            return
        if kind == "MISSION_ITEM_REACHED":
            self.reached.append((self.now(), msg.seq))
        elif kind == "MISSION_CURRENT":
            self.mission_current = msg
        else:
            self.mission_inbox.append(msg)

    @property
    def target(self) -> tuple[int, int]:
        """The vehicle addressed: (system id, component id)."""
        return (self.target_system, self.target_component)

    def _wait(self, accept: Callable[[Any], bool], timeout_s: float):
        """The first collected mission message ``accept`` takes, within ``timeout_s`` (wall)."""
        deadline = time.monotonic() + timeout_s
        while True:
            while self.mission_inbox:
                msg = self.mission_inbox.popleft()
                if accept(msg):
                    return msg
            if time.monotonic() >= deadline:
                return None
            if self.poll() == 0:
                time.sleep(0.0005)

    def upload(self, items: Sequence[Item], timeout_s: float = 60.0) -> None:
        """MISSION_COUNT, answer each MISSION_REQUEST_INT, until MISSION_ACK; raises MissionError."""
        self.mission_inbox.clear()
        deadline = time.monotonic() + timeout_s
        count = len(items)
        self.mav.mission_count_send(*self.target, count, m.MAV_MISSION_TYPE_MISSION)
        tries = 0
        answered = False
        last_sent = -1  # the item sent last: sent again when the vehicle falls silent (its ACK lost)
        while time.monotonic() < deadline:
            msg = self._wait(
                lambda x: x.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"),
                STEP_TIMEOUT_S,
            )
            if msg is None:
                tries += 1
                if tries > RETRIES:
                    raise MissionError(f"mission upload: no answer from the vehicle ({tries} waits)")
                if answered:  # the vehicle repeats a request itself; a silence is a lost last ACK
                    self.mav.send(items[last_sent].message(self.target, last_sent))
                else:
                    self.mav.mission_count_send(*self.target, count, m.MAV_MISSION_TYPE_MISSION)
                continue
            tries = 0
            kind = msg.get_type()
            if kind == "MISSION_ACK":
                if msg.type == m.MAV_MISSION_ACCEPTED:
                    if answered or count == 0:
                        return
                    continue  # an ACK left over from an earlier operation
                raise MissionError(
                    f"mission upload refused: {RESULT_NAMES.get(msg.type, msg.type)}", msg.type
                )
            if kind == "MISSION_REQUEST":
                raise MissionError("the vehicle asked for float MISSION_ITEMs: not supported here")
            if 0 <= msg.seq < count:
                answered, last_sent = True, msg.seq
                self.mav.send(items[msg.seq].message(self.target, msg.seq))
        raise MissionError(f"mission upload: not finished within {timeout_s:g} s")

    def download(self, timeout_s: float = 60.0) -> list[Item]:
        """MISSION_REQUEST_LIST, then each item by MISSION_REQUEST_INT; ends with MISSION_ACK."""
        self.mission_inbox.clear()
        count_msg = None
        for _ in range(RETRIES):
            self.mav.mission_request_list_send(*self.target, m.MAV_MISSION_TYPE_MISSION)
            count_msg = self._wait(lambda x: x.get_type() == "MISSION_COUNT", STEP_TIMEOUT_S)
            if count_msg is not None:
                break
        if count_msg is None:
            raise MissionError("mission download: no MISSION_COUNT")
        items: list[Item] = []
        deadline = time.monotonic() + timeout_s
        for seq in range(count_msg.count):
            got = None
            for _ in range(RETRIES):
                self.mav.mission_request_int_send(*self.target, seq, m.MAV_MISSION_TYPE_MISSION)

                def item_or_ack(x, seq=seq):
                    return (
                        x.get_type() == "MISSION_ITEM_INT" and x.seq == seq
                    ) or x.get_type() == "MISSION_ACK"

                got = self._wait(item_or_ack, ITEM_TIMEOUT_S)
                if got is not None or time.monotonic() > deadline:
                    break
            if got is None:
                raise MissionError(f"mission download: no item {seq}")
            if got.get_type() == "MISSION_ACK":
                raise MissionError(
                    f"mission download ended by the vehicle: {RESULT_NAMES.get(got.type, got.type)}"
                )
            items.append(item_from_message(got))
        self.mav.mission_ack_send(*self.target, m.MAV_MISSION_ACCEPTED, m.MAV_MISSION_TYPE_MISSION)
        return items

    def clear(self) -> None:
        """Clear the vehicle's mission (MISSION_CLEAR_ALL, retried); raises MissionError when refused or
        never acknowledged (MISSION_ACK)."""
        self.mission_inbox.clear()
        for _ in range(RETRIES):
            self.mav.mission_clear_all_send(*self.target, m.MAV_MISSION_TYPE_MISSION)
            ack = self._wait(lambda x: x.get_type() == "MISSION_ACK", STEP_TIMEOUT_S)
            if ack is not None:
                if ack.type != m.MAV_MISSION_ACCEPTED:
                    raise MissionError(
                        f"mission clear refused: {RESULT_NAMES.get(ack.type, ack.type)}", ack.type
                    )
                return
        raise MissionError("mission clear: no MISSION_ACK")

    def set_current(self, seq: int, timeout_s: float = 3.0) -> None:
        """MISSION_SET_CURRENT; confirmed by a MISSION_CURRENT with that seq."""
        self.mission_current = None
        self.mav.mission_set_current_send(*self.target, seq)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.mission_current is not None and self.mission_current.seq == seq:
                return
            if self.poll() == 0:
                time.sleep(0.001)
        raise MissionError(f"set current item {seq}: no MISSION_CURRENT confirming it")


def connect(url: str | None, instance: int, timeout_s: float = 10.0) -> MissionLink:
    """Like :func:`gcs_scripts.link.connect` (loopback only), with mission messages collected."""
    base = mavlink_link.connect(url, instance, timeout_s)
    link = MissionLink(base.conn, instance)
    link.view = base.view
    return link


def verify(link: MissionLink, items: Sequence[Item]) -> list[str]:
    """Download the mission and compare it with ``items``; the differences (empty if none)."""
    got = link.download()
    problems = []
    if len(got) != len(items):
        problems.append(f"the vehicle has {len(got)} items, {len(items)} were uploaded")
    for seq, (a, b) in enumerate(zip(items, got, strict=False)):
        if not same_item(a, b):
            problems.append(f"item {seq} differs: sent {a}, got {b}")
    return problems


def fly(link: MissionLink, items: Sequence[Item], timeout_s: float) -> None:
    """Arm, AUTO.MISSION, report each MISSION_ITEM_REACHED; until the mission is complete, and
    if it ends with a landing (NAV_LAND / RETURN_TO_LAUNCH) until the vehicle has disarmed."""
    count = len(items)
    lands = bool(items) and items[-1].command in (m.MAV_CMD_NAV_LAND, m.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    link.reached.clear()
    link.arm_when_ready()  # (nothing if armed)
    link.set_mode("AUTO.MISSION")
    say(link, "mission started")
    shown = 0

    def progress(lk: MissionLink) -> bool:
        nonlocal shown
        for t, seq in lk.reached[shown:]:
            if seq < 20 or seq % 50 == 0 or seq >= count - 2:
                print(f"t={t:.2f} s reached item {seq}", flush=True)
        shown = len(lk.reached)
        if not lk.reached or lk.reached[-1][1] != count - 1:
            return False
        if lands:
            return not lk.armed
        current = lk.mission_current
        return current is not None and current.mission_state == m.MISSION_STATE_COMPLETE

    link.wait_until(progress, timeout_s, what="the mission to complete")
    say(link, f"mission complete ({len(link.reached)} items reached{', disarmed' if lands else ''})")


# -- command line -------------------------------------------------------------------------------------
def build_parser(prog: str = "upload_mission.py") -> argparse.ArgumentParser:
    """The ``upload_mission.py`` command line (a file, ``--curve``, ``--download`` or ``--clear``)."""
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__, formatter_class=HelpFormatter
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("file", nargs="?", help="mission file (.waypoints/.txt QGC WPL 110, .toml, .json)")
    source.add_argument("--curve", choices=("circle", "helix"), help="sample the paper's trajectory")
    source.add_argument("--download", action="store_true", help="print the vehicle's mission")
    source.add_argument("--clear", action="store_true", help="clear the vehicle's mission")
    parser.add_argument("--instance", type=int, default=0,
                        help="vehicle instance N (default 0); through quadsitl also a range, "
                        "0-9 or 3,5,8: the script once per vehicle")
    parser.add_argument(
        "--url",
        default=None,
        help="MAVLink URL (default udpin:127.0.0.1:14540+N; from N=10 udpout:127.0.0.1:14580+N)",
    )
    parser.add_argument("--scenario", default=None, help="scenario for --curve (default: the curve's name)")
    parser.add_argument(
        "--duration", type=float, default=None, help="curve duration, s (default: scenario's)"
    )
    parser.add_argument("--rate", type=float, default=10.0, help="curve samples per second (default 10)")
    parser.add_argument(
        "--start-time", type=float, default=0.0, help="time of the first sample, s after start"
    )
    parser.add_argument("--takeoff-alt", type=float, default=None, help="takeoff altitude above home, m")
    parser.add_argument("--end", choices=("land", "rtl", "hold"), default="land", help="after the curve")
    parser.add_argument("--skip-first", action="store_true", help="drop line 0 of a WPL file (home)")
    parser.add_argument("--save", default=None, help="with --download: write the mission as QGC WPL 110")
    parser.add_argument("--no-verify", action="store_true", help="do not download the mission to check it")
    parser.add_argument("--fly", action="store_true", help="arm, fly the mission in AUTO.MISSION, wait")
    parser.add_argument("--timeout", type=float, default=600.0, help="sim seconds allowed for --fly")
    return parser


def build_items(args: argparse.Namespace) -> list[Item]:
    """The items to upload: the sampled paper curve (``--curve``) or the mission file's."""
    if args.curve:
        from quadcommon.config import load_scenario
        from quadcommon.trajectories import trajectory_from_spec

        scenario = load_scenario(args.scenario or args.curve)
        duration = scenario.duration_s if args.duration is None else args.duration
        if not (duration > 0 and args.rate > 0):
            raise MissionFileError("--duration and --rate must be positive")
        trajectory = trajectory_from_spec(scenario.trajectory)
        return curve_items(trajectory, duration, args.rate, args.start_time, args.takeoff_alt, args.end)
    return read_mission_file(args.file, args.skip_first)


def main(argv: list[str] | None = None, prog: str = "upload_mission.py") -> int:
    """Upload (and verify, and optionally fly), download or clear the mission of vehicle N; 0 on
    success, 1 when the vehicle refuses or the download differs, 2 for a bad file or URL, 3 when no
    vehicle answers."""
    args = build_parser(prog).parse_args(argv)
    items: list[Item] = []
    if not (args.download or args.clear):
        try:
            items = build_items(args)
        except (MissionFileError, ValueError) as exc:
            print(f"upload_mission: {exc}", file=sys.stderr)
            return 2
    try:
        link = connect(args.url, args.instance)
    except LinkTimeout as exc:
        print(f"upload_mission: {exc}", file=sys.stderr)
        return 3
    except ValueError as exc:
        print(f"upload_mission: {exc}", file=sys.stderr)
        return 2
    try:
        if args.clear:
            link.clear()
            say(link, "mission cleared")
            return 0
        if args.download:
            got = link.download()
            text = write_wpl(got)
            if args.save:
                Path(args.save).write_text(text)
                say(link, f"{len(got)} items saved to {args.save}")
            else:
                print(text, end="")
            return 0
        start = time.monotonic()
        link.upload(items)
        say(link, f"uploaded {len(items)} items in {time.monotonic() - start:.2f} s (wall)")
        if not args.no_verify:
            problems = verify(link, items)
            if problems:
                for p in problems[:10]:
                    print(f"upload_mission: {p}", file=sys.stderr)
                return 1
            say(link, "download matches the upload")
        if args.fly:
            fly(link, items, args.timeout)
        return 0
    except LinkError as exc:
        print(f"upload_mission: {exc}", file=sys.stderr)
        return 1
    finally:
        link.close()


if __name__ == "__main__":
    sys.exit(main())
