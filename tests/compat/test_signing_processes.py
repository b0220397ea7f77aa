"""MAVLink 2 signing for real: the autopilot process, real MAVProxy (headless, ``signing setup`` /
``signing key``) and a pymavlink client over UDP.

* ``python -m autopilot`` (started by the launcher, as ``quadsitl up`` starts it): MAVProxy turns
  signing on with ``signing setup PASSPHRASE`` (SETUP_SIGNING) and arms with signed commands; a
  pymavlink client's unsigned command gets no COMMAND_ACK, its signed one does, the same signed
  frame sent again (a replay) gets none, all counted in ``quadsitl/<N>/autopilot/info``; after a
  restart (state file beside ``--params``) the key is still on, the recorded frame is still
  refused, and the client goes on signing.
* ``quadsitl up --signing-key FILE`` (a passphrase file): MAVProxy without the key sees the vehicle
  but its ``arm throttle`` is refused; after ``signing key PASSPHRASE`` (the same passphrase) it arms.
* MAVSDK, which has no signing: it reads the vehicle, its ``arm()`` times out.

Instances 70-72 (on the test process's port block, tests/ports.py).
"""

from __future__ import annotations

import json
import os
import stat
import sys
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink import mavutil  # noqa: E402

from autopilot.mavlink.signing import passphrase_to_key  # noqa: E402
from quadcommon import bus, wire  # noqa: E402
from sitl.launcher import Child, Launcher, VehicleSpec  # noqa: E402
from tests.ports import instance_ports  # noqa: E402

from .mavproxy_driver import MavProxy  # noqa: E402
from .vehicles import run_flow  # noqa: E402

pytestmark = [pytest.mark.processes, pytest.mark.compat]  # (tests/conftest.py: the markers)

PASSPHRASE = "quadsitl-signing-test"
REQUEST_MESSAGE = mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE
AUTOPILOT_VERSION = mavutil.mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION


class InfoTap:
    """``quadsitl/<N>/autopilot/info`` over zenoh (the vehicle's simulator listens on 7447 + N)."""

    def __init__(self, instance: int) -> None:
        self.instance = instance
        self.session = bus.open_peer(instance_ports(instance).zenoh)

    def get(self, timeout_s: float = 10.0) -> dict:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for reply in self.session.get(wire.zenoh_key(self.instance, "autopilot/info"), timeout=1.0):
                if reply.ok is not None:
                    return json.loads(reply.ok.payload.to_bytes())
            time.sleep(0.1)
        raise AssertionError(f"quadsitl/{self.instance}/autopilot/info never answered")

    def signing(self) -> dict:
        return self.get()["signing"]

    def close(self) -> None:
        self.session.close()


class Client:
    """A pymavlink ground station on a UDP port (``udpin``, as scripts connect to 14540 + N)."""

    def __init__(self, port: int, system_id: int) -> None:
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=254,
                                               source_component=190)  # fmt: skip
        self.system_id = system_id
        self.statustext: list[str] = []  # every STATUSTEXT received, whatever was waited for

    def close(self) -> None:
        self.conn.close()

    def wait(self, kind: str, timeout_s: float, predicate=lambda msg: True):
        """The next ``kind`` message from the vehicle satisfying ``predicate``, or None (wall time)."""
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(blocking=True, timeout=min(remaining, 0.2))
            if msg is None or msg.get_srcSystem() != self.system_id:
                continue
            if msg.get_type() == "STATUSTEXT":
                self.statustext.append(msg.text)
            if msg.get_type() == kind and predicate(msg):
                return msg
        return None

    def wait_statustext(self, needle: str, timeout_s: float) -> bool:
        """Whether a ``signing: refused ...`` STATUSTEXT with ``needle`` arrived (or arrives)."""
        def seen() -> bool:
            return any(t.startswith("signing: refused") and needle in t for t in self.statustext)

        deadline = time.monotonic() + timeout_s
        while not seen() and time.monotonic() < deadline:
            self.wait("STATUSTEXT", 0.2)
        return seen()

    def request_frame(self) -> bytes:
        """A COMMAND_LONG REQUEST_MESSAGE(AUTOPILOT_VERSION), packed (signed if signing is set up)."""
        mav = self.conn.mav
        data = mav.command_long_encode(self.system_id, 1, REQUEST_MESSAGE, 0, AUTOPILOT_VERSION,
                                       0, 0, 0, 0, 0, 0).pack(mav)  # fmt: skip
        mav.seq = (mav.seq + 1) % 256
        return data

    def send_and_ack(self, data: bytes, timeout_s: float):
        """Send raw ``data``; the COMMAND_ACK of REQUEST_MESSAGE it brings, or None."""
        self.drain()
        self.conn.write(data)
        return self.wait("COMMAND_ACK", timeout_s, lambda a: a.command == REQUEST_MESSAGE)

    def drain(self) -> None:
        while (msg := self.conn.recv_match(blocking=False)) is not None:
            if msg.get_type() == "STATUSTEXT":
                self.statustext.append(msg.text)


def start_mavproxy(port: int, cwd, sysid: int, parameters: bool = True) -> MavProxy:
    """MAVProxy connected; ``parameters``: wait until it has the parameters (a quiet console)."""
    mp = MavProxy(port, cwd)
    mp.expect(rf"online system {sysid}\b", 15)
    if parameters:
        mp.expect(r"Received (\d+) parameters", 30)
    return mp


def transcript(launcher: Launcher | None, mp: MavProxy | None) -> str:
    parts = [f"--- {c.name}:\n{c.tail(30)}" for c in (launcher.children if launcher else [])]
    if mp is not None:
        parts.append("--- MAVProxy:\n" + mp.tail(40))
    return "\n".join(parts)


@pytest.mark.timeout(120)
def test_mavproxy_signing_setup_then_signed_commands_work_unsigned_and_replayed_do_not(tmp_path):
    instance = 70
    sysid = wire.system_id(instance)
    spec = VehicleSpec(instance=instance, speed="1", params_file=str(tmp_path / "params.toml"))
    ports = spec.ports()
    state_file = tmp_path / f"signing-{instance}.json"
    client = Client(ports.api_remote, sysid)
    info = InfoTap(instance)
    launcher = mp = None
    try:
        with Launcher() as launcher:
            launcher.start_vehicles([spec], 30.0)
            assert info.signing()["enabled"] is False
            mp = start_mavproxy(ports.gcs_remote, tmp_path, sysid)
            mp.command(f"signing setup {PASSPHRASE}", r"Sent secret_key", 5)
            mp.expect(r"signing on: key set by SETUP_SIGNING", 5)  # the vehicle's STATUSTEXT, signed
            mp.command("arm throttle", r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", 5)
            mp.expect(r"^ARMED", 5)
            mp.command("disarm", r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", 5)
            signing = info.signing()
            assert signing["enabled"] and signing["key_source"] == "SETUP_SIGNING"
            assert signing["setup_signing"] == {"accepted": 1}
            assert stat.S_IMODE(state_file.stat().st_mode) == 0o600

            # pymavlink without the key: refused, no ACK; it still reads the signed telemetry.
            assert client.wait("HEARTBEAT", 5.0) is not None
            assert client.send_and_ack(client.request_frame(), 2.0) is None
            # Announced (a STATUSTEXT at most every 10 s sums up the refusals since the last one).
            assert client.wait_statustext("unsigned message(s)", 12.0), client.statustext
            # With the key (the passphrase hashed as MAVProxy does): ACKed, the answer signed.
            client.conn.setup_signing(passphrase_to_key(PASSPHRASE), sign_outgoing=True)
            recorded = client.request_frame()
            ack = client.send_and_ack(recorded, 3.0)
            assert ack is not None and ack.result == 0 and ack.get_signed()
            version = client.wait("AUTOPILOT_VERSION", 2.0)
            assert version is not None and version.get_signed()
            # The same signed frame again: a replay, refused.
            assert client.send_and_ack(recorded, 2.0) is None
            signing = info.signing()
            assert signing["refused"]["unsigned"] >= 1 and signing["refused"]["replayed"] == 1
            assert signing["refused_by_link"]["API"]["replayed"] == 1
            mp.close()
            mp = None
            launcher.stop()  # SIGTERM: the autopilot saves its signing state as it stops

        stored = json.loads(state_file.read_text())
        assert stored["key"] == passphrase_to_key(PASSPHRASE).hex() and stored["timestamp"] > 0

        # Restart: the key is still on (state file), the recorded frame is still refused, the
        # client (connected all along) goes on, and it still accepts the vehicle's frames.
        with Launcher() as launcher:
            launcher.start_vehicles([spec], 30.0)
            launcher.child(f"autopilot[{instance}]").wait_line("signing on (key from SETUP_SIGNING)", 5)
            assert client.wait("HEARTBEAT", 5.0) is not None
            assert client.send_and_ack(recorded, 2.0) is None
            ack = client.send_and_ack(client.request_frame(), 3.0)
            assert ack is not None and ack.get_signed()
            signing = info.signing()
            assert signing["enabled"] and signing["refused"]["replayed"] == 1
            assert signing["timestamp"] > stored["timestamp"]

            # MAVProxy with the key ("signing key": its side only), then "signing remove": a signed
            # SETUP_SIGNING with an all-zero key and timestamp 0, signing off.
            mp = start_mavproxy(ports.gcs_remote, tmp_path, sysid, parameters=False)
            mp.command(f"signing key {PASSPHRASE}", r"Setup signing key", 5)
            mp.command("signing remove", r"signing off \(SETUP_SIGNING\)", 5)
            assert info.signing()["enabled"] is False
            # The client still signs (accepted too, signing off) and now takes unsigned answers.
            client.conn.mav.signing.allow_unsigned_callback = lambda mav, msg_id: True
            ack = client.send_and_ack(client.request_frame(), 3.0)
            assert ack is not None and not ack.get_signed()
            assert json.loads(state_file.read_text())["key"] is None
    except AssertionError as exc:
        raise AssertionError(f"{exc}\n{transcript(launcher, mp)}") from None
    finally:
        if mp is not None:
            mp.close()
        client.close()
        info.close()


@pytest.mark.timeout(120)
def test_quadsitl_up_with_a_passphrase_file_and_mavproxy_signing_key(tmp_path):
    instance = 71
    sysid = wire.system_id(instance)
    key = tmp_path / "signing.key"
    key.write_text(PASSPHRASE + "\n")
    key.chmod(0o600)
    up = Child("quadsitl up", [sys.executable, "-u", "-m", "sitl.cli", "up", "--instance", str(instance),
                               "--speed", "1", "--signing-key", str(key), "--no-log"])  # fmt: skip
    info = mp = None
    try:
        up.wait_line("Ctrl-C stops", 30.0)
        up.wait_line(f"signing on (key from key file {key})", 5.0)
        info = InfoTap(instance)
        # Without the key MAVProxy reads the (signed) telemetry, but gets no parameters: its
        # requests are refused, as every frame it sends.
        mp = start_mavproxy(instance_ports(instance).gcs_remote, tmp_path, sysid, parameters=False)
        mp.send("arm throttle")  # unsigned: refused, no ACK
        with pytest.raises(AssertionError, match="no line matching"):
            mp.expect(r"COMMAND_ACK|^ARMED", 3)
        assert info.signing()["refused"]["unsigned"] >= 1
        mp.command(f"signing key {PASSPHRASE}", r"Setup signing key", 5)
        mp.command("arm throttle", r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", 5)
        mp.expect(r"^ARMED", 5)
        signing = info.signing()
        assert signing["enabled"] and signing["key_source"] == f"key file {key}"
        assert (tmp_path / f"signing-{instance}.json").exists()  # the state, beside the key file
    except Exception as exc:
        raise AssertionError(f"{exc}\n--- quadsitl up:\n{up.tail(40)}\n"
                             f"--- MAVProxy:\n{mp.tail(40) if mp else ''}") from None  # fmt: skip
    finally:
        if mp is not None:
            mp.close()
        if info is not None:
            info.close()
        assert up.stop(10.0) == 0


@pytest.mark.timeout(120)
def test_mavsdk_has_no_signing_it_reads_a_signing_vehicle_but_its_commands_are_refused(tmp_path):
    """MAVSDK 4 (C++ core) has no API for a signing key: it discovers the vehicle and reads its
    telemetry (it does not check signatures), but everything it sends is unsigned and refused."""
    instance = 72
    key = tmp_path / "signing.key"
    key.write_text(PASSPHRASE + "\n")
    key.chmod(0o600)
    spec = VehicleSpec(instance=instance, speed="1", signing_key_file=str(key))
    info = None
    with Launcher() as launcher:
        launcher.start_vehicles([spec], 30.0)
        try:
            info = InfoTap(instance)
            flow = run_flow("action", f"udpin://127.0.0.1:{spec.ports().api_remote}", 60.0)
            assert flow.event("discovered")["sysid"] == wire.system_id(instance), flow.transcript()
            assert flow.event("healthy")["health"]["is_armable"], flow.transcript()
            error = flow.event("error")
            # Its first command (the flow's set_rate_ground_truth, a SET_MESSAGE_INTERVAL) goes unanswered.
            assert "set_rate_ground_truth()" in error["message"] and "TIMEOUT" in error["message"], \
                flow.transcript()
            assert info.signing()["refused"]["unsigned"] > 0
        finally:
            if info is not None:
                info.close()
