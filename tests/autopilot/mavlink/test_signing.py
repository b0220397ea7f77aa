"""MAVLink 2 signing on the GCS links (autopilot/mavlink/signing.py), in-process and in simulation
time: the whole stack (sitl.inprocess.Lockstep) with ground stations whose pymavlink ``mav`` signs.

The autopilot's wall clock for signing is a fake one (T0 + the stack's time): the runs are
deterministic, and timestamps behave as they do in the process, where the shell passes time.time.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat

import pytest

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from autopilot.mavlink import signing as sg
from autopilot.mavlink.links import GCS_LINK, HIL_LINK
from autopilot.mavlink.signing import SigningOptions, mavlink_timestamp, passphrase_to_key
from quadcommon.schema import ConfigError
from simulator.core import SimulatorSetup
from sitl.inprocess import API_LINK, Lockstep, mavlink
from tests.stack import sequence_gaps

m = mavlink
T0 = 1.75e9  # the fake wall clock at the stack's t = 0 (s since 1970; mid-2025)
PASSPHRASE = "correct-horse-battery-staple"
KEY = passphrase_to_key(PASSPHRASE)
REQUEST_MESSAGE = m.MAV_CMD_REQUEST_MESSAGE
ARM = m.MAV_CMD_COMPONENT_ARM_DISARM


class FakeEpoch:
    """The wall clock the shell would inject: T0 plus the stack's (simulation) time."""

    def __init__(self) -> None:
        self.stack: Lockstep | None = None
        self.offset_s = 0.0

    def __call__(self) -> float:
        return T0 + self.offset_s + (self.stack.t if self.stack is not None else 0.0)


def signing_stack(tmp_path, key=None, state: str | None = "signing.json", clock: bool = True) -> Lockstep:
    """A vehicle on the ground; signing with the key file ``key`` (None: off), the state file
    ``state`` in ``tmp_path`` (None: the default), the fake wall clock (or none); no client yet."""
    epoch = FakeEpoch() if clock else None
    sim = SimulatorSetup.load(scenario="hover")
    options = SigningOptions(
        str(key) if key else None, str(tmp_path / state) if state else None, epoch_clock=epoch
    )
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller("intbs_nlhinf"), default_remotes=False,
                        signing=options)  # fmt: skip
    stack = Lockstep(sim, ap)
    if epoch is not None:
        epoch.stack = stack
    return stack


def key_file(tmp_path, text: str = PASSPHRASE + "\n"):
    path = tmp_path / "key.txt"
    path.write_text(text)
    path.chmod(0o600)
    return path


def sign(station, key: bytes = KEY, link_id: int = 7, epoch_s: float | None = None) -> None:
    """The station's pymavlink ``mav`` signs from now on, as ``mavutil``'s ``setup_signing`` does."""
    s = station.mav.signing
    s.secret_key, s.sign_outgoing, s.link_id = key, True, link_id
    s.timestamp = mavlink_timestamp(T0 + station.stack.t if epoch_s is None else epoch_s)


def verify_incoming(station, key: bytes = KEY) -> None:
    """The station checks every frame the vehicle sends with ``key`` (pymavlink's own check, no
    accept-list): an unsigned or wrongly signed one arrives as BAD_DATA."""
    station._parser.signing.secret_key = key


def command_frame(station, command: int, *params: float) -> bytes:
    """A COMMAND_LONG frame as the station's ``mav`` packs it (signed if it signs), not yet sent."""
    p = list(params) + [0.0] * (7 - len(params))
    msg = station.mav.command_long_encode(station.stack.autopilot.system_id, 1, command, 0, *p)
    data = msg.pack(station.mav)
    station.mav.seq = (station.mav.seq + 1) % 256
    return data


def send_and_wait(stack: Lockstep, station, data: bytes, command: int, seconds: float = 0.3) -> list:
    """Deliver ``data``, run ``seconds`` of simulation; the COMMAND_ACKs of ``command`` it brought."""
    before = len(station.acks(command))
    station.send_bytes(data)
    stack.run_for(seconds)
    return station.acks(command)[before:]


def signing_info(stack: Lockstep) -> dict:
    return stack.autopilot.info()["signing"]


# -- key files, state files ---------------------------------------------------------------------------
def test_key_file_hex_or_passphrase_as_mavproxy_derives_it(tmp_path):
    hex_key = "00112233445566778899aabbccddeeff" * 2
    assert sg.read_key_file(key_file(tmp_path, f"  {hex_key}\n\n")) == bytes.fromhex(hex_key)
    assert sg.read_key_file(key_file(tmp_path)) == hashlib.sha256(PASSPHRASE.encode("ascii")).digest()
    # MAVProxy's own derivation (its signing module), if it imports here: one passphrase, both sides.
    mavproxy_signing = pytest.importorskip("MAVProxy.modules.mavproxy_signing")
    assert mavproxy_signing.SigningModule.passphrase_to_key(None, PASSPHRASE) == KEY


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("", "found 0"),
        ("one\ntwo\n", "found 2"),
        ("two words\n", "one word"),
        ("pässword\n", "one word"),
    ],
)
def test_bad_key_files_are_refused_naming_the_file(tmp_path, text, why):
    path = key_file(tmp_path, text)
    with pytest.raises(ConfigError, match=why) as exc:
        sg.read_key_file(path)
    assert str(path) in str(exc.value)
    with pytest.raises(ConfigError, match="not found"):
        sg.read_key_file(tmp_path / "missing.txt")


def test_state_file_is_written_atomically_private_and_read_back(tmp_path):
    path = tmp_path / "dir" / "signing-3.json"
    state = sg.SigningState(KEY, 123456789, 123000000, {(7, 255, 190): 122999999}, "SETUP_SIGNING")
    sg.save_state(path, state)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600  # it holds the key
    assert sg.load_state(path) == state
    assert os.listdir(path.parent) == ["signing-3.json"]  # no temporary file left behind
    assert sg.load_state(tmp_path / "none.json") is None
    path.write_text('{"format": "quadsitl-signing-1", "timestamp": -1}')
    with pytest.raises(ConfigError, match="timestamp"):
        sg.load_state(path)
    path.write_text("{not json")
    with pytest.raises(ConfigError, match=str(path)):
        sg.load_state(path)


def test_where_the_state_lives(tmp_path):
    opts = SigningOptions
    assert sg.default_state_file(opts(state_file="/x/s.json"), "/p/params.toml", 4) == sg.Path("/x/s.json")
    assert sg.default_state_file(opts(key_file="/k/key.txt"), "/p/params.toml", 4) == sg.Path(
        "/p/signing-4.json"
    )
    assert sg.default_state_file(opts(key_file="/k/key.txt"), None, 4) == sg.Path("/k/signing-4.json")
    assert sg.default_state_file(opts(), None, 4) is None


def test_mavlink_timestamp_is_10us_since_2015():
    assert mavlink_timestamp(sg.EPOCH_2015_S) == 0
    assert mavlink_timestamp(sg.EPOCH_2015_S + 1.5) == 150_000
    assert mavlink_timestamp(0.0) == 0  # a clock before 2015 (an unset RTC) is clamped


# -- the stack ------------------------------------------------------------------------------------------
def test_signed_commands_work_unsigned_ones_are_refused_and_counted(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path))
    gcs = stack.ground_station(API_LINK)
    stack.run_for(0.3)
    assert gcs.of_type("HEARTBEAT"), "a station without the key still sees the (signed) telemetry"

    # Unsigned: no ACK, counted, announced (rate-limited STATUSTEXT).
    assert send_and_wait(stack, gcs, command_frame(gcs, REQUEST_MESSAGE, 148), REQUEST_MESSAGE) == []
    gcs.heartbeat()
    stack.run_for(0.3)
    info = signing_info(stack)
    assert info["enabled"] and info["refused"] == {"unsigned": 2, "bad_signature": 0, "replayed": 0}
    assert info["refused_by_link"]["API"] == {"unsigned": 2}
    assert "signing: refused 1 unsigned message(s)" in gcs.statustext
    assert stack.autopilot.links[API_LINK].last_heartbeat_s is None  # the unsigned heartbeat did not count

    # Signed with the key: accepted, ACKed; the heartbeat counts.
    sign(gcs)
    acks = send_and_wait(stack, gcs, command_frame(gcs, REQUEST_MESSAGE, 148), REQUEST_MESSAGE)
    assert [a.result for a in acks] == [m.MAV_RESULT_ACCEPTED]
    gcs.heartbeat()
    stack.run_for(0.1)
    assert stack.autopilot.links[API_LINK].last_heartbeat_s is not None
    assert signing_info(stack)["refused"]["unsigned"] == 2


def test_everything_the_vehicle_sends_on_the_gcs_links_is_signed_in_order(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path))
    gcs, api = stack.ground_station(GCS_LINK), stack.ground_station(API_LINK)
    for station in (gcs, api):
        verify_incoming(station)  # pymavlink refuses unsigned, badly signed and out-of-order frames
        sign(station)
    # Telemetry, STATUSTEXT, COMMAND_ACK + the message asked for, PARAM_VALUE, mission protocol.
    api.command(REQUEST_MESSAGE, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    api.mav.param_request_read_send(stack.autopilot.system_id, 1, b"MIS_TAKEOFF_ALT", -1)
    api.mav.mission_request_list_send(stack.autopilot.system_id, 1, 0)
    api.command(ARM, 7)  # refused (param1 not a MAV_BOOL): a STATUSTEXT
    stack.run_for(1.0)
    for station in (gcs, api):
        kinds = {msg.get_type() for msg in station.messages}
        assert "BAD_DATA" not in kinds, [str(x) for x in station.messages if x.get_type() == "BAD_DATA"][:3]
        assert all(msg.get_signed() for msg in station.messages)
        assert sequence_gaps(station.messages) == []  # each link numbers (and so signs) its own frames
    kinds = {msg.get_type() for msg in api.messages}
    assert {"HEARTBEAT", "COMMAND_ACK", "AUTOPILOT_VERSION", "PARAM_VALUE", "MISSION_COUNT",
            "STATUSTEXT"} <= kinds  # fmt: skip


def test_the_hil_link_stays_unsigned(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path))
    core = stack.autopilot
    hello = [o for o in core.tick(0.0) if o.link == HIL_LINK]  # before any frame: hello to the simulator
    assert hello and all(o.data[2] & 1 == 0 for o in hello)  # MAVLink 2 incompat flags: not signed
    gcs_frames = [o for o in core.tick(1.5) if o.link != HIL_LINK]
    assert gcs_frames == [] or all(o.data[2] & 1 for o in gcs_frames)
    answer = core.on_hil_datagram(stack.sim.begin_frame(), 0.0)
    assert answer is not None and answer[2] & 1 == 0
    assert stack.sim.answer_to_frame(answer) is not None  # the simulator reads it as always


def test_wrongly_signed_and_replayed_frames_are_refused_and_counted(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path))
    gcs = stack.ground_station(API_LINK)
    stack.run_for(0.2)

    sign(gcs, key=passphrase_to_key("not-the-key"))
    assert send_and_wait(stack, gcs, command_frame(gcs, REQUEST_MESSAGE, 148), REQUEST_MESSAGE) == []
    assert signing_info(stack)["refused"]["bad_signature"] == 1

    sign(gcs)
    frame = command_frame(gcs, REQUEST_MESSAGE, 148)
    assert len(send_and_wait(stack, gcs, frame, REQUEST_MESSAGE)) == 1
    assert send_and_wait(stack, gcs, frame, REQUEST_MESSAGE) == []  # the same frame again: a replay
    assert signing_info(stack)["refused"]["replayed"] == 1

    # A new stream more than a minute behind the vehicle's clock: refused as old.
    late = stack.ground_station(API_LINK)
    sign(late, epoch_s=T0 + stack.t - 61.0)
    assert send_and_wait(stack, late, command_frame(late, REQUEST_MESSAGE, 148), REQUEST_MESSAGE) == []
    # ... less than a minute behind: accepted (the spec's window for new streams).
    sign(late, link_id=8, epoch_s=T0 + stack.t - 50.0)
    assert len(send_and_wait(stack, late, command_frame(late, REQUEST_MESSAGE, 148), REQUEST_MESSAGE)) == 1
    info = signing_info(stack)
    assert info["refused"] == {"unsigned": 0, "bad_signature": 1, "replayed": 2}
    assert any("1 badly signed" in t for t in gcs.statustext)


def test_a_forged_frame_with_a_high_timestamp_does_not_lock_a_station_out(tmp_path):
    """pymavlink 2.4's own check records a stream's timestamp before it checks the signature; the
    autopilot's records it only for a valid one."""
    stack = signing_stack(tmp_path, key_file(tmp_path))
    gcs = stack.ground_station(API_LINK)
    sign(gcs, link_id=5)
    assert len(send_and_wait(stack, gcs, command_frame(gcs, REQUEST_MESSAGE, 148), REQUEST_MESSAGE)) == 1
    attacker = stack.ground_station(API_LINK)  # same system/component ids and link id, wrong key
    sign(attacker, key=b"\x01" * 32, link_id=5, epoch_s=T0 + 10_000.0)
    assert send_and_wait(stack, attacker, command_frame(attacker, ARM, 1), ARM) == []
    assert len(send_and_wait(stack, gcs, command_frame(gcs, REQUEST_MESSAGE, 148), REQUEST_MESSAGE)) == 1
    assert not stack.autopilot.commander.armed


def test_the_accept_list_lets_radio_status_in_unsigned(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path))
    gcs = stack.ground_station(API_LINK)
    received = stack.autopilot.dispatcher.received
    gcs.mav.radio_status_send(200, 190, 80, 30, 20, 0, 0)  # from a SiK radio: unsigned
    stack.run_for(0.1)
    assert signing_info(stack)["accepted_unsigned"] == {"RADIO_STATUS": 1}
    assert received["unhandled"] == 1 and received["bad data"] == 0  # it got through to dispatch
    gcs.mav.radio_status_send(200, 190, 80, 30, 20, 0, 0)
    gcs.heartbeat()  # HEARTBEAT is not on the list
    stack.run_for(0.1)
    info = signing_info(stack)
    assert info["accepted_unsigned"] == {"RADIO_STATUS": 2} and info["refused"]["unsigned"] == 1
    assert sg.ACCEPT_UNSIGNED == {m.MAVLINK_MSG_ID_RADIO_STATUS: "RADIO_STATUS"}  # documented: keep short


def setup_signing(station, key: bytes, initial_timestamp: int) -> None:
    station.mav.setup_signing_send(station.stack.autopilot.system_id, 1, list(key), initial_timestamp)


def test_setup_signing_refused_while_armed_accepted_disarmed_and_zero_key_turns_it_off(tmp_path):
    stack = signing_stack(tmp_path)  # no key: signing off
    gcs = stack.ground_station(API_LINK)
    stack.run_for(0.5)
    assert not signing_info(stack)["enabled"]
    assert [a.result for a in send_and_wait(stack, gcs, command_frame(gcs, ARM, 1), ARM)] == [
        m.MAV_RESULT_ACCEPTED
    ]
    now_ts = mavlink_timestamp(T0 + stack.t)
    setup_signing(gcs, KEY, now_ts)  # as MAVProxy's "signing setup": the key, its wall clock
    stack.run_for(0.3)
    info = signing_info(stack)
    assert not info["enabled"] and info["setup_signing"] == {"refused_armed": 1}
    assert any("SETUP_SIGNING refused: the vehicle is armed" in t for t in gcs.statustext)
    assert not (tmp_path / "signing.json").exists()  # nothing to keep yet

    assert len(send_and_wait(stack, gcs, command_frame(gcs, ARM, 0), ARM)) == 1
    assert not stack.autopilot.commander.armed
    setup_signing(gcs, KEY, now_ts)
    sign(gcs)  # MAVProxy sets the key on its side right after sending SETUP_SIGNING
    stack.run_for(0.3)
    info = signing_info(stack)
    assert info["enabled"] and info["key_source"] == "SETUP_SIGNING"
    assert info["setup_signing"] == {"refused_armed": 1, "accepted": 1}
    assert "signing on: key set by SETUP_SIGNING" in gcs.statustext
    assert sg.load_state(tmp_path / "signing.json").key == KEY  # saved at once

    assert len(send_and_wait(stack, gcs, command_frame(gcs, REQUEST_MESSAGE, 148), REQUEST_MESSAGE)) == 1
    other = stack.ground_station(API_LINK)  # no key
    assert send_and_wait(stack, other, command_frame(other, REQUEST_MESSAGE, 148), REQUEST_MESSAGE) == []
    setup_signing(other, bytes(32), 0)  # an unsigned "signing off" is refused like any unsigned frame
    stack.run_for(0.2)
    assert signing_info(stack)["enabled"]

    setup_signing(gcs, bytes(32), 1)  # all-zero key with a timestamp: no key at all, refused
    stack.run_for(0.2)
    assert signing_info(stack)["setup_signing"]["refused_zero_key"] == 1 and signing_info(stack)["enabled"]
    setup_signing(gcs, bytes(32), 0)  # signed, all-zero key and timestamp 0: signing off
    stack.run_for(0.2)
    assert not signing_info(stack)["enabled"]
    assert "signing off (SETUP_SIGNING)" in gcs.statustext
    assert len(send_and_wait(stack, other, command_frame(other, REQUEST_MESSAGE, 148), REQUEST_MESSAGE)) == 1
    assert sg.load_state(tmp_path / "signing.json").key is None


def test_setup_signing_for_another_system_is_ignored(tmp_path):
    stack = signing_stack(tmp_path)
    gcs = stack.ground_station(API_LINK)
    gcs.mav.setup_signing_send(99, 1, list(KEY), mavlink_timestamp(T0))
    stack.run_for(0.2)
    assert not signing_info(stack)["enabled"] and signing_info(stack)["setup_signing"] == {}


@pytest.mark.parametrize("clean_stop", [True, False], ids=["clean stop", "killed"])
def test_key_and_timestamps_survive_a_restart(tmp_path, clean_stop):
    """The state file carries the key, the timestamp the vehicle signs with and the streams: after a
    restart a frame recorded before it is refused, the station goes on, the vehicle signs on past
    the stored timestamp. Killed (no save at stop): the periodic save (every SAVE_EVERY_S) covers
    what is older than it. No wall clock here: the state alone must carry it."""
    stack = signing_stack(tmp_path, clock=False)
    gcs = stack.ground_station(API_LINK)
    stack.run_for(0.2)
    setup_signing(gcs, KEY, mavlink_timestamp(T0))
    sign(gcs, epoch_s=T0)
    stack.run_for(0.2)
    recorded = command_frame(gcs, REQUEST_MESSAGE, 148)
    assert len(send_and_wait(stack, gcs, recorded, REQUEST_MESSAGE)) == 1
    stack.run_for(sg.SAVE_EVERY_S + 0.5)  # a periodic save happens in here
    sent = signing_info(stack)["timestamp"]
    if clean_stop:
        assert stack.autopilot.signing.save()  # what autopilot/app.py does when the process stops
    stored = sg.load_state(tmp_path / "signing.json")
    assert stored.key == KEY and stored.timestamp <= sent and stored.streams

    again = signing_stack(tmp_path, clock=False)  # the same state file
    info = signing_info(again)
    assert info["enabled"] and info["key_source"] == "SETUP_SIGNING"
    assert info["timestamp"] >= stored.timestamp + sg.RESTART_MARGIN  # never a timestamp used before
    station = again.ground_station(API_LINK)
    station.mav.signing = gcs.mav.signing  # the same ground station, signing on where it was
    verify_incoming(station)
    again.run_for(0.2)
    assert send_and_wait(again, station, recorded, REQUEST_MESSAGE) == []  # the replay after the restart
    assert signing_info(again)["refused"]["replayed"] == 1
    acks = send_and_wait(again, station, command_frame(station, REQUEST_MESSAGE, 148), REQUEST_MESSAGE)
    assert len(acks) == 1 and acks[0].get_signed()


def test_a_key_file_wins_over_the_stored_key_and_a_broken_state_file_stops_the_start(tmp_path):
    old = sg.SigningState(passphrase_to_key("old"), 5, 5, {}, "SETUP_SIGNING")
    sg.save_state(tmp_path / "signing.json", old)
    stack = signing_stack(tmp_path, key_file(tmp_path))
    assert stack.autopilot.signing.key == KEY
    assert signing_info(stack)["key_source"].startswith("key file ")
    assert sg.load_state(tmp_path / "signing.json").key == KEY
    (tmp_path / "signing.json").write_text("garbage")
    with pytest.raises(ConfigError, match="signing.json"):
        signing_stack(tmp_path, key_file(tmp_path))


def test_the_state_defaults_beside_the_key_file_and_without_either_nothing_is_written(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path), state=None)
    assert signing_info(stack)["state_file"] == str(tmp_path / "signing-0.json")
    assert sg.load_state(tmp_path / "signing-0.json").key == KEY

    bare = tmp_path / "bare"
    bare.mkdir()
    stack = signing_stack(bare, state=None)
    gcs = stack.ground_station(API_LINK)
    setup_signing(gcs, KEY, mavlink_timestamp(T0))  # on, in memory only
    stack.run_for(sg.SAVE_EVERY_S + 1.0)
    info = signing_info(stack)
    assert info["enabled"] and info["state_file"] is None and not stack.autopilot.signing.save()
    assert list(bare.iterdir()) == []


def test_info_is_json_and_never_holds_the_key(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path))
    text = json.dumps(stack.autopilot.info())
    assert KEY.hex() not in text and PASSPHRASE not in text


def test_the_timestamp_follows_the_wall_clock_and_a_jump_is_saved_at_once(tmp_path):
    stack = signing_stack(tmp_path, key_file(tmp_path))
    stack.run_for(1.0)
    core = stack.autopilot
    now_ts = mavlink_timestamp(T0 + stack.t)
    assert now_ts - sg.TICKS_PER_S < core.signing.timestamp <= now_ts + sg.TICKS_PER_S // 10  # ~ the clock
    saved = sg.load_state(tmp_path / "signing.json").timestamp
    core.setup.signing.epoch_clock.offset_s = 30.0  # the wall clock steps forward 30 s
    stack.run_for(0.1)
    assert core.signing.timestamp >= now_ts + 30 * sg.TICKS_PER_S
    assert sg.load_state(tmp_path / "signing.json").timestamp > saved + 29 * sg.TICKS_PER_S  # not 10 s later
