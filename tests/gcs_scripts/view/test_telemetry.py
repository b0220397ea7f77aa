"""What the view takes from MAVLink: frame picking, STATUSTEXT chunks, mode/armed/landed, failsafes."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from gcs_scripts.link import custom_mode
from gcs_scripts.view.telemetry import (
    MSG_HEARTBEAT,
    MSG_STATUSTEXT,
    FailsafeTracker,
    StatusTextAssembler,
    VehicleTelemetry,
    wanted_frames,
)
from tests.gcs_scripts.helpers import Vehicle, parse

pytestmark = pytest.mark.timeout(30)


def _mode(name: str) -> int:
    return custom_mode(name)[0]


def test_wanted_frames_picks_by_id_and_source_from_a_datagram_of_several():
    v, other = Vehicle(instance=3), Vehicle(instance=4)
    hb = v.heartbeat(True)
    att = v.attitude(1.0, 0.1, 0.2, 0.3)
    text = v.statustext("armed")
    foreign = other.heartbeat(False)
    datagram = att + hb + foreign + text
    got = list(wanted_frames(datagram, system_id=4))
    assert got == [hb, text]
    assert [m.get_msgId() for m in parse(got)] == [MSG_HEARTBEAT, MSG_STATUSTEXT]
    assert list(wanted_frames(datagram, system_id=5)) == [foreign]


def test_wanted_frames_handles_signed_mavlink2_and_mavlink1_and_stops_at_garbage():
    v = Vehicle(instance=0)
    hb = bytearray(v.heartbeat(False))
    hb[2] |= 1  # incompat flag "signed": 13 signature bytes follow the CRC
    signed = bytes(hb) + bytes(13)
    mav1 = b"\xfe" + bytes([9, 0, 1, 1, 0]) + bytes(9) + b"\x00\x00"  # a MAVLink 1 HEARTBEAT frame
    assert list(wanted_frames(signed + mav1, system_id=1)) == [signed, mav1]
    assert list(wanted_frames(b"\x00garbage" + signed, system_id=1)) == []
    assert list(wanted_frames(signed[:-3], system_id=1)) == []  # truncated: nothing half-parsed


def test_statustext_single_and_chunked():
    a = StatusTextAssembler()
    assert a.add(6, b"armed\x00\x00") == [(6, "armed")]
    long = "GCS connection lost: no heartbeat for 10.2 s (NAV_DLL_ACT 1): holding"
    raw = long.encode()
    chunks = [raw[i : i + 50] for i in range(0, len(raw), 50)]
    assert a.add(2, chunks[0], ident=7, chunk_seq=0) == []
    assert a.add(2, chunks[1], ident=7, chunk_seq=1) == [(2, long)]


def test_statustext_lost_last_chunk_is_bounded():
    a = StatusTextAssembler(max_pending=2)
    full = b"x" * 50
    assert a.add(4, full, ident=1) == []
    assert a.add(4, full, ident=2) == []
    out = a.add(4, full, ident=3)  # a third id waiting: the oldest goes out as it is
    assert out == [(4, "x" * 50)]


def test_failsafe_ends_on_mode_change_after_the_one_it_set():
    f = FailsafeTracker()
    f.statustext("offboard setpoints lost: switching to hold")
    assert f.name == "offboard loss"
    f.heartbeat("AUTO.LOITER", True)  # the failsafe's own mode
    f.heartbeat("AUTO.LOITER", True)
    assert f.name == "offboard loss"
    f.heartbeat("AUTO.LAND", True)  # the pilot took over
    assert f.name is None


def test_failsafe_link_loss_lasts_until_regained_whatever_the_mode():
    f = FailsafeTracker()
    f.statustext("GCS connection lost: no heartbeat for 10.1 s (NAV_DLL_ACT 2): returning to launch")
    for mode in ("AUTO.RTL", "AUTO.RTL", "AUTO.LAND"):
        f.heartbeat(mode, True)
    assert f.name == "GCS link lost"
    f.statustext("mode AUTO.LAND")
    assert f.name == "GCS link lost"
    f.statustext("GCS connection regained")
    assert f.name is None


def test_failsafe_disarm_ends_it_but_not_the_simulator_loss():
    f = FailsafeTracker()
    f.statustext("geofence breached: 12.0 m from home > GF_MAX_HOR_DIST 10 m: holding")
    f.heartbeat("AUTO.LOITER", False)
    assert f.name is None
    f.statustext("simulator lost: no sensor frame for 1 s (COM_SIM_LOSS_T); motors off")
    f.heartbeat("AUTO.LOITER", False)
    assert f.name == "simulator lost"
    f.statustext("simulator link recovered")
    assert f.name is None


def test_vehicle_telemetry_from_parsed_messages():
    v = Vehicle(instance=0)
    tm = VehicleTelemetry()
    frames = [
        v.heartbeat(False, _mode("AUTO.LOITER")),
        v.extended_sys_state(1),
        v.heartbeat(True, _mode("AUTO.TAKEOFF")),
        v.extended_sys_state(3),
        v.statustext("takeoff to 2.50 m"),
    ]
    for msg in parse(frames):
        tm.add(msg, sim_time_s=4.5)
    assert (tm.mode, tm.armed, tm.landed) == ("AUTO.TAKEOFF", True, "TAKEOFF")
    assert tm.take_texts() == [(4.5, 6, "takeoff to 2.50 m")]
    assert tm.take_texts() == []
    assert tm.failsafe_name is None


def test_geofence_health_bit_reads_as_a_failsafe():
    tm = VehicleTelemetry()
    fence = 1 << 20
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = mavlink2.MAVLink_sys_status_message(fence, fence, 0, 250, 16000, -1, 100, 0, 0, 0, 0, 0, 0)
    tm.add(parse([bytes(msg.pack(mav))])[0], 0.0)
    assert tm.failsafe_name == "geofence"
