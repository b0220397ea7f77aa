"""The HIL link's lockstep rules on the autopilot's side (autopilot/mavlink/simulator_link.py), in
the caller's time: which frame is new, resent, a late copy or a restarted simulator's; when the
simulator counts as lost and found again; the hello's pace; the requests riding in the answer."""

from __future__ import annotations

import pytest

from autopilot.mavlink.codec import Encoder, new_parser
from autopilot.mavlink.simulator_link import HIL_HELLO_S, LATE_COPY_S, FrameOrder, SimulatorLink
from autopilot.params.definitions import default_parameters
from quadcommon import wire
from quadcommon.config import SIM_BATTERY_PARAMETERS

pytestmark = pytest.mark.timeout(30)

HOME = (47.397742, 8.545594, 488.0)


def new_link() -> SimulatorLink:
    return SimulatorLink(Encoder(1, wire.AUTOPILOT_COMPONENT_ID), 1, HOME)


def test_frames_in_order_resent_late_and_restarted():
    link = new_link()
    assert link.order(0, now=0.0) is FrameOrder.NEW
    assert link.arrived(0, now=0.0) == "linked"
    answer = link.answer(b"controls", lambda payload: b"<" + payload + b">")
    assert answer.datagram == b"<controls>" and link.last_answer is answer  # framed when sent
    assert link.order(0, now=0.001) is FrameOrder.AGAIN  # resent: the same answer again
    assert link.order(2000, now=0.002) is FrameOrder.NEW
    assert link.arrived(2000, now=0.002) is None
    assert link.frame_gap_s == pytest.approx(0.002)
    assert link.order(0, now=0.5) is FrameOrder.LATE  # a late copy of the first frame
    assert link.order(0, now=LATE_COPY_S + 0.5) is FrameOrder.RESTARTED  # t = 0 long after: a new run
    link.restart()
    assert link.order(0, now=LATE_COPY_S + 0.5) is FrameOrder.NEW


def test_the_simulator_is_lost_once_and_found_again():
    link = new_link()
    loss_s = 0.5
    assert link.silent(now=1.0, loss_s=loss_s) and not link.lose()  # never linked: nothing to lose
    link.arrived(0, now=1.0)
    link.arrived(2000, now=1.0)
    assert not link.silent(now=1.4, loss_s=loss_s)
    assert link.silent(now=1.6, loss_s=loss_s)
    assert link.lose() and not link.lose()  # said once
    assert link.order(0, now=1.7) is FrameOrder.RESTARTED  # lost: an older frame is a new run's
    link.restart()
    assert link.arrived(0, now=1.7) == "recovered" and not link.lost


def test_hello_until_frames_flow_at_its_pace():
    link = new_link()
    assert link.hello_due(0.0) and not link.hello_due(HIL_HELLO_S / 2) and link.hello_due(HIL_HELLO_S)


def test_the_requests_ride_in_the_answer_and_only_the_changed_sim_parameters_go():
    link = new_link()
    params = default_parameters()
    name = sorted(SIM_BATTERY_PARAMETERS)[0]
    link.forward_parameters(params)
    assert not link.requests.pending  # all at the vehicle file's values
    params.values[name] = params.specs[name].default + 1.0
    link.forward_parameters(params)
    assert link.request_failure(1, 1, 0, 0.0)
    answer = link.answer(b"", lambda payload: payload)
    parser = new_parser()
    messages = [parser.parse_char(bytes([byte])) for byte in answer.datagram]
    sent = [msg for msg in messages if msg is not None]
    assert [msg.get_type() for msg in sent] == ["PARAM_SET", "COMMAND_LONG"]
    assert sent[0].param_id == name and sent[0].target_component == wire.SIMULATOR_COMPONENT_ID
    while not link.requests.full:
        link.request_failure(1, 1, 0, 0.0)
    assert not link.request_failure(1, 1, 0, 0.0)  # bounded: refused when too many wait
