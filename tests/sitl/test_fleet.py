"""A fleet in one process (sitl/fleet.py): a vehicle flies in a fleet exactly as it flies alone;
each vehicle answers on its own ports as PX4 numbers them, one ground station on the GCS port sees
them all, and a client on one vehicle's API port drives that vehicle alone; over several
processes (sitl/fleet_processes.py) a lost one is restarted while the others fly on."""

from __future__ import annotations

import math
import os
import re
import resource
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as m

from autopilot.mavlink.links import API_LINK
from quadcommon import bus, frames, wire
from quadcommon.failures import Type, Unit
from sitl.fleet import Fleet, FleetOptions, VehicleLines, make_vehicle, room_for_files
from sitl.launcher import Child
from tests.compat.vehicles import run_flow
from tests.ports import block_config_dir, instance_ports
from tests.sitl.harness import ZenohTap
from tests.sitl.test_up_cli import children_of

pytestmark = pytest.mark.timeout(240)

CIRCLE = FleetOptions(scenario="circle", autostart="circle")  # armed at t = 0, flying the paper's circle
IDLE = FleetOptions(scenario="hover")  # on the ground, disarmed


def test_a_vehicle_flies_in_a_fleet_of_20_as_it_flies_alone():
    """Instance 7 flying the paper's circle under its gusts, alone and among 19 others (half of
    them flying the circle, half idle on the ground): the same truth, bit for bit, every frame."""
    frames = 1500  # 3 s: the climb onto the circle and the first gust
    alone = make_vehicle(7, CIRCLE)
    alone.stack.record_rows = True
    for _ in range(frames):
        alone.stack.step()
    fleet = Fleet([make_vehicle(n, CIRCLE if n % 2 else IDLE) for n in range(20)])
    ours = fleet.vehicles[7]
    ours.stack.record_rows = True
    for _ in range(frames):
        fleet.step()
    assert fleet.t == pytest.approx(alone.stack.t)
    assert len(ours.stack.truth_rows) == len(alone.stack.truth_rows) == frames
    assert ours.stack.truth_rows == alone.stack.truth_rows
    climbed = [row for row in alone.stack.truth_rows if row[3] > 0.5]  # (t, x, y, z, ...): it flew
    assert climbed
    idle = fleet.vehicles[6].stack
    assert not idle.autopilot.commander.armed


def fly_with_battery_failure(vehicle, frames: int, inject_at: int, step) -> list[str]:
    """Fly ``frames`` with ``step()``; at frame ``inject_at`` a ground station on the vehicle's API
    link injects PX4's battery failure (``failure battery off``) with COM_LOW_BAT_ACT 3 (the
    emergency level lands). What the vehicle said (STATUSTEXT), in order."""
    stack = vehicle.stack
    stack.record_rows = True
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    stack.autopilot.params.set("COM_LOW_BAT_ACT", 3.0)
    gcs = stack.ground_station(API_LINK)
    for frame in range(frames):
        if frame == inject_at:
            gcs.command(m.MAV_CMD_INJECT_FAILURE, Unit.battery, Type.off, 0)
        step()
    assert [ack.result for ack in gcs.acks(m.MAV_CMD_INJECT_FAILURE)] == [m.MAV_RESULT_ACCEPTED]
    return gcs.statustext


def test_a_failsafe_acts_in_a_fleet_as_it_acts_alone():
    """Instance 1 flying the circle loses its battery monitor in flight (PX4's failure injection):
    alone and in a fleet of 3 it announces the emergency-battery failsafe, lands and disarms, and its truth is
    the same bit for bit; the other vehicles fly on untouched."""
    frames, inject_at = 5000, 500  # the failure 1 s into the circle; 9 s after it
    alone = make_vehicle(1, CIRCLE)
    said_alone = fly_with_battery_failure(alone, frames, inject_at, alone.stack.step)
    fleet = Fleet([make_vehicle(n, CIRCLE) for n in range(3)])
    ours = fleet.vehicles[1]
    said = fly_with_battery_failure(ours, frames, inject_at, fleet.step)
    landing = "Failsafe activated due to emergency battery level, triggering land"
    assert landing in "".join(said_alone) and "landed: disarmed" in said_alone
    assert said == said_alone
    assert ours.stack.truth_rows == alone.stack.truth_rows
    heights = [row[3] for row in ours.stack.truth_rows]  # (t, x, y, z, ...)
    assert max(heights) > 0.5 and heights[-1] < 0.05  # it climbed, and came down
    assert not ours.stack.autopilot.commander.armed
    neighbour = fleet.vehicles[2].stack.autopilot.commander
    assert neighbour.armed and not neighbour.in_failsafe


def heartbeat_senders(conn, wall_s: float) -> set[int]:
    """The system ids heard on ``conn`` within ``wall_s`` of wall time."""
    heard: set[int] = set()
    deadline = time.monotonic() + wall_s
    while time.monotonic() < deadline:
        msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
        if msg is not None and msg.get_srcComponent() == 1:
            heard.add(msg.get_srcSystem())
    return heard


def relative_altitude(conn, system_id: int, wall_s: float = 5.0) -> float:
    """The next GLOBAL_POSITION_INT's relative altitude (m) from ``system_id``."""
    deadline = time.monotonic() + wall_s
    while time.monotonic() < deadline:
        msg = conn.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=0.2)
        if msg is not None and msg.get_srcSystem() == system_id:
            return msg.relative_alt * 1e-3
    raise AssertionError(f"no GLOBAL_POSITION_INT from system {system_id}")


def command(conn, target: int, command_id: int, *params: float, wall_s: float = 20.0) -> None:
    """COMMAND_LONG to ``target`` until it is accepted (a vehicle refuses to arm until its checks
    pass); AssertionError with the last refusal after ``wall_s``."""
    p = list(params) + [0.0] * (7 - len(params))
    deadline, last = time.monotonic() + wall_s, None
    while time.monotonic() < deadline:
        conn.mav.command_long_send(target, 1, command_id, 0, *p)
        ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.5)
        if ack is not None and ack.get_srcSystem() == target and ack.command == command_id:
            if ack.result == m.MAV_RESULT_ACCEPTED:
                return
            last = ack.result
    raise AssertionError(f"command {command_id} to system {target} not accepted (last result {last})")


def fleet_child_of(supervisor_pid: int, instance: int) -> int:
    """The fleet process (a child of the supervisor) flying ``instance`` first (Linux /proc)."""
    for pid in children_of(supervisor_pid):
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"--instance" in cmdline and cmdline[cmdline.index(b"--instance") + 1] == str(instance).encode():
            return pid
    raise AssertionError(f"no fleet process for instance {instance} under {supervisor_pid}")


@pytest.mark.processes
def test_a_fleet_in_two_processes_driven_by_mavsdk_and_pymavlink_a_lost_process_restarted():
    """`quadsitl fleet --count 2 --processes 2` (instances 12 and 13): on the GCS port both system
    ids. At the same time MAVSDK flies vehicle 0 through its API port (discovery, health, arm, take
    off, land, disarm: the flow a PX4 user's first script is) and a pymavlink client arms vehicle 1
    and takes it off through its own: each vehicle does what its own client said and nothing the
    other's did. Past instance 9 PX4 sends every API link to one port (14549), so both clients talk
    to their vehicle's own API link (``udpout``, :func:`quadcommon.wire.api_connect_url`).
    `quadsitl mission download --instance 12-13` reads both vehicles' missions side by side.
    Vehicle 0's process killed: it is restarted (its vehicle back on the GCS port) while vehicle 1
    flies on."""
    first = 12
    ports = [instance_ports(first), instance_ports(first + 1)]
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{ports[0].gcs_remote}", source_system=255)
    api = mavutil.mavlink_connection(f"udpout:127.0.0.1:{ports[1].api_local}", source_system=245)
    quadsitl = [sys.executable, "-u", "-m", "sitl.cli"]
    child = Child("quadsitl fleet", [*quadsitl, "fleet", "--count", "2", "--instance", str(first),
                                     "--speed", "4", "--processes", "2"])  # fmt: skip
    mavsdk: list = []
    try:
        child.wait_line("[0] fleet: 1 vehicles, instances", timeout=60.0)
        child.wait_line("[1] fleet: 1 vehicles, instances", timeout=60.0)
        assert heartbeat_senders(gcs, 3.0) == {first + 1, first + 2}  # system id = instance + 1
        url = wire.api_connect_url(ports[0], first)
        assert url.startswith("udpout://127.0.0.1:")
        flying = threading.Thread(target=lambda: mavsdk.append(run_flow("action", url, 50.0)), daemon=True)
        flying.start()
        target = first + 2
        api.mav.heartbeat_send(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0)  # (talks first: udpout)
        assert api.wait_heartbeat(timeout=10.0).get_srcSystem() == target
        command(api, target, m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        nan = float("nan")
        command(api, target, m.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0, nan, nan, nan, 3.0)
        deadline = time.monotonic() + 30.0
        while relative_altitude(gcs, target) < 1.5:
            assert time.monotonic() < deadline, "vehicle 1 did not climb"
        flying.join(60.0)
        (flow,) = mavsdk
        assert flow.returncode == 0 and not flow.timed_out, flow.transcript()
        assert flow.event("discovered")["sysid"] == first + 1  # vehicle 0's port: vehicle 0
        assert flow.event("took_off") and flow.event("disarmed")  # up to 2.5 m, down, disarmed
        assert relative_altitude(gcs, target) > 1.5  # vehicle 1 flew on: MAVSDK's land was not for it

        missions = subprocess.run([*quadsitl, "mission", "download", "--instance", f"{first}-{first + 1}"],
                                  capture_output=True, text=True, timeout=60.0)  # fmt: skip
        assert missions.returncode == 0, missions.stdout + missions.stderr
        for n in (first, first + 1):
            assert f"[{n}] QGC WPL 110" in missions.stdout.splitlines(), missions.stdout  # (empty)
        assert f"instances {first}..{first + 1}: all 2 succeeded" in missions.stdout

        os.kill(fleet_child_of(child.pid, first), signal.SIGKILL)
        child.wait_line(f"fleet process 0 (instances {first}..{first}) lost: killed by SIGKILL", timeout=10.0)
        child.wait_line("fleet process 0 relinked", timeout=60.0)
        assert first + 1 in heartbeat_senders(gcs, 2.0)  # vehicle 0 is back
        assert relative_altitude(gcs, target) > 1.5  # vehicle 1 flew on
    finally:
        child.stop()
        gcs.close()
        api.close()
    assert child.returncode == 0, child.tail()


def test_a_vehicle_whose_frame_fails_is_restarted_on_the_ground_and_the_others_fly_on():
    """Vehicle 0's plant diverges (its state made NaN): it is reported and replaced by a new one on
    the ground, disarmed; vehicle 1 flies on as if nothing happened."""
    said: list[str] = []
    fleet = Fleet([make_vehicle(n, CIRCLE) for n in range(2)], said.append,
                  restart=lambda n: make_vehicle(n, IDLE))  # fmt: skip
    alone = make_vehicle(1, CIRCLE)
    alone.stack.record_rows = fleet.vehicles[1].stack.record_rows = True
    for _ in range(300):
        fleet.step()
    broken = fleet.vehicles[0]
    broken.stack.sim.plant.state = [float("nan")] * len(broken.stack.sim.plant.state)
    for _ in range(300):
        fleet.step()
    for _ in range(600):
        alone.stack.step()
    assert fleet.restarts == {0: 1}
    assert len(said) == 1 and said[0].startswith("vehicle 0 lost (PlantDiverged: ") and "restarted" in said[0]
    restarted = fleet.vehicles[0]
    assert restarted is not broken and not restarted.stack.autopilot.commander.armed
    assert restarted.stack.frames > 0  # it flies its own frames from its own t = 0
    assert fleet.vehicles[1].stack.truth_rows == alone.stack.truth_rows


def test_a_restarted_vehicle_comes_back_with_the_parameters_it_was_given(tmp_path):
    """`--params DIR/params-{instance}.toml`: a PARAM_SET to vehicle 0 is saved in its own file;
    its plant diverges, and the vehicle that replaces it starts from that file (vehicle 1's file
    is not touched)."""
    template = str(tmp_path / "params-{instance}.toml")
    options = replace(IDLE, params=template)
    fleet = Fleet([make_vehicle(n, options) for n in range(2)], restart=lambda n: make_vehicle(n, options))
    gcs = fleet.vehicles[0].stack.ground_station(API_LINK)
    gcs.mav.param_set_send(1, 1, b"MPC_XY_VEL_MAX", 7.5, m.MAV_PARAM_TYPE_REAL32)
    for _ in range(50):
        fleet.step()
    assert gcs.last["PARAM_VALUE"].param_id == "MPC_XY_VEL_MAX" and gcs.last["PARAM_VALUE"].param_value == 7.5
    assert "MPC_XY_VEL_MAX" in (tmp_path / "params-0.toml").read_text()
    assert not (tmp_path / "params-1.toml").exists()
    broken = fleet.vehicles[0]
    broken.stack.sim.plant.state = [float("nan")] * len(broken.stack.sim.plant.state)
    for _ in range(5):
        fleet.step()
    assert fleet.restarts == {0: 1} and fleet.vehicles[0] is not broken
    assert fleet.vehicles[0].stack.autopilot.params.values["MPC_XY_VEL_MAX"] == 7.5
    assert fleet.vehicles[1].stack.autopilot.params.values["MPC_XY_VEL_MAX"] != 7.5


def test_a_fleet_vehicle_streams_its_truth_on_its_zenoh_keys():
    """`--zenoh`: each vehicle's truth on ``quadsitl/<N>/truth`` as its simulator process streams
    it (a recorder or the live view subscribes there): every frame's row, the same numbers."""
    fleet = Fleet([make_vehicle(n, CIRCLE) for n in (5, 6)], zenoh=True, speed=None)
    fleet.open()
    tap = None
    try:
        ours = fleet.vehicles[1]
        tap = ZenohTap(6, "truth")
        assert bus.wait_matching(ours.sim_bus.truth.publisher, 10.0)
        ours.stack.record_rows = True
        for _ in range(500):
            fleet.step()
        ours.sim_bus.truth.flush()
        deadline = time.monotonic() + 10.0
        while len(tap.rows()) < 500 and time.monotonic() < deadline:
            time.sleep(0.01)
        np.testing.assert_array_equal(tap.rows(), np.array(ours.stack.truth_rows))
    finally:
        if tap is not None:
            tap.close()
        fleet.close()


@pytest.mark.processes
def test_two_fleet_launches_meet_through_a_router_and_one_recorder_records_both(tmp_path):
    """Across hosts, shown on loopback: `quadsitl router` and two fleet launches (instances 10 and
    20) whose sitl.toml names it; a client of the router hears both vehicles' truth, and one
    `quadsitl record --instance 10,20` records each vehicle (its MAVLink from the one ground-station
    port, its truth and rows through the router) into a recording of its own."""
    endpoint = f"tcp/127.0.0.1:{instance_ports(240).zenoh}"  # a port of this test's block
    config = tmp_path / "config"
    config.mkdir()
    text = (block_config_dir() / "sitl.toml").read_text()
    (config / "sitl.toml").write_text(re.sub(r"(?m)^router\s*=.*$", f'router = "{endpoint}"', text))
    quadsitl = [sys.executable, "-u", "-m", "sitl.cli"]
    children = [Child("router", [*quadsitl, "router", "--listen", endpoint])]
    session = None
    try:
        children[0].wait_line("router: listening", timeout=20.0)
        for n in (10, 20):
            launch = [*quadsitl, "--config-dir", str(config), "fleet", "--count", "1", "--instance", str(n),
                      "--zenoh", "--speed", "2"]  # fmt: skip
            children.append(Child(f"fleet {n}", launch))
        for child in children[1:]:
            child.wait_line("vehicles, instances", timeout=60.0)
        session = bus.open_peer(0, router=endpoint)
        import zenoh

        sub = session.declare_subscriber("quadsitl/*/truth", zenoh.handlers.FifoChannel(10_000))
        heard: set[str] = set()
        deadline = time.monotonic() + 20.0
        while heard != {"quadsitl/10/truth", "quadsitl/20/truth"} and time.monotonic() < deadline:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.01)
            else:
                heard.add(str(sample.key_expr))
        assert heard == {"quadsitl/10/truth", "quadsitl/20/truth"}

        # One recorder for the whole fleet: `quadsitl record --instance 10,20` through the router.
        recording = subprocess.run([*quadsitl, "--config-dir", str(config), "record", "--instance", "10,20",
                                    "--out", str(tmp_path / "fleet-{instance}"), "--duration", "2"],
                                   capture_output=True, text=True, timeout=60.0)  # fmt: skip
        assert recording.returncode == 0, recording.stdout + recording.stderr
        for n in (10, 20):
            assert f"record: [{n}] stopped (duration 2 s)" in recording.stdout, recording.stdout
            table = pq.read_table(tmp_path / f"fleet-{n}.parquet")
            assert table.num_rows >= 900  # 2 s at 500 Hz
            assert set(table.column("x_m").to_pylist()) != {None}  # the truth joined in
            tlog = mavutil.mavlink_connection(str(tmp_path / f"fleet-{n}.tlog"))
            senders = set()
            while (msg := tlog.recv_match()) is not None:
                senders.add(msg.get_srcSystem())
            tlog.close()
            assert senders == {n + 1}  # its own vehicle's messages, the other's left out
    finally:
        if session is not None:
            session.close()
        for child in reversed(children):
            child.stop()
    assert all(child.returncode == 0 for child in children), [child.tail() for child in children]


def test_one_parameter_file_for_several_vehicles_is_refused(capsys):
    from sitl.fleet import main

    with pytest.raises(SystemExit) as info:
        main(["--count", "2", "--params", "params.toml"])
    assert info.value.code == 2
    assert "--params params.toml: with --count 2 the path must contain {instance}" in capsys.readouterr().err


def test_what_the_vehicles_say_alike_at_start_is_one_line():
    """100 vehicles linking print one line, not 100; after the start each line as it comes."""
    out: list[str] = []
    lines = VehicleLines(out.append)
    for n in (0, 1, 2, 3, 7):
        lines.say(n, "signing off")
    for n in (0, 1, 2, 3, 7):
        lines.say(n, "linked with simulator")
    lines.say(2, "a parameter file loaded")
    assert out == []
    lines.flush()
    assert out == ["[0..3, 7] signing off", "[0..3, 7] linked with simulator", "[2] a parameter file loaded"]
    lines.say(7, "vehicle lost")
    assert out[-1] == "[7] vehicle lost"


def test_spaced_homes_put_the_vehicles_apart_on_the_map_and_fly_them_as_alone():
    """`--spacing 3`: instance N's home 3 N m north of the configured one, as PX4's multi-vehicle
    SITL spawns its instances. A ground station reads the vehicles 3 m apart (GLOBAL_POSITION_INT,
    HOME_POSITION), while each flies its local frame as it does at the configured home."""
    spaced = replace(CIRCLE, spacing_m=3.0)
    fleet = Fleet([make_vehicle(n, spaced) for n in (4, 5)])
    stations = [vehicle.stack.ground_station(API_LINK) for vehicle in fleet.vehicles]
    fleet.vehicles[1].stack.record_rows = True
    for _ in range(500):
        fleet.step()
    alone = make_vehicle(5, CIRCLE)
    stations.append(alone.stack.ground_station(API_LINK))
    alone.stack.record_rows = True
    for _ in range(500):
        alone.stack.step()
    assert fleet.vehicles[1].stack.truth_rows == alone.stack.truth_rows  # the same local flight
    metres_per_degree = frames.EARTH_RADIUS_M * math.pi / 180.0  # (PX4's projection's radius)
    north, lon = [], []
    for station in stations:  # each station's latest report was sent at the same time of the flight
        position = station.last["GLOBAL_POSITION_INT"]
        north.append(position.lat * 1e-7 * metres_per_degree)
        lon.append(position.lon)
    assert north[1] - north[0] == pytest.approx(3.0, abs=0.02)  # instances 4 and 5: 3 m apart
    assert north[1] - north[2] == pytest.approx(15.0, abs=0.02)  # instance 5: 5 x 3 m from home
    assert abs(lon[1] - lon[0]) <= 1 and abs(lon[1] - lon[2]) <= 1  # due north (1e-7 deg: < 1 cm)


def test_a_spacing_out_of_bounds_is_refused(capsys):
    from sitl.fleet import main

    for spacing in ("-1", "nan", "21"):
        with pytest.raises(SystemExit) as info:
            main(["--spacing", spacing])
        assert info.value.code == 2
        assert f"--spacing {float(spacing)}: metres between homes, in [0, 20]" in capsys.readouterr().err


@pytest.mark.processes
def test_the_fleet_asks_for_room_for_its_files_and_says_so_when_there_is_none():
    """A soft limit on open files too low for the fleet is raised (as far as the hard limit
    allows); a hard limit too low ends the launch with a clear error, exit 2, no traceback."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (256, hard))
        wanted = 64 + 8 * 100 if hard == resource.RLIM_INFINITY else min(64 + 8 * 100, hard)
        assert room_for_files(100) == wanted
        assert resource.getrlimit(resource.RLIMIT_NOFILE)[0] == wanted
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))

    def few_files() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (48, 48))

    launch = subprocess.run([sys.executable, "-m", "sitl.cli", "fleet", "--count", "40", "--instance", "200",
                             "--duration", "0.1"], capture_output=True, text=True, timeout=60.0,
                            preexec_fn=few_files)  # fmt: skip
    assert launch.returncode == 2, launch.stdout + launch.stderr
    assert "Too many open files" in launch.stderr and "raise `ulimit -n`" in launch.stderr
    assert "Traceback" not in launch.stderr


@pytest.mark.parametrize("speed", ["0", "-1", "inf", "nan", "fast"])
def test_a_speed_that_is_not_a_finite_factor_or_max_is_refused(capsys, speed):
    """`quadsitl fleet` and `quadsitl up` read --speed as the simulator does (one parser)."""
    from sitl import cli
    from sitl.fleet import main

    for run in (lambda: main(["--speed", speed]), lambda: cli.main(["up", "--speed", speed])):
        with pytest.raises(SystemExit) as info:
            run()
        assert info.value.code == 2
        assert f"--speed must be a positive number or 'max', got '{speed}'" in capsys.readouterr().err
