"""Faults on the links, in-process and in simulation time (quadcommon/impairment.py in
sitl/inprocess.py): the lockstep loses no frame to a lost, duplicated or reordered datagram, the
ground-station protocols complete over a lossy, slow link, and the link-loss failsafes fire when,
and only when, they should."""

import numpy as np
import pytest

from autopilot.control.config import load_controller
from autopilot.core import AutopilotCore, AutopilotSetup
from autopilot.mavlink.simulator_link import LATE_COPY_S
from gcs_scripts import fly_setpoints
from gcs_scripts.link import land_and_disarm
from gcs_scripts.upload_mission import MissionLink, items_from_list, same_item
from quadcommon.config import load_scenario
from quadcommon.impairment import ImpairConfig
from quadcommon.mavlink_fast import MessageParts
from quadcommon.trajectories import trajectory_from_spec
from quadcommon.wire import new_parser, parse_datagram
from simulator.core import SimulatorCore, SimulatorSetup
from sitl.inprocess import GCS_LINK, RunOptions, paper_stack

from ..stack import connect, make_stack

LATE_COPY = "HIL frame already answered (a late copy)"
GROUND_LOSSY = "loss=5%,delay=50ms,jitter=20ms"


def _fly(stack, seconds: float) -> None:
    for _ in range(round(seconds / stack.sim.dt_control)):
        stack.step()


# -- lockstep ---------------------------------------------------------------------------------------
@pytest.mark.timeout(120)
def test_the_papers_helix_is_bit_identical_under_hil_loss_duplication_and_reordering():
    scenario, controller = load_scenario("helix"), load_controller("intbs_nlhinf")
    impair = ImpairConfig(seed=1).with_specs(["hil:loss=5%,dup=1%,reorder=1%"])
    runs = []
    for options in (RunOptions(), RunOptions(impair=impair)):
        stack = paper_stack(scenario, controller, options)
        _fly(stack, scenario.duration_s)
        stack.final_frame()
        runs.append(stack)
    clean, lossy = runs
    assert len(lossy.truth_rows) == len(clean.truth_rows) == round(scenario.duration_s * 500) + 1
    assert np.array_equal(np.asarray(lossy.truth_rows), np.asarray(clean.truth_rows))
    controller = np.asarray(lossy.controller_rows), np.asarray(clean.controller_rows)
    assert np.array_equal(*controller, equal_nan=True)
    frames = lossy.frames
    links = lossy.impaired.info()
    assert 0.04 * frames < links["hil sim->ap"]["dropped"] < 0.06 * frames
    assert 0.04 * frames < links["hil ap->sim"]["dropped"] < 0.06 * frames
    # Each lost frame or answer cost one resend (a reordered one too: it came too late)
    assert lossy.sim.resends >= links["hil sim->ap"]["dropped"] + links["hil ap->sim"]["dropped"]
    assert lossy.sim.resends < 0.15 * frames  # 5 % + 1 % each way, resends lost too
    late = lossy.autopilot.info()["dropped"][LATE_COPY]  # duplicated and reordered frames, dropped
    assert late >= 0.5 * links["hil sim->ap"]["reordered"] > 0
    assert lossy.sim.info()["resends"] == lossy.sim.resends and clean.sim.resends == 0


def _cores(autostart: bool = True) -> tuple[SimulatorCore, AutopilotCore]:
    sim = SimulatorCore(SimulatorSetup.load(scenario="helix"))
    trajectory = trajectory_from_spec(sim.setup.scenario.trajectory) if autostart else None
    ap = AutopilotCore(AutopilotSetup(sim.setup.sitl, sim.setup.vehicle, load_controller("intbs_nlhinf"),
                                      autostart=trajectory, default_remotes=False))  # fmt: skip
    return sim, ap


def _frame(sim: SimulatorCore, ap: AutopilotCore, now: float) -> bytes:
    frame = sim.begin_frame()
    answer = ap.on_hil_datagram(frame, now)
    ap.after_frame()
    sim.end_frame(sim.answer_to_frame(answer))
    return frame


def test_a_resent_frame_is_answered_from_the_last_answer_without_stepping_twice():
    sim, ap = _cores()
    for k in range(10):
        _frame(sim, ap, 0.002 * k)
    sim.begin_frame()
    answer = ap.on_hil_datagram(sim.frame_datagram, 0.02)
    ap.after_frame()
    steps, rows = ap.frames, len(ap.controller_rows)
    ap.commander.disarm(ap.sim_time, force=True)  # even if the vehicle changed since: the same bytes
    again = ap.on_hil_datagram(sim.resend_frame(), 0.04)
    assert again == answer and ap.frames == steps and len(ap.controller_rows) == rows
    assert sim.resends == 1 and sim.answer_to_frame(again) is not None


def test_a_late_copy_is_dropped_an_out_of_date_answer_discarded_and_a_restart_still_recognised():
    sim, ap = _cores()
    first = _frame(sim, ap, 0.0)
    sim.begin_frame()
    old_answer = ap.on_hil_datagram(sim.frame_datagram, 0.002)
    sim.end_frame(sim.answer_to_frame(old_answer))
    _frame(sim, ap, 0.004)
    assert ap.commander.armed
    assert ap.on_hil_datagram(first, 0.3) is None  # a late copy of frame 0: not a restarted simulator
    assert ap.commander.armed and ap.info()["dropped"][LATE_COPY] == 1
    sim.begin_frame()
    assert sim.answer_to_frame(old_answer) is None  # the answer to frame 1 cannot end frame 3
    restarted = SimulatorCore(sim.setup)  # a new simulator: t = 0 again, long after our first frame
    assert ap.on_hil_datagram(restarted.begin_frame(), LATE_COPY_S + 0.5) is not None
    assert not ap.commander.armed and ap.simulator.last_time_usec == 0


@pytest.mark.timeout(60)
def test_every_frame_lost_the_simulator_descends_and_resumes_once_the_link_is_back():
    stack = paper_stack(load_scenario("helix"), load_controller("intbs_nlhinf"), RunOptions())
    _fly(stack, 3.0)
    stack.impair("hil:loss=100%")
    cut = stack.t
    while not stack.sim.emergency:
        stack.step()
    timeout = stack.sim.setup.sitl.lockstep_timeout_s
    assert stack.t - cut == pytest.approx(timeout, abs=0.01)  # the lockstep timeout, never a hang
    assert stack.sim.resends == pytest.approx(timeout / stack.sim.resend_after_s, abs=1)
    _fly(stack, 0.5)
    assert stack.sim.emergency and stack.autopilot.simulator.lost  # each side reports the other lost
    stack.impair("hil:none")
    _fly(stack, 0.1)
    assert not stack.sim.emergency and not stack.autopilot.simulator.lost


# -- ground-station protocols over a lossy, slow link -----------------------------------------------
@pytest.mark.timeout(120)
def test_fly_setpoints_completes_over_a_lossy_slow_api_link():
    stack = make_stack(impair=ImpairConfig(seed=2).with_specs([f"api:{GROUND_LOSSY}"]))
    args, setpoints = fly_setpoints.parse_args(["--setpoint", "1", "0.5", "2", "--hold", "1"])
    link = connect(stack)
    flight = fly_setpoints.Flight(link, args)
    flight.takeoff()
    stream = flight.start_offboard()
    flight.fly(1, setpoints[0])
    land_and_disarm(link, args.timeout, stream)
    assert not link.armed
    api = stack.impaired.info()
    assert api["api in"]["dropped"] > 0 and api["api out"]["dropped"] > 0


@pytest.mark.timeout(120)
def test_mission_upload_download_and_parameters_complete_over_a_lossy_slow_gcs_link():
    stack = make_stack(impair=ImpairConfig(seed=3).with_specs([f"gcs:{GROUND_LOSSY}"]))
    link = connect(stack, MissionLink, link=GCS_LINK)
    corners = [(0.0, 0.0, 2.0), (1.0, 0.0, 2.0), (1.0, 1.0, 2.0), (0.0, 1.0, 2.0)] * 5
    items = items_from_list({"frame": "paper", "items": [{"type": "takeoff", "altitude_m": 2.0}] + [
        {"type": "waypoint", "position": list(p)} for p in corners] + [{"type": "land"}]})
    link.upload(items)
    assert stack.autopilot.missions.protocol.mission.count == len(items) == 22
    downloaded = link.download()
    assert len(downloaded) == len(items) and all(map(same_item, downloaded, items))
    # Parameters as QGroundControl reads them: the whole list, then each one missing by index
    gcs = link.mav
    values: dict[int, float] = {}
    total = None
    gcs.param_request_list_send(stack.autopilot.system_id, 1)
    for _round in range(10):
        deadline = stack.t + 3.0
        while stack.t < deadline and (total is None or len(values) < total):
            msg = link.conn.recv_msg()
            if msg is not None and msg.get_type() == "PARAM_VALUE":
                total = msg.param_count
                values[msg.param_index] = msg.param_value
        if total is not None and len(values) == total:
            break
        if total is None:  # the request (or every answer) was lost: ask again
            gcs.param_request_list_send(stack.autopilot.system_id, 1)
        for index in sorted(set(range(total or 0)) - set(values))[:20]:
            gcs.param_request_read_send(stack.autopilot.system_id, 1, b"", index)
    assert total is not None and len(values) == total
    # A change confirmed by its PARAM_VALUE echo, resent until then
    for _attempt in range(10):
        gcs.param_set_send(stack.autopilot.system_id, 1, b"MPC_XY_VEL_MAX", 3.5, 9)
        deadline = stack.t + 0.5
        echo = None
        while stack.t < deadline and echo is None:
            msg = link.conn.recv_msg()
            if msg is not None and msg.get_type() == "PARAM_VALUE" and msg.param_id == "MPC_XY_VEL_MAX":
                echo = msg
        if echo is not None:
            break
    assert echo is not None and echo.param_value == pytest.approx(3.5)
    links = stack.impaired.info()
    assert links["gcs in"]["dropped"] + links["gcs out"]["dropped"] > 0 and links["gcs in"]["sent"] > 40


# -- link-loss failsafes ----------------------------------------------------------------------------
def _texts(link) -> list[str]:
    return [text for _, _, text in link.statustext]


def _offboard(stack):
    args, _ = fly_setpoints.parse_args(["--setpoint", "0", "0", "2"])
    link = connect(stack)
    flight = fly_setpoints.Flight(link, args)
    flight.takeoff()
    flight.start_offboard()
    return link


@pytest.mark.timeout(120)
def test_offboard_loss_fires_after_com_of_loss_t_when_the_api_link_dies_and_not_on_a_lossy_one():
    stack = make_stack(impair=ImpairConfig(seed=4).with_specs([f"api:{GROUND_LOSSY}"]))
    link = _offboard(stack)
    commander = stack.autopilot.commander
    link.sleep_sim(20.0)  # the stream goes on: 5 % of the setpoints lost, 50 ms late: no failsafe
    assert commander.mode.px4_name == "OFFBOARD"
    assert not any("offboard setpoints lost" in text for text in _texts(link))
    stack.impair("api:loss=100%")  # the script still streams: nothing arrives
    cut = stack.t
    while commander.mode.px4_name == "OFFBOARD" and stack.t < cut + 5.0:
        link.conn.recv_msg()
    last_setpoint = max(commander._setpoint_times)
    loss_t = stack.autopilot.params["COM_OF_LOSS_T"]
    assert commander.mode.px4_name == "AUTO.LOITER"
    assert cut - 0.2 < last_setpoint <= cut
    assert stack.t - last_setpoint == pytest.approx(loss_t, abs=0.01)  # COM_OF_LOSS_T after the last one


@pytest.mark.timeout(120)
def test_gcs_loss_fires_after_com_dl_loss_t_when_the_gcs_link_dies_and_not_on_a_lossy_one():
    stack = make_stack(impair=ImpairConfig(seed=5).with_specs([f"gcs:{GROUND_LOSSY}"]))
    ap = stack.autopilot
    assert ap.params.set("NAV_DLL_ACT", 3.0) is None  # land
    assert ap.params.set("COM_DL_LOSS_T", 5.0) is None
    gcs = stack.ground_station(GCS_LINK)
    beat = {"next": 0.0}

    def heartbeat(stack, t):  # 1 Hz, as QGroundControl
        if t >= beat["next"]:
            beat["next"] = t + 1.0
            gcs.heartbeat()

    args, _ = fly_setpoints.parse_args([])
    fly_setpoints.Flight(connect(stack), args).takeoff()  # on the API link; holding in the air
    failsafes = ap.commander.failsafes
    stack.run_for(30.0, script=heartbeat)  # 5 % of the heartbeats lost, 50 ms late: no failsafe
    assert not failsafes.link_lost and ap.commander.mode.px4_name == "AUTO.LOITER"
    stack.impair("gcs:loss=100%")
    cut = stack.t
    assert stack.run_for(10.0, script=heartbeat, until=lambda s: failsafes.link_lost)
    last = failsafes.last_gcs_heartbeat_s
    assert cut - 1.1 <= last <= cut
    assert stack.t - last == pytest.approx(5.0, abs=0.01)  # COM_DL_LOSS_T after the last heartbeat
    stack.step()
    assert ap.commander.mode.px4_name == "AUTO.LAND"
    assert any("GCS connection lost" in text for text in gcs.statustext) is False  # the link is dead


# -- a stream that stops ----------------------------------------------------------------------------
@pytest.mark.timeout(120)
def test_a_sensor_stream_that_stops_in_flight_is_announced_and_flown_through():
    """Flying the helix on the EKF over the GPS profile, HIL_GPS vanishes from the frames for 3 s:
    the autopilot says so after a second, the EKF dead reckons, the flight goes on, and the
    stream's return is announced too."""
    stack = paper_stack(load_scenario("helix"), load_controller("intbs_nlhinf"),
                        RunOptions(estimator="ekf", sensors="gps"))  # fmt: skip
    texts: list[str] = []
    stack.autopilot.log = lambda text: texts.append(text)
    parser, frame = new_parser(), stack.sim.begin_frame_parts
    cut = (6.0, 9.0)

    def begin_frame_parts() -> MessageParts:
        parts = frame()
        if cut[0] <= stack.sim.t < cut[1]:  # the GPS stream stops (and comes back)
            sent = parse_datagram(parser, stack.sim.frame_datagram)
            data = b"".join(bytes(msg.get_msgbuf()) for msg in sent if msg.get_type() != "HIL_GPS")
            parts = MessageParts.of_datagram(data)
        return parts

    stack.sim.begin_frame_parts = begin_frame_parts
    _fly(stack, 12.0)
    stopped = [t for t in texts if "sensor stream stopped: GPS (HIL_GPS)" in t]
    resumed = [t for t in texts if "sensor stream resumed: GPS (HIL_GPS)" in t]
    assert len(stopped) == 1 and len(resumed) == 1, texts
    t_stopped = float(stopped[0].split("[t=")[1].split("]")[0])
    assert cut[0] + 0.9 < t_stopped <= cut[0] + 1.05  # a second after the last fix (10 Hz)
    assert float(resumed[0].split("[t=")[1].split("]")[0]) == pytest.approx(cut[1], abs=0.11)
    assert stack.autopilot.commander.armed
    truth = np.asarray(stack.truth_rows)
    assert np.all(np.isfinite(truth)) and truth[-1][3] > 0.5  # still flying, no hang
    assert not any("stream stopped" in t and "GPS" not in t for t in texts)  # the others flowed on
