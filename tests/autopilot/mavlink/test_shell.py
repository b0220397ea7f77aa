"""The MAVLink shell (SERIAL_CONTROL, device SHELL) on the in-process stack, in simulation time: the
console's commands acting through the vehicle's own paths, line handling as PX4's shell, the
flags, and what a hostile or flooding station can and cannot do. AUTOPILOT_VERSION's build here
too (``ver all`` prints the same).

The real client (MAVSDK-Python 4's Shell plugin against ``quadsitl up``) is in tests/compat/test_mavsdk.py.
"""

from __future__ import annotations

import struct
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from autopilot.core import SHELL_MESSAGES_PER_FRAME
from autopilot.mavlink import shell
from quadcommon.build_info import BuildInfo
from quadcommon.mavlink_fast import frame_payload
from sitl.inprocess import API_LINK, GCS_LINK, Lockstep
from tests.stack import Gcs, make_stack

RESPOND = m.SERIAL_CONTROL_FLAG_RESPOND | m.SERIAL_CONTROL_FLAG_EXCLUSIVE
PROMPT = "nsh> "


class ShellClient:
    """A console as QGC's MAVLink Console or PX4's mavlink_shell.py uses it."""

    def __init__(self, stack, link: int = API_LINK, system_id: int = 255) -> None:
        self.stack = stack
        self.station = stack.ground_station(link, listen=False, system_id=system_id)
        self.replies: list = []  # every SERIAL_CONTROL the vehicle sent this station
        self.per_frame: list[int] = []

    def type(self, text: str | bytes, flags: int = RESPOND, device: int = m.SERIAL_CONTROL_DEV_SHELL) -> None:
        data = text.encode() if isinstance(text, str) else text
        while True:
            chunk, data = data[:70], data[70:]
            data70 = list(chunk.ljust(70, b"\0"))
            self.station.mav.serial_control_send(device, flags, 0, 0, len(chunk), data70)
            if not data:
                return

    def read(self, frames: int = 20, until: str | None = None) -> str:
        out = ""
        for _ in range(frames):
            self.stack.step()
            got = [msg for msg in self.station.inbox if msg.get_type() == "SERIAL_CONTROL"]
            self.station.inbox.clear()
            self.per_frame.append(len(got))
            self.replies += got
            out += "".join(bytes(msg.data[: msg.count]).decode() for msg in got)
            if until is not None and out.endswith(until):
                break
        return out

    def run(self, line: str, frames: int = 2000) -> str:
        """The output of ``line``, its echo and the next prompt stripped."""
        self.type(line + "\n")
        out = self.read(frames, until=PROMPT)
        assert out.endswith(PROMPT), out
        echo = line + "\n"
        assert out.startswith(echo), out
        return out[len(echo) : -len(PROMPT)]


@pytest.fixture
def vehicle():
    stack = make_stack()
    console = ShellClient(stack)
    console.type("\n")
    greeting = console.read(until=PROMPT)
    assert greeting.endswith(PROMPT) and "'help' lists the commands" in greeting
    return stack, console


def test_answers_are_serial_control_replies_as_px4_sends_them(vehicle):
    stack, console = vehicle
    out = console.run("help")
    for command in ("param", "commander", "failure", "listener", "ver", "top"):
        assert f"\n  {command} " in out
    for reply in console.replies:
        assert reply.device == m.SERIAL_CONTROL_DEV_SHELL and reply.flags == m.SERIAL_CONTROL_FLAG_REPLY
        assert (reply.timeout, reply.baudrate) == (0, 0) and 0 < reply.count <= 70
        assert reply.get_srcSystem() == stack.autopilot.system_id
    assert max(console.per_frame) <= SHELL_MESSAGES_PER_FRAME  # paced
    assert console.run("nonsense --flag") == "nsh: nonsense: command not found\n"
    assert console.run("# a comment") == "" and console.run("   ") == ""


def test_param_show_and_set_through_the_parameter_store(vehicle):
    stack, console = vehicle
    params = stack.autopilot.params
    shown = console.run("param show MPC_TKO*").splitlines()
    assert shown[0] == "Symbols: x = used, + = saved, * = unsaved"
    index = params.index("MPC_TKO_SPEED")
    assert shown[1] == f"x   MPC_TKO_SPEED [{index},{index}] : 1.5000"
    assert shown[-1].strip() == f"1/{len(params)} parameters shown."
    other = Gcs(stack, GCS_LINK)  # another ground station sees the change as PX4 announces it
    assert console.run("param set MPC_TKO_SPEED 1.2") == "MPC_TKO_SPEED: curr: 1.5000 -> new: 1.2000\n"
    assert params["MPC_TKO_SPEED"] == pytest.approx(1.2)
    other.wait(lambda g: "PARAM_VALUE" in g.last and g.last["PARAM_VALUE"].param_id == "MPC_TKO_SPEED",
               sim_timeout=0.5, what="PARAM_VALUE")  # fmt: skip
    assert other.last["PARAM_VALUE"].param_value == pytest.approx(1.2)
    assert "* MPC_TKO_SPEED" in console.run("param show -c")
    # The store's checks, the refusal said on the links too (STATUSTEXT), the value unchanged.
    out = console.run("param set MPC_TKO_SPEED 99")
    assert out == "ERROR [param] MPC_TKO_SPEED: 99 out of range [0.1, 5] m/s\n"
    other.wait(lambda g: any("MPC_TKO_SPEED: 99 out of range" in t for t in g.statustext), sim_timeout=0.5)
    assert params["MPC_TKO_SPEED"] == pytest.approx(1.2)
    assert console.run("param set SITL_CTRL_HZ 250").startswith("ERROR [param] SITL_CTRL_HZ is read-only")
    assert console.run("param set NO_SUCH 1") == "ERROR [param] parameter NO_SUCH not found\n"
    assert console.run("param set MPC_TKO_SPEED x") == "ERROR [param] MPC_TKO_SPEED: 'x' is not a number\n"
    assert console.run("param set SDLOG_MODE 1.5") == "ERROR [param] SDLOG_MODE: '1.5' is not an integer\n"
    assert console.run("param set SDLOG_MODE 2") == "SDLOG_MODE: curr: 0 -> new: 2\n"
    assert console.run("param reset MPC_TKO_SPEED").endswith("-> new: 1.5000\n")
    assert console.run("param").startswith("usage: param show")


def test_commander_flies_through_the_vehicles_own_commands(vehicle):
    stack, console = vehicle
    gcs = Gcs(stack, GCS_LINK)
    refused = console.run("commander takeoff")
    assert refused.startswith("WARN  [commander] takeoff: DENIED") and "arm first" in refused
    assert console.run("commander check") == "Preflight check: OK\n"
    assert "preflight: ready to arm" in console.run("commander status")
    assert console.run("commander arm") == "INFO  [commander] arm: accepted\n"
    gcs.wait(lambda g: g.armed, sim_timeout=1.5, what="armed (HEARTBEAT)")
    assert console.run("commander takeoff") == "INFO  [commander] takeoff: accepted\n"
    loiter = FlightMode.AUTO_LOITER.custom_mode  # the takeoff done: holding at MIS_TAKEOFF_ALT
    gcs.wait(lambda g: g.custom_mode == loiter and g.position()[2] > 2.4, sim_timeout=15.0, what="hold")
    status = console.run("commander status")
    assert "armed: yes" in status and "landed state: IN_AIR" in status
    listener = console.run("listener vehicle_local_position")
    assert listener.startswith("TOPIC: vehicle_local_position\n vehicle_local_position\n")
    z = float(next(line for line in listener.splitlines() if line.strip().startswith("z:")).split(":")[1])
    assert z == pytest.approx(-gcs.position()[2], abs=0.05)  # NED: z is minus the height
    out = console.run("commander mode posctl")  # PX4's answer to POSCTL without sticks
    assert out.startswith("WARN  [commander] mode posctl: DENIED")
    assert console.run("commander mode warp") .startswith("commander mode: unknown mode 'warp'")
    assert console.run("commander disarm").startswith("WARN  [commander] disarm: DENIED")  # in the air
    assert console.run("commander land") == "INFO  [commander] land: accepted\n"
    gcs.wait(lambda g: not g.armed, sim_timeout=20.0, what="landed and disarmed (COM_DISARM_LAND)")
    assert "landed state: ON_GROUND" in console.run("commander status")
    assert console.run("commander").startswith("usage: commander")


def test_failure_goes_through_mav_cmd_inject_failure(vehicle):
    stack, console = vehicle
    injection = stack.autopilot.failure_injection
    disabled = "failure injection disabled: set SYS_FAILURE_EN to 1"
    assert console.run("failure rc_signal off") == f"WARN  [failure] rc_signal off: DENIED: {disabled}\n"
    console.run("param set SYS_FAILURE_EN 1")
    assert console.run("failure rc_signal off") == "INFO  [failure] rc_signal off: accepted\n"
    assert injection.rc_signal_lost and injection.active == {"rc_signal": "off"}
    assert console.run("failure rc_signal ok") == "INFO  [failure] rc_signal ok: accepted\n"
    assert not injection.rc_signal_lost and injection.active == {}
    gps = console.run("failure gps off -i 1")  # the handler's own refusal: this vehicle flies on truth
    assert gps.startswith("WARN  [failure] gps off: DENIED: failure gps acts on the EKF")
    assert console.run("failure motor off -i 9").startswith("WARN  [failure] motor off: DENIED: failure "
                                                            "motor: no instance 9")
    assert console.run("failure motor off") == "INFO  [failure] motor off: accepted\n"  # the wrench too
    assert console.run("failure motor ok") == "INFO  [failure] motor ok: accepted\n"
    for bad in ("failure", "failure gps", "failure warp off", "failure gps melt", "failure gps off -i x"):
        assert console.run(bad).startswith("usage: failure UNIT TYPE"), bad


def test_listener_prints_the_flight_logs_topics_now(vehicle):
    stack, console = vehicle
    status = console.run("listener vehicle_status")
    assert "    arming_state: 1\n" in status  # disarmed
    console.run("commander arm")
    assert "    arming_state: 2\n" in console.run("listener vehicle_status")
    battery = console.run("listener battery_status")
    assert "    connected: True\n" in battery and "    voltage_v: " in battery
    assert console.run("listener sim_disturbance").startswith("never published: sim_disturbance")
    usage = console.run("listener")
    assert usage.startswith("usage: listener TOPIC") and "vehicle_attitude" in usage
    assert console.run("listener no_such_topic").startswith("usage: listener TOPIC")


def test_version_in_autopilot_version_and_in_the_console():
    """AUTOPILOT_VERSION as PX4 fills it: the version 0xMMmmppTT, the commit's first 8 bytes as a
    little-endian uint64 (QGC and MAVSDK print them reversed: the hash); ``ver all`` the same."""
    base = make_stack()
    commit = "0123456789abcdef" + "0" * 24
    stack = Lockstep(base.sim.setup, replace(base.autopilot.setup, build=BuildInfo("1.2.3", commit)))
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    assert gcs.command(m.MAV_CMD_REQUEST_MESSAGE, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION).result == 0
    gcs.wait(lambda g: "AUTOPILOT_VERSION" in g.last, sim_timeout=0.5)
    version = gcs.last["AUTOPILOT_VERSION"]
    assert version.flight_sw_version == version.middleware_sw_version == 0x010203FF
    assert list(version.flight_custom_version) == [0xEF, 0xCD, 0xAB, 0x89, 0x67, 0x45, 0x23, 0x01]
    assert "".join(f"{b:02x}" for b in reversed(version.flight_custom_version)) == commit[:16]  # as QGC
    assert list(version.middleware_custom_version) == list(version.flight_custom_version)
    assert version.capabilities & m.MAV_PROTOCOL_CAPABILITY_FTP  # as PX4: FTP is served
    console = ShellClient(stack)
    console.type("\n")
    assert "quadsitl 1.2.3:" in console.read(until=PROMPT)
    ver = console.run("ver all")
    assert f"quadsitl git-hash: {commit}\n" in ver and "quadsitl version: 1.2.3 (0x010203ff)" in ver
    assert console.run("ver git") == f"quadsitl git-hash: {commit}\n"
    unknown = Gcs(make_stack())  # no build given (a test's stack): zeros, as PX4 without a hash
    unknown.wait_heartbeat()
    unknown.command(m.MAV_CMD_REQUEST_MESSAGE, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    unknown.wait(lambda g: "AUTOPILOT_VERSION" in g.last, sim_timeout=0.5)
    assert list(unknown.last["AUTOPILOT_VERSION"].flight_custom_version) == [0] * 8


def test_line_handling_as_px4s_shell(vehicle):
    stack, console = vehicle
    console.type("param shoX\x7fw MPC_LAND_SX\x08PEED\r\n")  # backspaces; \r\n is one Enter
    out = console.read(400, until=PROMPT)
    assert out.startswith("param shoX\b \bw MPC_LAND_SX\b \bPEED\n")  # the echo, erasures too
    assert "MPC_LAND_SPEED" in out and out.endswith(PROMPT)
    console.type("par")  # a line split across messages
    console.type("am show MIS_TAKEOFF_ALT\n")
    assert "MIS_TAKEOFF_ALT" in console.read(400, until=PROMPT)
    console.type(b"\x1b[Aparam \xff\xc3show\x01 COM_OF_LOSS_T\n")  # control and non-ASCII bytes dropped
    out = console.read(400, until=PROMPT)
    assert out.startswith("[Aparam show COM_OF_LOSS_T\n")
    long = "x" * (shell.LINE_MAX + 100)
    console.type(long + "\n")
    out = console.read(400, until=PROMPT)
    assert out.startswith("x" * shell.LINE_MAX + "\n")  # kept up to LINE_MAX characters
    assert f"nsh: {'x' * shell.LINE_MAX}: command not found" in out


def test_without_respond_the_line_runs_and_the_console_closes(vehicle):
    """PX4 closes its shell when a message does not ask for an answer: the line still runs here,
    nothing comes back, and the next message opens a new console (greeting again). MAVSDK sends a
    long command's first pieces without RESPOND: a line still being typed keeps the console."""
    stack, console = vehicle
    console.type("param set MPC_LAND_SPEED 0.5\n", flags=0)
    assert console.read(50) == ""
    assert stack.autopilot.params["MPC_LAND_SPEED"] == pytest.approx(0.5)
    assert not stack.autopilot.shell.terminals[API_LINK]
    long = "param set MPC_LAND_SPEED 0.6" + " " * 60 + "\n"  # 89 characters: two pieces
    console.type(long[:70], flags=0)
    console.type(long[70:])
    out = console.read(400, until=PROMPT)
    assert "'help' lists the commands" not in out  # the same console: the first piece was kept
    assert "MPC_LAND_SPEED: curr: 0.5000 -> new: 0.6000" in out
    assert stack.autopilot.params["MPC_LAND_SPEED"] == pytest.approx(0.6)


def test_messages_px4_ignores_are_ignored(vehicle):
    stack, console = vehicle
    params = stack.autopilot.params
    console.type("param set MPC_LAND_SPEED 0.4\n", flags=RESPOND | m.SERIAL_CONTROL_FLAG_REPLY)  # an answer
    console.type("param set MPC_LAND_SPEED 0.4\n", device=m.SERIAL_CONTROL_DEV_TELEM2)  # not the shell
    console.station.mav.serial_control_send(10, RESPOND, 0, 0, 71, [ord("x")] * 70)  # count > 70
    assert console.read(50) == "" and params["MPC_LAND_SPEED"] == pytest.approx(0.7)
    # MAVLink 2's target fields (an extension pymavlink's dialect lacks): another vehicle's ignored.
    for target, answered in ((7, False), (0, True), (stack.autopilot.system_id, True)):
        text = b"ver hw\n"
        payload = struct.pack("<IHBBB70sBB", 0, 0, 10, RESPOND, len(text), text, target, 1)
        mav = console.station.mav
        frame = frame_payload(m.MAVLink_serial_control_message, payload, mav.seq, 255, 190)
        console.station.send_bytes(frame)
        mav.seq = (mav.seq + 1) % 256
        assert ("HW arch" in console.read(100, until=PROMPT)) == answered, target


def test_a_flood_is_bounded(vehicle):
    """Lines that produce much output, faster than the link carries it: the backlog stays bounded,
    lines are refused while it is full ("busy"), nothing breaks; many stations: a link keeps a
    few consoles."""
    stack, console = vehicle
    core = stack.autopilot
    out = ""
    for _ in range(300):
        console.type("param show\n" * 6)
        out += console.read(1)
        terminal = core.shell.terminals[API_LINK][console.station.address]
        assert len(terminal.output) <= shell.OUTPUT_MAX
    assert core.shell.lines_refused > 1000 and core.shell.lines_run < 100
    out += console.read(3000)
    assert "nsh: busy" in out
    assert max(console.per_frame) <= SHELL_MESSAGES_PER_FRAME
    others = [ShellClient(stack, GCS_LINK, system_id=100 + k) for k in range(10)]
    for other in others:
        other.type("ver hw\n")
    stack.run_for(0.1)
    assert len(core.shell.terminals[GCS_LINK]) == shell.MAX_CONSOLES_PER_LINK
    assert not core.faults.counts
    assert console.run("ver hw").startswith("HW arch")  # the flooding station's console still works


def test_host_commands_are_not_run(vehicle, tmp_path):
    """NuttX's shell has no host behind it: ``!``, shell syntax and substitutions are words of a
    command (unknown, or a console command's arguments); nothing reaches the host's shell."""
    stack, console = vehicle
    canary = tmp_path / "canary"
    unknown = (f"!touch {canary}", f"sh -c 'touch {canary}'", f"$(touch {canary})", f"`touch {canary}`",
               f"exec touch {canary}", f"system touch {canary}")  # fmt: skip
    for line in unknown:
        assert "command not found" in console.run(line), line
    for line in (f"ver; touch {canary}", f"ver && touch {canary}", f"param show | touch {canary}"):
        console.run(line)  # answered by the console command named first, its arguments as words
    assert not canary.exists()
    assert not stack.autopilot.faults.counts
