"""The parameter protocol (pure, against fake links): list/read/set, PX4's bytewise INT32
encoding including the signalling-NaN bit patterns, refusals, storage command."""

import struct

import pytest

from autopilot.control.config import load_controller
from autopilot.mavlink.codec import Encoder, mavlink, new_parser
from autopilot.mavlink.commands import CommandDispatcher, CommandRequest
from autopilot.mavlink.params import (
    LIST_BURST,
    ParamService,
    float32_shortest,
    int32_to_wire_float,
    pack_param_value,
    param_set_raw_value,
    wire_float_to_int32,
)
from autopilot.params.definitions import default_parameters
from autopilot.params.store import INT32, ParameterStore, ParamSpec
from quadcommon.config import load_sitl

m = mavlink
SYS = 3
GCS = ("127.0.0.1", 14553)
# int32 values whose bytes are a signalling NaN as float32: a float -> double conversion sets the
# quiet bit and changes them (0x7F800001 -> 0x7FC00001, -4194305 -> -1, ...).
SNAN_INTS = [0x7F800001, 0x7FBFFFFF, 2143289343, -8388607, -4194305, -4194304 - 1]
EDGE_INTS = [0, 1, -1, 2, 4001, 65536, 2**31 - 1, -(2**31), -4194304, 123456789]


class FakeLink:
    def __init__(self):
        self.peers = [GCS]
        self.sent: list[bytes] = []  # broadcast to peers
        self.sent_to: list[tuple[bytes, tuple]] = []

    def send(self, data):
        self.sent.append(data)

    def send_to(self, data, address):
        self.sent_to.append((data, address))

    def messages(self, which="all"):
        parser = new_parser()
        frames = []
        if which in ("all", "send"):
            frames += self.sent
        if which in ("all", "send_to"):
            frames += [d for d, _ in self.sent_to]
        out = []
        for frame in frames:
            out += parser.parse_buffer(frame) or []
        return out

    def clear(self):
        self.sent.clear()
        self.sent_to.clear()


def decode_value(msg):
    """A PARAM_VALUE's value from its raw bytes (as a careful client does)."""
    raw = param_set_raw_value(msg)  # value is the first payload field in PARAM_VALUE too
    if msg.param_type == m.MAV_PARAM_TYPE_INT32:
        return struct.unpack("<i", raw)[0]
    return struct.unpack("<f", raw)[0]


def param_set_frame(name, raw4: bytes, param_type, target=(SYS, 1)):
    """A PARAM_SET frame whose value field holds exactly ``raw4`` (pymavlink's pack would not)."""
    enc = Encoder(255, 190)
    msg = m.MAVLink_param_set_message(target[0], target[1], name.encode(), 0.0, param_type)
    payload = raw4 + struct.pack("<BB16sB", target[0], target[1], name.encode(), param_type)
    return msg._pack(enc.mav, msg.crc_extra, payload)


def parse_one(frame):
    return new_parser().parse_buffer(frame)[0]


@pytest.fixture
def service():
    store = default_parameters(load_controller("intbs_nlhinf"), load_sitl().rates)
    link = FakeLink()
    texts = []
    clock = [0.0]
    svc = ParamService(store, Encoder(SYS, 1), [link], lambda s, t: texts.append(t), SYS, 1,
                       clock=lambda: clock[0])  # fmt: skip
    svc.link, svc.texts, svc.clock_value = link, texts, clock
    return svc


def test_bytewise_int32_round_trip_through_the_wire_including_signalling_nans():
    enc = Encoder(SYS, 1)
    for value in EDGE_INTS + SNAN_INTS:
        frame = pack_param_value(enc, "TEST_INT", value, INT32, 5, 2)
        msg = parse_one(frame)
        assert msg.param_type == m.MAV_PARAM_TYPE_INT32 and (msg.param_count, msg.param_index) == (5, 2)
        assert decode_value(msg) == value, value
    # What naive float handling does to them (the reason for the raw bytes): not the same int.
    assert wire_float_to_int32(int32_to_wire_float(-4194305)) != -4194305
    assert wire_float_to_int32(int32_to_wire_float(4001)) == 4001
    assert int32_to_wire_float(1) == pytest.approx(1.4e-45)


def test_param_set_int_is_decoded_from_raw_bytes_including_signalling_nans():
    for value in EDGE_INTS + SNAN_INTS:
        msg = parse_one(param_set_frame("X", struct.pack("<i", value), m.MAV_PARAM_TYPE_INT32))
        assert struct.unpack("<i", param_set_raw_value(msg))[0] == value
    # MAVLink 2 strips trailing zero bytes; the value (first field) still decodes (0 here).
    msg = parse_one(param_set_frame("Y", struct.pack("<i", 0), m.MAV_PARAM_TYPE_INT32))
    assert struct.unpack("<i", param_set_raw_value(msg))[0] == 0


def test_signalling_nan_int_is_set_and_echoed_exactly():
    store = ParameterStore([ParamSpec("WIDE_INT", 0, -(2**31), 2**31 - 1, kind=INT32)])
    link = FakeLink()
    svc = ParamService(store, Encoder(SYS, 1), [link], lambda s, t: None, SYS, 1, clock=lambda: 0.0)
    for value in SNAN_INTS:
        link.clear()
        frame = param_set_frame("WIDE_INT", struct.pack("<i", value), m.MAV_PARAM_TYPE_INT32)
        svc.on_message(parse_one(frame), link, GCS)
        assert store["WIDE_INT"] == value
        (echo,) = link.messages("send")
        assert decode_value(echo) == value and echo.param_type == m.MAV_PARAM_TYPE_INT32


def test_float32_shortest():
    assert float32_shortest(struct.unpack("<f", struct.pack("<f", 0.3))[0]) == 0.3
    assert float32_shortest(4.5) == 4.5
    for v in (0.1, 1.7, 123.456, 1e-3, 2.5e7):
        shortest = float32_shortest(v)
        assert struct.pack("<f", shortest) == struct.pack("<f", v)


def test_request_list_streams_every_parameter_paced(service):
    link = service.link
    request = m.MAVLink_param_request_list_message(SYS, 1)
    service.on_message(request, link, GCS)
    first = link.messages()
    assert len(first) == LIST_BURST  # paced: the first burst only
    polls = 0
    while service.streaming and polls < 100:
        service.poll()
        polls += 1
    values = link.messages()
    count = len(service.store)
    assert len(values) == count and polls == -(-count // LIST_BURST) - 1
    assert [v.param_index for v in values] == list(range(count))
    assert all(v.param_count == count for v in values)
    assert [v.param_id for v in values] == service.store.names()
    assert all(addr == GCS for _, addr in link.sent_to)
    by_name = {v.param_id: v for v in values}
    assert by_name["MIS_TAKEOFF_ALT"].param_type == m.MAV_PARAM_TYPE_REAL32
    assert decode_value(by_name["MIS_TAKEOFF_ALT"]) == 2.5
    assert by_name["NAV_DLL_ACT"].param_type == m.MAV_PARAM_TYPE_INT32
    assert decode_value(by_name["GF_ACTION"]) == 2  # bytewise: the float field holds int 2's bytes
    assert decode_value(by_name["MAV_SYS_ID"]) == 1


def test_request_read_by_name_and_index(service):
    link = service.link
    service.on_message(m.MAVLink_param_request_read_message(SYS, 1, b"NLH_W3", -1), link, GCS)
    service.on_message(m.MAVLink_param_request_read_message(SYS, 1, b"", 0), link, GCS)
    a, b = link.messages()
    assert (a.param_id, decode_value(a), a.param_index) == ("NLH_W3", 9.0, service.store.index("NLH_W3"))
    assert (b.param_id, b.param_index) == ("MIS_TAKEOFF_ALT", 0)
    link.clear()
    service.on_message(m.MAVLink_param_request_read_message(SYS, 1, b"NOPE", -1), link, GCS)
    service.on_message(m.MAVLink_param_request_read_message(SYS, 1, b"", 999), link, GCS)
    assert link.messages() == []
    assert "unknown parameter 'NOPE'" in service.texts[0] and "index 999" in service.texts[1]
    # Addressed to another system: ignored.
    service.on_message(m.MAVLink_param_request_read_message(SYS + 1, 1, b"NLH_W3", -1), link, GCS)
    assert link.messages() == []


def test_set_float_and_int_are_applied_and_echoed(service):
    link, store = service.link, service.store
    service.on_message(parse_one(param_set_frame("NLH_W3", struct.pack("<f", 4.7), 9)), link, GCS)
    assert store["NLH_W3"] == 4.7  # the shortest decimal of float32(4.7)
    (echo,) = link.messages()
    assert echo.param_id == "NLH_W3" and echo.param_type == 9
    assert struct.pack("<f", decode_value(echo)) == struct.pack("<f", 4.7)  # exactly what was sent
    link.clear()
    service.on_message(parse_one(param_set_frame("NAV_DLL_ACT", struct.pack("<i", 1), 6)), link, GCS)
    assert store["NAV_DLL_ACT"] == 1.0
    (echo,) = link.messages()
    assert echo.param_type == 6 and decode_value(echo) == 1
    assert service.texts == []


@pytest.mark.parametrize(
    "name, raw, ptype, reason",
    [
        ("MIS_TAKEOFF_ALT", struct.pack("<f", 500.0), 9, "out of range [0.2, 100] m"),
        ("NAV_DLL_ACT", struct.pack("<f", 1.0), 9, "type 9 refused, it is INT32"),
        ("MIS_TAKEOFF_ALT", struct.pack("<i", 3), 6, "type 6 refused, it is REAL32"),
        ("GF_ACTION", struct.pack("<i", 4), 6, "flight termination is not supported"),
        ("SITL_CTRL_HZ", struct.pack("<f", 250.0), 9, "read-only"),
        ("NLH_W1", struct.pack("<f", float("nan")), 9, "not finite"),
    ],
)
def test_refused_set_keeps_the_value_echoes_it_and_says_why(service, name, raw, ptype, reason):
    link, store = service.link, service.store
    old = store[name]
    service.on_message(parse_one(param_set_frame(name, raw, ptype)), link, GCS)
    assert store[name] == old
    (echo,) = link.messages()
    assert echo.param_id == name and decode_value(echo) == pytest.approx(old)
    assert echo.param_type == (6 if store.specs[name].kind == INT32 else 9)
    (text,) = service.texts
    assert text.startswith("param set refused:") and reason in text


def test_unknown_name_gets_a_statustext_only_and_retries_are_not_repeated(service):
    link = service.link
    for _ in range(5):  # MAVSDK resends
        service.on_message(parse_one(param_set_frame("NOPE", struct.pack("<f", 1.0), 9)), link, GCS)
    assert link.messages() == []
    assert service.texts == ["param set refused: unknown parameter 'NOPE'"]
    service.clock_value[0] = 5.0
    service.on_message(parse_one(param_set_frame("NOPE", struct.pack("<f", 1.0), 9)), link, GCS)
    assert len(service.texts) == 2


def request(command, *params):
    p = list(params) + [0.0] * (7 - len(params))
    return CommandRequest(command, tuple(p), None, 255, 190, FakeLink(), GCS)


def test_preflight_storage_save_load_reset(tmp_path):
    path = tmp_path / "p.toml"
    store = default_parameters(load_controller("intbs"), load_sitl().rates)
    link, texts = FakeLink(), []
    svc = ParamService(store, Encoder(SYS, 1), [link], lambda s, t: texts.append(t), SYS, 1, path,
                       clock=lambda: 0.0)  # fmt: skip
    commands = CommandDispatcher()
    svc.register({}, commands)
    store.set("ATT_KI_R", 50.0)  # autosaved
    assert "ATT_KI_R = 50.0" in path.read_text()
    store.values["ATT_KI_R"] = 70.0  # (behind the service's back: not saved)
    result, _ = commands.dispatch(request(m.MAV_CMD_PREFLIGHT_STORAGE, 0))  # load
    assert result == m.MAV_RESULT_ACCEPTED and store["ATT_KI_R"] == 50.0
    assert [v.param_id for v in link.messages()] == ["ATT_KI_R"]  # changes announced
    result, _ = commands.dispatch(request(m.MAV_CMD_PREFLIGHT_STORAGE, 2))  # defaults
    assert result == m.MAV_RESULT_ACCEPTED and store["ATT_KI_R"] == 90.0
    assert "ATT_KI_R = 90.0" in path.read_text()
    store.set("ATT_KI_R", 60.0)
    result, _ = commands.dispatch(request(m.MAV_CMD_PREFLIGHT_STORAGE, 1))  # save
    assert result == m.MAV_RESULT_ACCEPTED and "ATT_KI_R = 60.0" in path.read_text()
    path.write_text("ATT_KI_R = -3.0\n")  # a bad file: refused, nothing changes
    result, reason = commands.dispatch(request(m.MAV_CMD_PREFLIGHT_STORAGE, 0))
    assert result == m.MAV_RESULT_DENIED and "ATT_KI_R" in reason and store["ATT_KI_R"] == 60.0


def test_preflight_storage_without_a_file_is_denied(service):
    commands = CommandDispatcher()
    service.register({}, commands)
    result, reason = commands.dispatch(request(m.MAV_CMD_PREFLIGHT_STORAGE, 1))
    assert result == m.MAV_RESULT_DENIED and "--params FILE" in reason
