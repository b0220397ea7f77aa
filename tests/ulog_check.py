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
* Flight Review (``app/plot_app``): the topics and fields its plots and tables read
  (:data:`FLIGHT_REVIEW`; a plot missing one field is dropped whole), ``estimator_status`` too
  when the vehicle flew on its EKF.
"""

from __future__ import annotations

import struct
from pathlib import Path

from autopilot.logger.ulog import TYPE_CODES

MAGIC = b"ULog\x01\x12\x35"
DEFINITION_TYPES = {ord(c) for c in "BFIMPQ"}
FLIGHT_REVIEW = {
    "vehicle_local_position": ("x", "y", "z", "vx", "vy", "vz", "xy_valid", "z_valid", "v_xy_valid",
                               "v_z_valid"),
    "vehicle_local_position_setpoint": ("x", "y", "z", "vx", "vy", "vz"),
    "vehicle_attitude": ("q[0]", "q[1]", "q[2]", "q[3]"),
    "vehicle_attitude_setpoint": ("q_d[0]", "q_d[1]", "q_d[2]", "q_d[3]", "yaw_sp_move_rate"),
    "vehicle_angular_velocity": ("xyz[0]", "xyz[1]", "xyz[2]"),
    "vehicle_rates_setpoint": ("roll", "pitch", "yaw"),
    "actuator_outputs": ("noutputs", "output[0]", "output[15]"),
    "vehicle_status": ("nav_state", "arming_state", "is_vtol", "vehicle_type", "failsafe",
                       "failsafe_and_user_took_over"),
    "sensor_combined": ("gyro_rad[0]", "accelerometer_m_s2[2]"),
    "vehicle_gps_position": ("latitude_deg", "longitude_deg", "altitude_msl_m", "fix_type", "time_utc_usec",
                             "eph", "epv", "hdop", "vdop", "s_variance_m_s", "satellites_used", "vel_m_s",
                             "noise_per_ms", "jamming_indicator"),
    "vehicle_global_position": ("lat", "lon", "alt"),
    "battery_status": ("voltage_v", "voltage_filtered_v", "current_a", "current_filtered_a", "discharged_mah",
                       "remaining"),
    "vehicle_local_position_groundtruth": ("x", "y", "z"),
    "vehicle_attitude_groundtruth": ("q[0]", "q[3]"),
    "vehicle_angular_velocity_groundtruth": ("xyz[0]",),
}  # fmt: skip
EKF_ONLY = {  # health_flags, timeout_flags: its "Estimator Flags" plot
    "estimator_status": ("pos_test_ratio", "vel_test_ratio", "hgt_test_ratio", "solution_status_flags",
                         "health_flags", "timeout_flags"),
}  # fmt: skip


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
    samples per topic. A message cut by the end of the file ends the check (as the parser stops)."""
    assert data[:7] == MAGIC, "not a ULog file (magic)"
    assert len(data) >= 16 + 3 + 40, "no flag bits message"
    size, kind = struct.unpack_from("<HB", data, 16)
    assert (kind, size) == (ord("B"), 40), f"first message {chr(kind)!r} of {size} bytes, expected 'B' of 40"
    incompat = data[16 + 3 + 8 : 16 + 3 + 16]
    assert incompat[0] & ~1 == 0 and not any(incompat[1:]), "unknown incompatible flags"
    formats: dict[str, int] = {}
    subscriptions: dict[int, str] = {}
    counts: dict[str, int] = {}
    in_data = False
    offset = 16
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
            assert all(k in TYPE_CODES for k, _, _ in fields), f"format {name}: a nested or unknown type"
            formats[name] = sum(struct.calcsize("<" + TYPE_CODES[k]) * n for k, n, _ in fields)
        elif kind in (ord("I"), ord("P")):
            key = body[1 : 1 + body[0]].decode("ascii")
            type_name, _, key_name = key.partition(" ")
            assert key_name, f"info/parameter key {key!r} is not 'type name'"
            if kind == ord("P"):
                assert type_name in ("int32_t", "float"), f"parameter {key_name} of type {type_name}"
        elif kind == ord("A"):
            msg_id, name = struct.unpack_from("<H", body, 1)[0], body[3:].decode("ascii")
            assert name in formats, f"subscription {msg_id} to {name}: no such format"
            subscriptions[msg_id] = name
        elif kind == ord("D"):
            msg_id = struct.unpack_from("<H", body)[0]
            assert msg_id in subscriptions, f"data of message id {msg_id}, never subscribed"
            name = subscriptions[msg_id]
            assert size - 2 == formats[name], f"{name}: sample of {size - 2} bytes, format {formats[name]}"
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
        required = {**FLIGHT_REVIEW, **(EKF_ONLY if ekf else {})}
        for topic, fields in required.items():
            assert topic in datasets, f"{path}: no {topic} samples (Flight Review plots it)"
            missing = [f for f in fields if f not in datasets[topic].data]
            assert not missing, f"{path}: {topic} lacks {missing}"
        for key in ("sys_name", "ver_hw", "ver_sw"):
            assert key in ulog.msg_info_dict, f"{path}: no info {key}"
    return ulog
