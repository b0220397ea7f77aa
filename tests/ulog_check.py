"""What PX4's log tools need of a ULog file, checked on every flight log the tests write.

* pyulog (the reference parser: ``ulog_info``, ``ulog2csv``, Flight Review load it) opens it and
  finds no corruption (a file cut at its end by a kill is allowed where the caller says so);
* PlotJuggler's ULog parser (``plotjuggler_plugins/DataLoadULog/ulog_parser.cpp``) mirrored: the
  16-byte header with its magic; the flag-bits message first after it and exactly 40 bytes (else
  "unsupported message length for FLAG_BITS"), no unknown incompatible flag (else it refuses to
  parse); the definitions section holds only flag bits, formats, info, parameters and defaults
  until the first subscription ``A`` (where PlotJuggler starts the data section); every format
  ``name:type name;...`` with ``uint64_t timestamp`` as its first field (the sample's time);
  every subscription names a defined format (PlotJuggler dereferences it); parameters only
  ``int32_t`` or ``float`` (it throws on any other type); info keys ``type name``; every data
  message's id subscribed and its size the format's;
* Flight Review (``app/plot_app``): :data:`FLIGHT_REVIEW`, every topic and field its standard
  plots and tables read (a plot missing one field is dropped whole) and the least sampling rate
  its spectra take, ``estimator_status`` too when the vehicle flew on its EKF.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import NamedTuple

import numpy as np

from autopilot.commander.health import PX4_FIELDS
from autopilot.logger.ulog import TYPE_CODES

MAGIC = b"ULog\x01\x12\x35"
DEFINITION_TYPES = {ord(c) for c in "BFIMPQ"}


class Need(NamedTuple):
    """What Flight Review reads of one topic (``app/plot_app/configured_plots.py``, ``helper.py``,
    ``plotting.py``, ``plotted_tables.py``): pyulog's columns, the least sampling rate it takes
    (Hz, 0: any), the plots the topic serves, and whether every flight has it (False: only some
    flights, as in PX4's logs; checked where present)."""

    topic: str
    fields: tuple[str, ...]
    min_rate_hz: int
    plots: str
    every_flight: bool = True


# DataPlotFFT and DataPlotSpec draw a spectrum only at >= 100 Hz: int(1 / the median interval of
# timestamp_sample, else timestamp).
SPECTRUM_HZ = 100
XYZ = ("xyz[0]", "xyz[1]", "xyz[2]")
Q = ("q[0]", "q[1]", "q[2]", "q[3]")
FLIGHT_REVIEW: tuple[Need, ...] = (
    Need("vehicle_local_position",
         ("x", "y", "z", "vx", "vy", "vz", "xy_valid", "z_valid", "v_xy_valid", "v_z_valid",
          "ref_timestamp", "ref_lat", "ref_lon"), 0,
         "Position (2D) and its map origin, Local Position X/Y/Z, Velocity, the info table"),
    Need("vehicle_local_position_setpoint", ("x", "y", "z", "vx", "vy", "vz"), 0,
         "Position, Local Position X/Y/Z, Velocity: setpoints"),
    Need("vehicle_local_position_groundtruth", ("x", "y"), 0, "Position: groundtruth"),
    Need("position_setpoint_triplet", ("current.lat", "current.lon", "current.alt"), 0,
         "Altitude Estimate and Position: the setpoint circles (PX4: the navigator's modes)",
         every_flight=False),
    Need("vehicle_gps_position",
         ("latitude_deg", "longitude_deg", "altitude_msl_m", "fix_type", "time_utc_usec", "eph",
          "epv", "hdop", "vdop", "s_variance_m_s", "satellites_used", "noise_per_ms",
          "jamming_indicator"), 0,
         "the map, Position (GPS), Altitude Estimate (GPS), GPS Uncertainty, GPS Noise & Jamming, "
         "the info table's start time"),
    Need("vehicle_global_position", ("alt",), 0, "Altitude Estimate (fused)"),
    Need("vehicle_attitude", Q, 0, "Roll/Pitch/Yaw Angle (pyulog's Euler angles of q), the info table"),
    Need("vehicle_attitude_setpoint", ("q_d[0]", "q_d[1]", "q_d[2]", "q_d[3]", "yaw_sp_move_rate"), 0,
         "Roll/Pitch/Yaw Angle: setpoints, yaw feed-forward"),
    Need("vehicle_attitude_groundtruth", Q, 0, "Roll/Pitch/Yaw Angle: groundtruth"),
    Need("vehicle_angular_velocity", XYZ, SPECTRUM_HZ,
         "Roll/Pitch/Yaw Angular Rate, Angular Velocity FFT, Angular velocity Power Spectral Density"),
    Need("vehicle_rates_setpoint", ("roll", "pitch", "yaw"), 0, "Angular Rate: setpoints"),
    Need("rate_ctrl_status", ("rollspeed_integ", "pitchspeed_integ", "yawspeed_integ"), 0,
         "Angular Rate: the rate integrals"),
    Need("vehicle_angular_velocity_groundtruth", XYZ, 0, "Angular Rate: groundtruth"),
    Need("vehicle_torque_setpoint", XYZ, SPECTRUM_HZ, "Actuator Controls, Actuator Controls FFT"),
    Need("vehicle_thrust_setpoint", XYZ, 0, "Actuator Controls: thrust"),
    Need("actuator_motors", tuple(f"control[{i}]" for i in range(12)), 0,
         "Motor Outputs; its presence makes the torque and thrust setpoints the actuator controls "
         "(PX4's control allocation)"),
    Need("sensor_combined",
         ("gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]", "accelerometer_m_s2[0]", "accelerometer_m_s2[1]",
          "accelerometer_m_s2[2]"), SPECTRUM_HZ,
         "Raw Acceleration, Raw Angular Speed (Gyroscope), Acceleration Power Spectral Density, "
         "Sampling Regularity of Sensor Data"),
    Need("battery_status", ("voltage_v", "voltage_filtered_v", "current_a", "current_filtered_a",
                            "discharged_mah", "remaining"), 0,
         "Power, the info table"),
    Need("vehicle_status",
         ("nav_state", "arming_state", "is_vtol", "vehicle_type", "failsafe",
          "failsafe_and_user_took_over"), 0,
         "the flight modes behind every plot, Failsafe Flags (In Failsafe, User Took Over)"),
    # Failsafe Flags draws every failsafe_flags field set at some time in the flight, the mode_req_*
    # masks aside: PX4's fields, all of them logged.
    Need("failsafe_flags", tuple(f for f in PX4_FIELDS if not f.startswith("mode_req_")), 0,
         "Failsafe Flags (each flag that was set)"),
)  # fmt: skip
EKF_ONLY = (
    Need("estimator_status",
         ("pos_test_ratio", "vel_test_ratio", "hgt_test_ratio", "solution_status_flags", "health_flags",
          "timeout_flags"), 0, "Estimator Flags"),
)  # fmt: skip


def sampling_rate_hz(dataset) -> int:
    """The sampling rate as Flight Review's spectra compute it (``DataPlotSpec.add_graph``)."""
    data = dataset.data
    t = data["timestamp_sample"] if "timestamp_sample" in data else data["timestamp"]
    if len(t) < 2:
        return 0
    return int(1.0 / (np.median(np.diff(t.astype(np.int64))) * 1.0e-6))


def check_flight_review(ulog, ekf: bool = False) -> None:
    """Every :data:`FLIGHT_REVIEW` need (and :data:`EKF_ONLY` with ``ekf``) met by the pyulog
    ``ulog``: the topic there (unless only some flights have it), its fields, its rate."""
    datasets = {d.name: d for d in ulog.data_list}
    for need in (*FLIGHT_REVIEW, *(EKF_ONLY if ekf else ())):
        dataset = datasets.get(need.topic)
        if dataset is None:
            assert not need.every_flight, f"no {need.topic} samples (Flight Review: {need.plots})"
            continue
        missing = [f for f in need.fields if f not in dataset.data]
        assert not missing, f"{need.topic} lacks {missing} (Flight Review: {need.plots})"
        rate = sampling_rate_hz(dataset)
        assert rate >= need.min_rate_hz, f"{need.topic} at {rate} Hz, below {need.min_rate_hz} ({need.plots})"
    for key in ("sys_name", "ver_hw", "ver_sw"):
        assert key in ulog.msg_info_dict, f"no info {key}"


def _format_fields(text: str) -> tuple[str, list[tuple[str, int, str]]]:
    name, _, rest = text.partition(":")
    assert name and rest, f"format without a name or fields: {text!r}"
    fields = []
    for part in rest.split(";"):
        if not part:
            continue
        kind, field = part.split(" ")
        count = 1
        if "[" in kind:
            kind, size = kind[:-1].split("[")
            count = int(size)
        fields.append((kind, count, field))
    return name, fields


def check_plotjuggler(data: bytes) -> dict[str, int]:
    """The requirements of PlotJuggler's parser (see the module docstring); the number of data
    samples per topic. A message cut by the end of the file ends the check (as the parser stops).
    A field of a nested message type names a format (PlotJuggler reads it inline, recursively)."""
    assert data[:7] == MAGIC, "not a ULog file (magic)"
    assert len(data) >= 16 + 3 + 40, "no flag bits message"
    size, kind = struct.unpack_from("<HB", data, 16)
    assert (kind, size) == (ord("B"), 40), f"first message {chr(kind)!r} of {size} bytes, expected 'B' of 40"
    incompat = data[16 + 3 + 8 : 16 + 3 + 16]
    assert incompat[0] & ~1 == 0 and not any(incompat[1:]), "unknown incompatible flags"
    formats: dict[str, list[tuple[str, int, str]]] = {}
    sizes: dict[str, int] = {}
    subscriptions: dict[int, str] = {}
    counts: dict[str, int] = {}
    in_data = False
    offset = 16

    def size_of(name: str) -> int:
        if name not in sizes:
            sizes[name] = sum(
                (struct.calcsize("<" + TYPE_CODES[k]) if k in TYPE_CODES else size_of(k)) * n
                for k, n, _ in formats[name]
            )
        return sizes[name]

    while offset + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, offset)
        body = data[offset + 3 : offset + 3 + size]
        if len(body) < size:
            break  # cut at the end of the file
        offset += 3 + size
        if kind == ord("A"):
            in_data = True
        if not in_data:
            assert kind in DEFINITION_TYPES, f"message {chr(kind)!r} before the first subscription"
        if kind == ord("F"):
            name, fields = _format_fields(body.decode("ascii"))
            assert fields[0] == ("uint64_t", 1, "timestamp"), (
                f"format {name}: timestamp is not its first field"
            )
            formats[name] = fields
        elif kind in (ord("I"), ord("P")):
            key = body[1 : 1 + body[0]].decode("ascii")
            type_name, _, key_name = key.partition(" ")
            assert key_name, f"info/parameter key {key!r} is not 'type name'"
            if kind == ord("P"):
                assert type_name in ("int32_t", "float"), f"parameter {key_name} of type {type_name}"
        elif kind == ord("A"):
            msg_id, name = struct.unpack_from("<H", body, 1)[0], body[3:].decode("ascii")
            assert name in formats, f"subscription {msg_id} to {name}: no such format"
            unknown = [k for k, _, _ in formats[name] if k not in TYPE_CODES and k not in formats]
            assert not unknown, f"format {name}: types {unknown} neither basic nor defined"
            subscriptions[msg_id] = name
        elif kind == ord("D"):
            msg_id = struct.unpack_from("<H", body)[0]
            assert msg_id in subscriptions, f"data of message id {msg_id}, never subscribed"
            name = subscriptions[msg_id]
            assert size - 2 == size_of(name), f"{name}: sample of {size - 2} bytes, format {size_of(name)}"
            counts[name] = counts.get(name, 0) + 1
    return counts


def check_ulog(path: str | Path, ekf: bool = False, cut: bool = False, flight_review: bool = True):
    """Every check of the module docstring on the file at ``path``; returns the pyulog ULog.
    ``cut``: the file may end in the middle of a message (a killed autopilot)."""
    from pyulog import ULog

    data = Path(path).read_bytes()
    counts = check_plotjuggler(data)
    ulog = ULog(str(path))
    assert cut or not ulog.file_corruption, f"{path}: pyulog reports corruption"
    datasets = {d.name: d for d in ulog.data_list}
    assert {name: len(d.data["timestamp"]) for name, d in datasets.items()} == counts
    if flight_review:
        check_flight_review(ulog, ekf)
    return ulog
