"""The fast lockstep decoder gives exactly what pymavlink's decoder gives, and refuses what it refuses."""

import math
import random

import pytest
from pymavlink.dialects.v20 import common as m

from quadcommon.mavlink_fast import DecodeError, FastDecoder, split_frames, with_sequence


def packed(msg, system=1, component=51):
    mav = m.MAVLink(None, srcSystem=system, srcComponent=component)
    return bytes(msg.pack(mav))


def random_odometry(rng):
    return m.MAVLink_odometry_message(
        rng.randrange(2**40),
        1,
        rng.choice((1, 12)),
        *(rng.uniform(-50, 50) for _ in range(3)),
        [rng.uniform(-1, 1) for _ in range(4)],
        *(rng.uniform(-5, 5) for _ in range(6)),
        [math.nan] + [rng.uniform(0, 1) for _ in range(20)],
        [math.nan] + [0.0] * 20,
        rng.randrange(256),
        6,
        rng.randrange(101),
    )


@pytest.mark.parametrize("seed", range(5))
def test_odometry_matches_pymavlink(seed):
    rng = random.Random(seed)
    msg = random_odometry(rng)
    frame = packed(msg)
    fast = FastDecoder(m.MAVLink_odometry_message)
    values = fast.unpack(frame)
    ref = m.MAVLink(None).decode(bytearray(frame))
    for name in m.MAVLink_odometry_message.fieldnames:
        got, want = values[fast.slices[name]], getattr(ref, name)
        if isinstance(want, list):
            assert list(got) == pytest.approx(want, nan_ok=True), name
        else:
            assert got == pytest.approx(want, nan_ok=True), name


def test_truncated_payload_is_zero_padded():
    """MAVLink 2 drops trailing zeros: an actuator message with zero controls is shorter."""
    msg = m.MAVLink_hil_actuator_controls_message(7, [0.25] + [0.0] * 15, 0, 0)
    frame = packed(msg)
    assert frame[1] < m.MAVLink_hil_actuator_controls_message.unpacker.size
    fast = FastDecoder(m.MAVLink_hil_actuator_controls_message)
    values = fast.unpack(frame)
    assert values[fast.slices["time_usec"]] == 7
    assert list(values[fast.slices["controls"]]) == [0.25] + [0.0] * 15
    assert values[fast.slices["mode"]] == 0


def test_refuses_bad_crc_wrong_message_and_garbage():
    fast = FastDecoder(m.MAVLink_hil_actuator_controls_message)
    frame = bytearray(packed(m.MAVLink_hil_actuator_controls_message(7, [0.5] * 16, 128, 1)))
    frame[12] ^= 0x10
    with pytest.raises(DecodeError, match="CRC"):
        fast.unpack(bytes(frame))
    with pytest.raises(DecodeError, match="message id"):
        fast.unpack(packed(m.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3)))
    with pytest.raises(DecodeError):
        fast.unpack(b"\xfd\x05garbage")


def test_split_frames_of_a_multi_message_datagram():
    a = packed(m.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3))
    b = packed(random_odometry(random.Random(1)))
    parts = split_frames(a + b + b"\x00junk")
    assert [msg_id for msg_id, _ in parts] == [m.MAVLINK_MSG_ID_HEARTBEAT, m.MAVLINK_MSG_ID_ODOMETRY]
    assert parts[0][1] == a and parts[1][1] == b


@pytest.mark.parametrize("seed", range(5))
def test_fast_encoder_frames_exactly_what_pymavlink_packs(seed):
    """Every per-frame message, random values: the same bytes as pymavlink's pack (truncation of
    trailing zeros, CRC extra, sequence numbers and ids included)."""
    from quadcommon.mavlink_fast import FastEncoder

    rng = random.Random(seed)
    messages = [
        random_odometry(rng),
        m.MAVLink_hil_sensor_message(rng.randrange(2**40), *(rng.uniform(-9, 9) for _ in range(13)),
                                     0x1FFF, 0),  # fmt: skip
        m.MAVLink_hil_state_quaternion_message(rng.randrange(2**40), [rng.uniform(-1, 1) for _ in range(4)],
                                               *(rng.uniform(-2, 2) for _ in range(3)),
                                               *(rng.randrange(-2**31, 2**31) for _ in range(3)),
                                               *(rng.randrange(-2**15, 2**15) for _ in range(3)),
                                               rng.randrange(2**16), rng.randrange(2**16),
                                               *(rng.randrange(-2**15, 2**15) for _ in range(3)),
                                               ),  # fmt: skip
        m.MAVLink_hil_actuator_controls_message(rng.randrange(2**40), [0.25] + [0.0] * 15, 129, 3),
        m.MAVLink_hil_actuator_controls_message(0, [0.0] * 16, 0, 0),  # all zero: one payload byte left
    ]
    for msg in messages:
        mav = m.MAVLink(None, srcSystem=7, srcComponent=51)
        mav.seq = rng.randrange(256)
        expected = bytes(msg.pack(mav))
        fast = FastEncoder(type(msg), 7, 51, template=msg)
        assert fast.frame(mav.seq) == expected, msg.get_type()


@pytest.mark.parametrize("seed", range(3))
def test_a_record_of_every_message_is_the_payload_struct_packs(seed):
    """record_dtype of every message of the dialect, filled with random values of its fields'
    types: its bytes are what the class's struct packs of the same values, and back."""
    import numpy as np

    from quadcommon.mavlink_fast import FastEncoder, record_dtype

    rng = np.random.default_rng(seed)
    classes = [c for c in vars(m).values() if isinstance(c, type) and issubclass(c, m.MAVLink_message)
               and getattr(c, "unpacker", None) is not None and c.unpacker.size > 0]  # fmt: skip
    assert len(classes) > 200
    for message_class in classes:
        dtype = record_dtype(message_class)
        record = np.frombuffer(rng.bytes(dtype.itemsize), dtype=dtype).copy()
        for name in dtype.names:  # no NaN payloads: a NaN is not equal to itself when compared back
            if record[name].dtype.kind == "f":
                record[name] = np.nan_to_num(record[name], nan=0.5, posinf=1.0, neginf=-1.0)
        values = message_class.unpacker.unpack(record.tobytes())
        assert message_class.unpacker.pack(*values) == record.tobytes(), message_class.msgname
        encoder = FastEncoder(message_class, 7, 51)
        encoder.values[:] = values
        assert encoder.buffer().tobytes() == record.tobytes(), message_class.msgname


def test_message_parts_read_the_same_payloads_framed_or_not():
    """A simulator frame with every message it sends (GPS, the disturbance report, the battery):
    what the autopilot reads of its datagram is what the in-process runner hands over unframed,
    byte for byte, and both name the simulator's component."""
    from autopilot.mavlink.hil import _BATTERY, _DISTURBANCE, _GPS, _ODOMETRY, _SENSOR, _STATE
    from quadcommon import wire
    from quadcommon.mavlink_fast import MessageParts
    from simulator.core import SimulatorCore, SimulatorSetup

    core = SimulatorCore(SimulatorSetup.load(scenario="circle", sensors="gps"))
    seen: set[int] = set()
    for _ in range(150):
        unframed = core.begin_frame_parts()
        framed = MessageParts.of_datagram(core.frame_datagram)
        assert framed.ids() == unframed.ids()
        for decoder in (_SENSOR, _STATE, _ODOMETRY, _GPS, _DISTURBANCE, _BATTERY):
            assert framed.payload(decoder) == unframed.payload(decoder)
            if decoder.msg_id in unframed:
                seen.add(decoder.msg_id)
                assert framed.component_id(decoder.msg_id) == wire.SIMULATOR_COMPONENT_ID
                assert unframed.component_id(decoder.msg_id) == wire.SIMULATOR_COMPONENT_ID
        core.end_frame(None)
    assert len(seen) == 6  # every kind of message crossed at least once


def test_message_parts_check_a_frame_when_it_is_read():
    from quadcommon.mavlink_fast import MessageParts

    odometry = FastDecoder(m.MAVLink_odometry_message)
    good = packed(m.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3), component=7)
    bad = bytearray(packed(random_odometry(random.Random(2))))
    bad[12] ^= 0x55
    parts = MessageParts.of_datagram(good + bytes(bad))  # split, not checked yet
    assert m.MAVLINK_MSG_ID_ODOMETRY in parts and parts.component_id(m.MAVLINK_MSG_ID_HEARTBEAT) == 7
    with pytest.raises(DecodeError, match="CRC"):
        parts.payload(odometry)
    assert parts.payload(FastDecoder(m.MAVLink_hil_gps_message)) is None  # none in the datagram
    assert parts.component_id(m.MAVLINK_MSG_ID_HIL_GPS) is None


KEY = bytes(range(32))


def parsed(data: bytes, key: bytes | None = None) -> list:
    """What a fresh pymavlink parser makes of ``data`` (checking signatures with ``key``)."""
    parser = m.MAVLink(None)
    parser.robust_parsing = True
    parser.signing.secret_key = key
    return parser.parse_buffer(data) or []


def signer(link_id: int = 4, timestamp: int = 123_456_789):
    mav = m.MAVLink(None, srcSystem=3, srcComponent=1)
    mav.signing.secret_key, mav.signing.sign_outgoing = KEY, True
    mav.signing.link_id, mav.signing.timestamp = link_id, timestamp
    return mav


def test_with_sequence_numbers_a_frame_again_crc_and_signature_included():
    msg = m.MAVLink_attitude_message(1000, 0.1, -0.2, 0.3, 0.0, 0.5, 0.0)
    frame = packed(msg, system=3, component=1)  # seq 0
    (again,) = parsed(with_sequence(frame, 200))
    assert again.get_type() == "ATTITUDE" and again.get_seq() == 200
    assert (again.time_boot_ms, again.roll, again.yawspeed) == (1000, pytest.approx(0.1), 0.0)

    signed = bytes(msg.pack(signer()))
    renumbered = with_sequence(signed, 17, KEY)
    (checked,) = parsed(renumbered, KEY)  # pymavlink checks the signature against the key
    assert checked.get_type() == "ATTITUDE" and checked.get_signed() and checked.get_seq() == 17
    assert renumbered[-13:-6] == signed[-13:-6]  # the same link id and timestamp
    assert renumbered[-6:] != signed[-6:]
    # Signed with another key, pymavlink refuses it: the check above is a real one.
    assert [x.get_type() for x in parsed(with_sequence(signed, 17, bytes(32)), KEY)] == ["BAD_DATA"]


def test_with_sequence_leaves_what_it_cannot_number_as_it_is():
    frame = packed(m.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
    unknown_id = bytearray(frame)
    unknown_id[7:10] = (0xFF, 0xFF, 0xFF)
    signed = bytes(m.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(signer()))
    mavlink1 = b"\xfe" + frame[1:]  # (MAVLink 1's start byte)
    for data in (b"", b"garbage", frame[:-1], frame + frame, mavlink1, bytes(unknown_id), signed):
        assert with_sequence(data, 9) is data  # (signed: no key to sign it again with)
    assert with_sequence(frame, 0) is frame  # already numbered so
