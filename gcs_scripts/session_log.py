"""The recorder's table: zenoh truth + controller internals joined with MAVLink telemetry.

No sockets, no zenoh, no clocks here (the recorder process owns those; this module is tested
with synthetic data). One row per control step:

* ``time_s``: simulation time (s), the row key. Truth and controller rows are joined EXACTLY on
  it, on the integer microsecond grid (``round(time_s * 1e6)``) because the two processes compute
  the same instant in floating point differently; a row one side lacks has NaN on that side.
* truth columns (:data:`~quadcommon.bus_records.TRUTH_FIELDS`) and controller columns
  (:data:`~quadcommon.bus_records.CONTROLLER_FIELDS`): the paper's frames (world x north,
  y left, z up; body front-left-up), SI units, names as on the bus.
* estimator columns (:data:`~quadcommon.bus_records.ESTIMATOR_FIELDS`, ``x_est_m``...), only
  in a session whose autopilot flew on its EKF (``quadsitl/N/estimator``): joined exactly on
  ``time_s`` like the controller's; a session flown on truth has no such columns at all (the
  table then is exactly what older readers know).
* ``mav_*`` columns: MAVLink telemetry AS RECEIVED (NED world, FRD body; SI units after the
  edge scaling, e.g. mm -> m, 1e7 deg -> deg), joined AS OF the row time: the latest sample
  stamped at or before the row (``time_boot_ms``/``time_usec`` = simulation time). Messages
  without a time stamp (HEARTBEAT, EXTENDED_SYS_STATE, SYS_STATUS) take the stamp of the next
  time-stamped message from the vehicle (the autopilot sends them in the same control step).
  Each message group also has ``mav_<group>_time_s``: the stamp of the sample used (staleness).

Rows are handed out incrementally (:meth:`SessionAssembler.take`) up to a watermark: the
latest time every live stream has reached, so the exact join never splits a row across two
parts. Part files (``NAME.parts/part-000001.parquet``...) are each a complete Parquet file with
the same schema; :func:`merge_parts` streams them into ``NAME.parquet``.

(One module: the join, the part files and their merge are one on-disk format and
change together.)
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from quadcommon.bus_records import CONTROLLER_FIELDS, ESTIMATOR_FIELDS, TRUTH_FIELDS

METADATA_KEY = b"quadsitl.session"
FORMAT = "quadsitl.session/1"
PART_GLOB = "part-*.parquet"
# A stream silent this long (wall) no longer holds the watermark back. Not shorter: at --speed max
# on a loaded 2-core machine a publisher's zenoh thread can fall over 1 s behind while the lockstep
# goes on (benchmarks/soak.py saw the controller rows of 8 frames arrive after their truth rows had
# been written with 1 s, so each of those frames became two half rows).
STALE_WALL_S = 5.0
NO_ZENOH_FALLBACK_WALL_S = 3.0  # no zenoh at all after this long: rows from LOCAL_POSITION_NED

FRAMES_NOTE = (
    "truth and controller columns: the paper's frames (world x north, y left, z up; body "
    "front-left-up), SI units. mav_* columns: MAVLink as received (world NED, body FRD), SI units; "
    "joined as of the row time (latest sample stamped at or before it)."
)


# --------------------------------------------------------------------------------------------
# Joins (pure)
# --------------------------------------------------------------------------------------------
def time_key(time_s: np.ndarray | float) -> np.ndarray:
    """Simulation time (s) -> integer microseconds, the join key."""
    return np.rint(np.asarray(time_s, dtype=float) * 1e6).astype(np.int64)


def asof_index(sample_keys: np.ndarray, row_keys: np.ndarray) -> np.ndarray:
    """For each row key, the index of the last sample with key <= it (-1 if none).

    ``sample_keys`` must be sorted ascending; among equal keys the last one wins.
    """
    return np.searchsorted(sample_keys, row_keys, side="right") - 1


def asof_join(sample_keys: np.ndarray, sample_values: np.ndarray, row_keys: np.ndarray) -> np.ndarray:
    """(rows, k) values of the latest sample at or before each row key; NaN before the first."""
    values = np.asarray(sample_values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    out = np.full((len(row_keys), values.shape[1]), np.nan)
    if len(sample_keys) == 0 or len(row_keys) == 0:
        return out
    idx = asof_index(np.asarray(sample_keys), np.asarray(row_keys))
    ok = idx >= 0
    out[ok] = values[idx[ok]]
    return out


def exact_join(keys: np.ndarray, values: np.ndarray, row_keys: np.ndarray) -> np.ndarray:
    """(rows, k) values whose key equals each row key; NaN where there is none.

    ``keys`` must be sorted ascending and unique (see :func:`dedupe_sorted`).
    """
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    out = np.full((len(row_keys), values.shape[1]), np.nan)
    if len(keys) == 0 or len(row_keys) == 0:
        return out
    idx = np.searchsorted(keys, row_keys, side="left")
    idx_clipped = np.minimum(idx, len(keys) - 1)
    ok = (idx < len(keys)) & (keys[idx_clipped] == row_keys)
    out[ok] = values[idx_clipped[ok]]
    return out


def dedupe_sorted(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sort by key (stable) and keep the LAST row of each key (a resent frame replaces the first)."""
    order = np.argsort(keys, kind="stable")
    keys, values = keys[order], values[order]
    if len(keys) == 0:
        return keys, values
    last = np.ones(len(keys), dtype=bool)
    last[:-1] = keys[1:] != keys[:-1]
    return keys[last], values[last]


# --------------------------------------------------------------------------------------------
# MAVLink columns
# --------------------------------------------------------------------------------------------
Extractor = Callable[[Any], float]


@dataclass(frozen=True)
class MavColumn:
    name: str
    extract: Extractor
    description: str


@dataclass(frozen=True)
class MavGroup:
    """The columns one MAVLink message contributes; ``stamp`` says where its time comes from."""

    name: str  # time column: mav_<name>_time_s
    message: str
    stamp: str  # "time_boot_ms", "time_usec", "time_usec32" (wraps at 2^32 µs) or "" (untimed)
    columns: tuple[MavColumn, ...]

    @property
    def time_column(self) -> str:
        """The column holding the stamp of this group's message sample (``mav_<name>_time_s``)."""
        return f"mav_{self.name}_time_s"


def _f(field: str, scale: float = 1.0) -> Extractor:
    return lambda msg: float(getattr(msg, field)) * scale


def _item(field: str, index: int) -> Extractor:
    return lambda msg: float(getattr(msg, field)[index])


def _hdg(msg: Any) -> float:
    return math.nan if msg.hdg == 65535 else msg.hdg * 0.01


def _armed(msg: Any) -> float:
    return 1.0 if msg.base_mode & 128 else 0.0  # MAV_MODE_FLAG_SAFETY_ARMED


def _cols(*specs: tuple[str, Extractor, str]) -> tuple[MavColumn, ...]:
    return tuple(MavColumn(*s) for s in specs)


MAV_GROUPS: tuple[MavGroup, ...] = (
    MavGroup("local", "LOCAL_POSITION_NED", "time_boot_ms", _cols(
        ("mav_local_x_m", _f("x"), "LOCAL_POSITION_NED.x, m, NED (north)"),
        ("mav_local_y_m", _f("y"), "LOCAL_POSITION_NED.y, m, NED (east)"),
        ("mav_local_z_m", _f("z"), "LOCAL_POSITION_NED.z, m, NED (down)"),
        ("mav_local_vx_m_s", _f("vx"), "LOCAL_POSITION_NED.vx, m/s, NED"),
        ("mav_local_vy_m_s", _f("vy"), "LOCAL_POSITION_NED.vy, m/s, NED"),
        ("mav_local_vz_m_s", _f("vz"), "LOCAL_POSITION_NED.vz, m/s, NED"),
    )),
    MavGroup("attitude", "ATTITUDE", "time_boot_ms", _cols(
        ("mav_roll_rad", _f("roll"), "ATTITUDE.roll, rad, NED/FRD"),
        ("mav_pitch_rad", _f("pitch"), "ATTITUDE.pitch, rad, NED/FRD"),
        ("mav_yaw_rad", _f("yaw"), "ATTITUDE.yaw, rad, NED/FRD (clockwise from north)"),
        ("mav_rollspeed_rad_s", _f("rollspeed"), "ATTITUDE.rollspeed, rad/s, FRD"),
        ("mav_pitchspeed_rad_s", _f("pitchspeed"), "ATTITUDE.pitchspeed, rad/s, FRD"),
        ("mav_yawspeed_rad_s", _f("yawspeed"), "ATTITUDE.yawspeed, rad/s, FRD"),
    )),
    MavGroup("attitude_q", "ATTITUDE_QUATERNION", "time_boot_ms", _cols(
        ("mav_qw", _f("q1"), "ATTITUDE_QUATERNION.q1 (w), FRD body to NED"),
        ("mav_qx", _f("q2"), "ATTITUDE_QUATERNION.q2 (x)"),
        ("mav_qy", _f("q3"), "ATTITUDE_QUATERNION.q3 (y)"),
        ("mav_qz", _f("q4"), "ATTITUDE_QUATERNION.q4 (z)"),
    )),
    MavGroup("global", "GLOBAL_POSITION_INT", "time_boot_ms", _cols(
        ("mav_lat_deg", _f("lat", 1e-7), "GLOBAL_POSITION_INT.lat, deg"),
        ("mav_lon_deg", _f("lon", 1e-7), "GLOBAL_POSITION_INT.lon, deg"),
        ("mav_alt_m", _f("alt", 1e-3), "GLOBAL_POSITION_INT.alt, m AMSL"),
        ("mav_relative_alt_m", _f("relative_alt", 1e-3), "GLOBAL_POSITION_INT.relative_alt, m above home"),
        ("mav_hdg_deg", _hdg, "GLOBAL_POSITION_INT.hdg, deg (NaN if unknown)"),
    )),
    MavGroup("att_target", "ATTITUDE_TARGET", "time_boot_ms", _cols(
        ("mav_target_qw", _item("q", 0), "ATTITUDE_TARGET.q[0] (w), FRD body to NED"),
        ("mav_target_qx", _item("q", 1), "ATTITUDE_TARGET.q[1] (x)"),
        ("mav_target_qy", _item("q", 2), "ATTITUDE_TARGET.q[2] (y)"),
        ("mav_target_qz", _item("q", 3), "ATTITUDE_TARGET.q[3] (z)"),
        ("mav_target_thrust", _f("thrust"), "ATTITUDE_TARGET.thrust, normalised 0..1"),
    )),
    MavGroup("pos_target", "POSITION_TARGET_LOCAL_NED", "time_boot_ms", _cols(
        ("mav_target_x_m", _f("x"), "POSITION_TARGET_LOCAL_NED.x, m, NED"),
        ("mav_target_y_m", _f("y"), "POSITION_TARGET_LOCAL_NED.y, m, NED"),
        ("mav_target_z_m", _f("z"), "POSITION_TARGET_LOCAL_NED.z, m, NED"),
        ("mav_target_vx_m_s", _f("vx"), "POSITION_TARGET_LOCAL_NED.vx, m/s, NED"),
        ("mav_target_vy_m_s", _f("vy"), "POSITION_TARGET_LOCAL_NED.vy, m/s, NED"),
        ("mav_target_vz_m_s", _f("vz"), "POSITION_TARGET_LOCAL_NED.vz, m/s, NED"),
        ("mav_target_ax_m_s2", _f("afx"), "POSITION_TARGET_LOCAL_NED.afx, m/s^2, NED"),
        ("mav_target_ay_m_s2", _f("afy"), "POSITION_TARGET_LOCAL_NED.afy, m/s^2, NED"),
        ("mav_target_az_m_s2", _f("afz"), "POSITION_TARGET_LOCAL_NED.afz, m/s^2, NED"),
        ("mav_target_yaw_rad", _f("yaw"), "POSITION_TARGET_LOCAL_NED.yaw, rad, NED"),
    )),
    MavGroup("servo", "SERVO_OUTPUT_RAW", "time_usec32", _cols(
        ("mav_servo1_us", _f("servo1_raw"), "SERVO_OUTPUT_RAW.servo1_raw, µs PWM"),
        ("mav_servo2_us", _f("servo2_raw"), "SERVO_OUTPUT_RAW.servo2_raw, µs PWM"),
        ("mav_servo3_us", _f("servo3_raw"), "SERVO_OUTPUT_RAW.servo3_raw, µs PWM"),
        ("mav_servo4_us", _f("servo4_raw"), "SERVO_OUTPUT_RAW.servo4_raw, µs PWM"),
    )),
    MavGroup("home", "HOME_POSITION", "time_usec", _cols(
        ("mav_home_x_m", _f("x"), "HOME_POSITION.x, m, NED"),
        ("mav_home_y_m", _f("y"), "HOME_POSITION.y, m, NED"),
        ("mav_home_z_m", _f("z"), "HOME_POSITION.z, m, NED"),
        ("mav_home_alt_m", _f("altitude", 1e-3), "HOME_POSITION.altitude, m AMSL"),
    )),
    MavGroup("heartbeat", "HEARTBEAT", "", _cols(
        ("mav_base_mode", _f("base_mode"), "HEARTBEAT.base_mode (MAV_MODE_FLAG bits)"),
        ("mav_custom_mode", _f("custom_mode"), "HEARTBEAT.custom_mode (PX4: main<<16 | sub<<24)"),
        ("mav_armed", _armed, "1 if HEARTBEAT.base_mode has SAFETY_ARMED, else 0"),
        ("mav_system_status", _f("system_status"), "HEARTBEAT.system_status (MAV_STATE)"),
    )),
    MavGroup("ext_state", "EXTENDED_SYS_STATE", "", _cols(
        ("mav_landed_state", _f("landed_state"), "EXTENDED_SYS_STATE.landed_state (MAV_LANDED_STATE)"),
    )),
    MavGroup("sys_status", "SYS_STATUS", "", _cols(
        ("mav_sensors_health", _f("onboard_control_sensors_health"), "SYS_STATUS sensors health bits"),
        ("mav_load_pct", _f("load", 0.1), "SYS_STATUS.load, %"),
    )),
)  # fmt: skip
MAV_GROUP_BY_MESSAGE = {g.message: g for g in MAV_GROUPS}

TRUTH_COLUMNS = TRUTH_FIELDS[1:]  # without time_s
CONTROLLER_COLUMNS = CONTROLLER_FIELDS[1:]
ESTIMATOR_COLUMNS = ESTIMATOR_FIELDS[1:]


def column_names(estimator: bool = False) -> list[str]:
    """Every column of the session table, in order (``estimator``: of a session flown on the EKF)."""
    names = ["time_s", *TRUTH_COLUMNS, *CONTROLLER_COLUMNS]
    for g in MAV_GROUPS:
        names.append(g.time_column)
        names.extend(c.name for c in g.columns)
    if estimator:
        names.extend(ESTIMATOR_COLUMNS)
    return names


def column_descriptions() -> dict[str, str]:
    """Every session column's description (units and source), by column name."""
    out = {"time_s": "simulation time, s (row key; truth and controller joined exactly on it)"}
    for name in TRUTH_COLUMNS:
        out[name] = "ground truth (simulator, zenoh), paper frames, SI"
    for name in CONTROLLER_COLUMNS:
        out[name] = "controller internals (autopilot, zenoh), paper frames, SI"
    for name in ESTIMATOR_COLUMNS:
        out[name] = "the autopilot's EKF (zenoh; only when flown on it), paper frames, SI"
    for g in MAV_GROUPS:
        out[g.time_column] = f"stamp of the {g.message} sample used, simulation s"
        out.update({c.name: c.description for c in g.columns})
    return out


SCHEMA = pa.schema([pa.field(name, pa.float64()) for name in column_names()])
# A session flown on the EKF: the same columns and the estimator's after them.
SCHEMA_WITH_ESTIMATOR = pa.schema([pa.field(name, pa.float64()) for name in column_names(estimator=True)])


def schema_for(has_estimator: bool) -> pa.Schema:
    """The session table's schema, with the estimator columns or without."""
    return SCHEMA_WITH_ESTIMATOR if has_estimator else SCHEMA


# --------------------------------------------------------------------------------------------
# Assembling rows incrementally
# --------------------------------------------------------------------------------------------
class _Stream:
    """Bookkeeping of one input: the latest time reached and when it last advanced (wall)."""

    def __init__(self) -> None:
        self.latest_key: int | None = None
        self.advanced_wall: float | None = None

    def saw(self, key: int, wall: float) -> None:
        if self.latest_key is None or key > self.latest_key:
            self.latest_key = key
            self.advanced_wall = wall

    def live(self, wall: float) -> bool:
        return self.advanced_wall is not None and wall - self.advanced_wall <= STALE_WALL_S


class _Rows:
    """Zenoh row batches (arrays with time_s first) waiting to be handed out."""

    def __init__(self, width: int) -> None:
        self.width = width
        self.chunks: list[np.ndarray] = []
        self.count = 0

    def add(self, rows: np.ndarray) -> None:
        if len(rows):
            self.chunks.append(np.asarray(rows, dtype=float).reshape(-1, self.width))

    def split(self, watermark: int | None) -> tuple[np.ndarray, np.ndarray]:
        """(keys, rows) with key <= watermark (all if None), sorted and deduplicated; keeps the rest."""
        if not self.chunks:
            return np.empty(0, dtype=np.int64), np.empty((0, self.width))
        rows = np.concatenate(self.chunks) if len(self.chunks) > 1 else self.chunks[0]
        keys = time_key(rows[:, 0])
        take = np.ones(len(keys), dtype=bool) if watermark is None else keys <= watermark
        rest = rows[~take]
        self.chunks = [rest] if len(rest) else []
        keys, rows = dedupe_sorted(keys[take], rows[take])
        self.count += len(keys)
        return keys, rows


class _MavSeries:
    """Time-stamped samples of one MAVLink group (appended in arrival order)."""

    def __init__(self, width: int) -> None:
        self.keys: list[int] = []
        self.values: list[tuple[float, ...]] = []
        self.width = width

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        keys = np.asarray(self.keys, dtype=np.int64)
        values = np.asarray(self.values, dtype=float).reshape(-1, self.width)
        order = np.argsort(keys, kind="stable")  # equal stamps keep arrival order: the last wins
        return keys[order], values[order]

    def prune(self, watermark: int) -> None:
        """Drop samples no row after ``watermark`` can use (keep the last one at or before it)."""
        if not self.keys:
            return
        keys, values = self.arrays()
        i = max(int(asof_index(keys, np.asarray([watermark]))[0]), 0)
        self.keys = keys[i:].tolist()
        self.values = [tuple(v) for v in values[i:]]


class SessionAssembler:
    """Collects truth rows, controller rows and MAVLink messages; hands out joined tables.

    ``wall`` arguments are monotonic wall-clock seconds (the caller's clock; injected so tests
    control it).
    """

    def __init__(self, system_id: int, component_id: int = 1, wall: float = 0.0) -> None:
        self.system_id = system_id
        self.component_id = component_id
        self.started_wall = wall
        self.truth = _Rows(len(TRUTH_FIELDS))
        self.controller = _Rows(len(CONTROLLER_FIELDS))
        self.estimator = _Rows(len(ESTIMATOR_FIELDS))
        self.mav = {g.name: _MavSeries(len(g.columns)) for g in MAV_GROUPS}
        self.truth_stream, self.controller_stream, self.mav_stream = _Stream(), _Stream(), _Stream()
        self.estimator_stream = _Stream()  # only ever advances when the autopilot flies on its EKF
        self._pending_untimed: list[tuple[MavGroup, tuple[float, ...]]] = []
        self.first_key: int | None = None
        self.latest_key: int | None = None
        self.emitted_until: int | None = None
        self.rows_emitted = 0
        self.mav_messages = 0
        self.statustext: list[tuple[float, int, str]] = []
        self.armed: bool | None = None  # from HEARTBEAT

    # -- inputs ----------------------------------------------------------------------------------
    def _saw_time(self, key: int) -> None:
        if self.first_key is None:
            self.first_key = key
        if self.latest_key is None or key > self.latest_key:
            self.latest_key = key

    def add_truth(self, rows: np.ndarray, wall: float) -> None:
        """A decoded TRUTH_CODEC batch, (n, len(TRUTH_FIELDS))."""
        if len(rows):
            self.truth.add(rows)
            key = int(time_key(rows[-1, 0]))
            self.truth_stream.saw(key, wall)
            self._saw_time(int(time_key(rows[0, 0])))
            self._saw_time(key)

    def add_controller(self, rows: np.ndarray, wall: float) -> None:
        """A decoded CONTROLLER_CODEC batch, (n, len(CONTROLLER_FIELDS))."""
        if len(rows):
            self.controller.add(rows)
            key = int(time_key(rows[-1, 0]))
            self.controller_stream.saw(key, wall)
            self._saw_time(int(time_key(rows[0, 0])))
            self._saw_time(key)

    def add_estimator(self, rows: np.ndarray, wall: float) -> None:
        """A decoded ESTIMATOR_CODEC batch, (n, len(ESTIMATOR_FIELDS))."""
        if len(rows):
            self.estimator.add(rows)
            key = int(time_key(rows[-1, 0]))
            self.estimator_stream.saw(key, wall)
            self._saw_time(int(time_key(rows[0, 0])))
            self._saw_time(key)

    @property
    def has_estimator(self) -> bool:
        """Estimator rows have arrived: from then on every table handed out has their columns."""
        return self.estimator_stream.latest_key is not None

    def _stamp(self, group: MavGroup, msg: Any) -> int | None:
        if group.stamp == "time_boot_ms":
            return int(msg.time_boot_ms) * 1000
        if group.stamp == "time_usec":
            return int(msg.time_usec)
        if group.stamp == "time_usec32":
            # SERVO_OUTPUT_RAW.time_usec is uint32: it wraps every 71.6 min; unwrap near "now".
            raw = int(msg.time_usec)
            ref = self.mav_stream.latest_key or 0
            return raw + round((ref - raw) / 2**32) * 2**32
        return None

    def add_mavlink(self, msg: Any, wall: float) -> None:
        """One parsed message (pymavlink); only the vehicle's own component is tabulated."""
        if msg.get_srcSystem() != self.system_id or msg.get_srcComponent() != self.component_id:
            return
        kind = msg.get_type()
        self.mav_messages += 1
        if kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode("utf-8", "replace")
            t = (self.mav_stream.latest_key or 0) * 1e-6
            self.statustext.append((t, int(msg.severity), text.rstrip("\x00")))
            return
        if kind == "HEARTBEAT":
            self.armed = bool(msg.base_mode & 128)
        group = MAV_GROUP_BY_MESSAGE.get(kind)
        if group is None:
            return
        values = tuple(c.extract(msg) for c in group.columns)
        key = self._stamp(group, msg)
        if key is None:
            self._pending_untimed.append((group, values))
            return
        self._append(group, key, values)
        if group.stamp == "time_boot_ms":
            # Only the telemetry clock drives time: SERVO_OUTPUT_RAW's counter wraps, and
            # HOME_POSITION may carry time_usec = 0 (set before the first frame).
            self.mav_stream.saw(key, wall)
            self._saw_time(key)
        if self._pending_untimed:
            for g, v in self._pending_untimed:
                self._append(g, key, v)
            self._pending_untimed.clear()

    def _append(self, group: MavGroup, key: int, values: tuple[float, ...]) -> None:
        series = self.mav[group.name]
        series.keys.append(key)
        series.values.append(values)

    # -- outputs ---------------------------------------------------------------------------------
    @property
    def latest_time_s(self) -> float | None:
        """The latest simulation time seen (s), or None before any row."""
        return None if self.latest_key is None else self.latest_key * 1e-6

    @property
    def last_row_time_s(self) -> float | None:
        """The simulation time of the last row handed out (s), or None before any."""
        return None if self.emitted_until is None else self.emitted_until * 1e-6

    @property
    def first_time_s(self) -> float | None:
        """The first simulation time seen (s), or None before any row."""
        return None if self.first_key is None else self.first_key * 1e-6

    def watermark(self, wall: float) -> int | None:
        """The latest key every live stream has reached (None: nothing is safe to hand out)."""
        streams = (self.truth_stream, self.controller_stream, self.estimator_stream, self.mav_stream)
        live = [s.latest_key for s in streams if s.live(wall) and s.latest_key is not None]
        if live:
            return min(live)
        # Every stream silent for a while (paused simulation): what arrived is complete.
        known = [s.latest_key for s in streams if s.latest_key is not None]
        return max(known) if known else None

    def _reached_by_flowing(self, since: float) -> int | None:
        """The latest key every stream that advanced at or after wall time ``since`` has reached
        (None: no stream did, everything is complete)."""
        streams = (self.truth_stream, self.controller_stream, self.estimator_stream, self.mav_stream)
        # (a stream's latest key and the wall time it advanced are set together)
        flowing = [s.latest_key for s in streams if s.latest_key is not None and s.advanced_wall >= since]
        return min(flowing) if flowing else None

    def take(self, wall: float, final: bool = False, flowing_since: float | None = None) -> pa.Table | None:
        """Joined rows up to the watermark (everything if ``final``); None if there are none.

        ``final`` with ``flowing_since`` (wall s): the last rows of a recording that ends while the
        vehicle still streams. They stop at the latest time every stream still flowing since then
        has reached, so the rows in flight on one stream and not yet on another (a ragged tail of
        empty cells) are left out; a stream that stopped before does not hold them back."""
        if self._pending_untimed and (final or not self.mav_stream.live(wall)):
            for g, v in self._pending_untimed:  # no later stamp is coming: use the latest
                self._append(g, self.mav_stream.latest_key or 0, v)
            self._pending_untimed.clear()
        if final:
            watermark = None if flowing_since is None else self._reached_by_flowing(flowing_since)
        else:
            watermark = self.watermark(wall)
        if watermark is None and not final:
            return None
        truth_keys, truth_rows = self.truth.split(watermark)
        ctrl_keys, ctrl_rows = self.controller.split(watermark)
        est_keys, est_rows = self.estimator.split(watermark)
        keys = np.union1d(np.union1d(truth_keys, ctrl_keys), est_keys)
        zenoh_seen = (
            self.truth_stream.latest_key is not None
            or self.controller_stream.latest_key is not None
            or self.has_estimator
        )
        if not zenoh_seen and (final or wall - self.started_wall > NO_ZENOH_FALLBACK_WALL_S):
            # A session without the zenoh bus: one row per LOCAL_POSITION_NED sample.
            local_keys, _ = self.mav["local"].arrays()
            keys = np.unique(local_keys)
            if self.emitted_until is not None:
                keys = keys[keys > self.emitted_until]
            if watermark is not None:
                keys = keys[keys <= watermark]
        if len(keys) == 0:
            return None
        cols: dict[str, np.ndarray] = {"time_s": keys * 1e-6}
        tv = exact_join(truth_keys, truth_rows, keys)
        for i, name in enumerate(TRUTH_COLUMNS, start=1):
            cols[name] = tv[:, i]
        cv = exact_join(ctrl_keys, ctrl_rows, keys)
        for i, name in enumerate(CONTROLLER_COLUMNS, start=1):
            cols[name] = cv[:, i]
        if self.has_estimator:
            ev = exact_join(est_keys, est_rows, keys)
            for i, name in enumerate(ESTIMATOR_COLUMNS, start=1):
                cols[name] = ev[:, i]
        for g in MAV_GROUPS:
            mkeys, mvalues = self.mav[g.name].arrays()
            stamped = np.column_stack([mkeys * 1e-6, mvalues])  # the stamp rides along as column 0
            joined = asof_join(mkeys, stamped, keys)
            cols[g.time_column] = joined[:, 0]
            for i, c in enumerate(g.columns, start=1):
                cols[c.name] = joined[:, i]
        last = int(keys[-1])
        for series in self.mav.values():
            series.prune(last)
        self.emitted_until = last if self.emitted_until is None else max(self.emitted_until, last)
        self.rows_emitted += len(keys)
        return pa.Table.from_pydict(cols, schema=schema_for(self.has_estimator))


# --------------------------------------------------------------------------------------------
# Files: parts, merge, reading back
# --------------------------------------------------------------------------------------------
def with_metadata(table: pa.Table, metadata: dict[str, Any]) -> pa.Table:
    """``table`` with ``metadata`` as JSON under :data:`METADATA_KEY` in its schema metadata."""
    return table.replace_schema_metadata({METADATA_KEY: json.dumps(metadata).encode()})


class PartWriter:
    """Writes ``part-000001.parquet``, ... into ``parts_dir``, each a complete Parquet file.

    Each part is written under a temporary name and renamed, so a process killed mid-write
    never leaves a truncated part under a part name.
    """

    def __init__(self, parts_dir: Path) -> None:
        self.parts_dir = Path(parts_dir)
        self.parts_dir.mkdir(parents=True, exist_ok=True)
        self.index = 0
        self.paths: list[Path] = []

    def write(self, table: pa.Table, metadata: dict[str, Any]) -> Path:
        """Write ``table`` (with ``metadata``) as the next numbered part, atomically (a temporary file
        renamed); return its path."""
        self.index += 1
        path = self.parts_dir / f"part-{self.index:06d}.parquet"
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(with_metadata(table, metadata), tmp)
        os.replace(tmp, path)
        self.paths.append(path)
        return path


def _conform(table: pa.Table, schema: pa.Schema) -> pa.Table:
    """``table`` with exactly ``schema``'s columns, in order; the ones it lacks NaN."""
    nan = pa.chunked_array([pa.array(np.full(table.num_rows, np.nan), type=pa.float64())])
    columns = [table.column(n) if n in table.column_names else nan for n in schema.names]
    return pa.Table.from_arrays(columns, names=schema.names).cast(schema)


def part_paths(parts_dir: Path) -> list[Path]:
    """The part files in ``parts_dir``, in order."""
    return sorted(Path(parts_dir).glob(PART_GLOB))


def merge_parts(parts_dir: Path, out_path: Path, metadata: dict[str, Any], remove: bool = True) -> Path:
    """Stream every part into ``out_path`` (one row group per part), then delete the parts.

    The merged file is complete before the parts go: it is written under a temporary name and
    renamed. Memory use is one part at a time. When any part has the estimator's columns the
    merged file has them, NaN in the rows of parts written before its first rows arrived.
    """
    out_path = Path(out_path)
    tmp = out_path.with_name(out_path.name + ".tmp")
    parts = part_paths(parts_dir)
    full = schema_for(any(ESTIMATOR_COLUMNS[0] in pq.read_schema(part).names for part in parts))
    schema = full.with_metadata({METADATA_KEY: json.dumps(metadata).encode()})
    with pq.ParquetWriter(tmp, schema) as writer:
        for part in parts:
            writer.write_table(_conform(pq.read_table(part), full).replace_schema_metadata(schema.metadata))
    os.replace(tmp, out_path)
    if remove:
        for part in parts:
            part.unlink()
        try:
            Path(parts_dir).rmdir()
        except OSError:
            pass  # something else in there (a .tmp of a killed writer): leave it
    return out_path


def resolve_session_path(path: str | Path) -> Path:
    """A session file, a parts directory, or a bare NAME (NAME.parquet, else NAME.parts)."""
    p = Path(path)
    if p.is_dir() or p.is_file():
        return p
    for candidate in (p.with_name(p.name + ".parquet"), p.with_name(p.name + ".parts")):
        if candidate.exists():
            return candidate
    raise FileNotFoundError(f"no session log at {p} (nor {p}.parquet, nor {p}.parts/)")


def read_session_table(path: str | Path) -> tuple[pa.Table, dict[str, Any]]:
    """The table and its metadata from a merged session file or a parts directory.

    A parts directory is what a recorder that died leaves behind: every complete part is read
    (in order) and the metadata of the last one is used.
    """
    p = resolve_session_path(path)
    if p.is_dir():
        parts = part_paths(p)
        if not parts:
            raise FileNotFoundError(f"{p}: no {PART_GLOB} files")
        tables = [pq.read_table(part) for part in parts]
        meta_raw = (tables[-1].schema.metadata or {}).get(METADATA_KEY, b"{}")
        full = schema_for(any(ESTIMATOR_COLUMNS[0] in t.column_names for t in tables))
        table = pa.concat_tables([_conform(t, full) for t in tables])
    else:
        table = pq.read_table(p)
        meta_raw = (table.schema.metadata or {}).get(METADATA_KEY, b"{}")
    return table, json.loads(meta_raw)


def session_metadata(
    instance: int,
    simulator: dict[str, Any] | None,
    autopilot: dict[str, Any] | None,
    start_sim_time_s: float | None,
    extra: dict[str, Any] | None = None,
    statustext: Sequence[tuple[float, int, str]] = (),
) -> dict[str, Any]:
    """The JSON stored under ``quadsitl.session`` in the Parquet schema metadata."""
    sim = simulator or {}
    ap = autopilot or {}
    meta: dict[str, Any] = {
        "format": FORMAT,
        "instance": instance,
        "scenario": sim.get("scenario", ""),
        "vehicle": sim.get("vehicle", ap.get("vehicle", "")),
        "controller": ap.get("controller", ""),
        "actuation": sim.get("actuation", ""),
        "physics_hz": sim.get("physics_hz"),
        "control_hz": sim.get("control_hz", ap.get("control_hz")),
        "speed": sim.get("speed"),
        "recording_start_sim_time_s": start_sim_time_s,
        "simulator_info": simulator,
        "autopilot_info": autopilot,
        "frames": FRAMES_NOTE,
        "columns": column_descriptions(),
        "statustext": [list(s) for s in statustext],
        "written_unix_s": time.time(),
    }
    meta.update(extra or {})
    return meta
