"""Test harness for the simulator process: start it as a subprocess, talk to it as a scripted
autopilot over real UDP on 127.0.0.1. Every wait is bounded; every process is stopped.

Instances 40-59 belong to the simulator's tests (other suites use other instances).
"""

from __future__ import annotations

import signal
import socket
import sys
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

from quadcommon import wire
from quadcommon.config import find_config
from sitl.launcher import Child
from tests.ports import instance_ports

REPO = Path(__file__).resolve().parents[2]


class SimProcess(Child):
    """``python -m simulator`` as a child of the project's launcher (output collected line by line)."""

    def __init__(self, instance: int, *args: str, speed: str = "max") -> None:
        self.instance = instance
        self.ports = instance_ports(instance)
        cmd = [sys.executable, "-u", "-m", "simulator", "--instance", str(instance), "--speed", speed, *args]
        super().__init__(f"simulator[{instance}]", cmd)

    def terminate(self, timeout: float = 10.0, sig: int = signal.SIGTERM) -> int:
        """Send ``sig`` and wait for the exit code (LaunchError if it does not exit in time)."""
        self.signal(sig)
        return self.wait(timeout)

    def __enter__(self) -> SimProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop(grace_s=2.0)


class Frame(dict):
    """Messages of one datagram by type name (``frame["ODOMETRY"]``)."""

    @property
    def time_usec(self) -> int:
        return self["HIL_SENSOR"].time_usec


class ScriptedAutopilot:
    """A minimal autopilot: says hello, receives frames, answers HIL_ACTUATOR_CONTROLS by hand."""

    def __init__(self, instance: int) -> None:
        self.address = (wire.LOOPBACK, instance_ports(instance).hil)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((wire.LOOPBACK, 0))
        self.mav = mavlink.MAVLink(None, srcSystem=wire.system_id(instance), srcComponent=1)
        self.parser = mavlink.MAVLink(None)

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> ScriptedAutopilot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _pack(self, msg) -> bytes:
        data = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        return data

    def hello(self) -> None:
        hb = mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, mavlink.MAV_STATE_STANDBY, 3
        )
        self.sock.sendto(self._pack(hb), self.address)

    def recv_frame(self, timeout: float = 2.0) -> Frame | None:
        """The next datagram's messages, or None after ``timeout`` s."""
        self.sock.settimeout(timeout)
        try:
            data = self.sock.recv(65535)
        except TimeoutError:
            return None
        messages = self.parser.parse_buffer(data) or []
        return Frame((m.get_type(), m) for m in messages)

    def link(self, timeout: float = 30.0) -> Frame:
        """HEARTBEAT every 0.1 s until the first frame arrives (what the real autopilot does). The
        wait covers the simulator's start: about a second here, more than 8 s with two suites
        running at once on two cores."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.hello()
            frame = self.recv_frame(0.1)
            if frame is not None:
                return frame
        raise AssertionError(f"no frame from the simulator within {timeout} s")

    def answer(
        self,
        time_usec: int,
        controls: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
        armed: bool = False,
        wrench: bool = True,
        lockstep: bool = True,
    ) -> None:
        mode = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if armed:
            mode |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        flags = (wire.HIL_FLAG_LOCKSTEP if lockstep else 0) | (wire.HIL_FLAG_WRENCH if wrench else 0)
        values = [*controls, *([0.0] * 12)]
        msg = mavlink.MAVLink_hil_actuator_controls_message(time_usec, values, mode, flags)
        self.sock.sendto(self._pack(msg), self.address)

    def step(self, frame: Frame, timeout: float = 2.0, **answer_kwargs) -> Frame:
        """Answer ``frame`` and return the next one (AssertionError if none comes)."""
        self.answer(frame.time_usec, **answer_kwargs)
        deadline = time.monotonic() + timeout
        while True:  # copies of frames answered already (resent while we were slow) are skipped
            nxt = self.recv_frame(max(deadline - time.monotonic(), 0.0))
            assert nxt is not None, f"no frame after answering t={frame.time_usec} us"
            if nxt.time_usec > frame.time_usec:
                return nxt


def sitl_toml_with(tmp_path: Path, **lockstep: float) -> Path:
    """A copy of the sitl.toml in use (the shipped one on this test process's ports: tests/ports.py)
    with ``[lockstep]`` values replaced (e.g. timeout_s=0.3)."""
    text = find_config("", "sitl").read_text()
    for key, value in lockstep.items():
        lines = []
        for line in text.splitlines():
            if line.split("=")[0].strip() == key:
                line = f"{key} = {value}"
            lines.append(line)
        text = "\n".join(lines) + "\n"
    path = tmp_path / "sitl.toml"
    path.write_text(text)
    return path


def airborne_scenario(tmp_path: Path) -> Path:
    """Tilted, yawed, in the air, with parametric uncertainty and gusts that start at 10 ms."""
    gusts = tmp_path / "gusts.toml"
    gusts.write_text(
        'description = "test"\n'
        '[[step]]\nchannel = "force_x"\nstart_s = 0.01\nvalue = 2.0\n'
        '[[step]]\nchannel = "torque_roll"\nstart_s = 0.02\nvalue = 0.3\n'
        '[[ramp]]\nchannel = "force_z"\nstart_s = 0.0\nend_s = 0.05\nvalue = -1.0\n'
    )
    path = tmp_path / "airborne.toml"
    path.write_text(
        f'name = "airborne"\ndescription = "test"\nvehicle = "paper_quad"\nduration_s = 5.0\n'
        f'gusts = "{gusts}"\n'
        '[trajectory]\nkind = "hover"\nposition_m = [1.0, -2.0, 3.0]\n'
        "[initial_state]\nposition_m = [1.0, -2.0, 3.0]\neuler_rad = [0.1, -0.2, 0.7]\n"
        "[uncertainty]\nmass_scale = 1.2\ninertia_scale = 0.9\n"
    )
    return path
