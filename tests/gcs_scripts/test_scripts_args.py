"""Command lines of the flying scripts and the recorder; paper -> NED conversion of setpoints."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from gcs_scripts import fly_setpoints, fly_trajectory, record
from gcs_scripts.link import (
    IGNORE_ACCELERATION,
    IGNORE_VELOCITY,
    IGNORE_YAW,
    IGNORE_YAW_RATE,
    PositionTarget,
    _check_loopback,
    api_url,
    custom_mode,
    encode_target,
    gcs_url,
    mavutil,
    mode_name,
)
from quadcommon.config import load_sitl


# -- paper frame -> NED ------------------------------------------------------------------------
def test_position_only_setpoint_is_converted_to_ned_with_ignore_bits() -> None:
    ned = encode_target(PositionTarget((1.0, 2.0, 3.0)))  # 1 m north, 2 m LEFT (west), 3 m UP
    assert ned.position == (1.0, -2.0, -3.0)
    assert ned.type_mask == IGNORE_VELOCITY | IGNORE_ACCELERATION | IGNORE_YAW | IGNORE_YAW_RATE == 3576
    assert ned.type_mask & 0b111 == 0  # position used
    assert not ned.type_mask & 512  # never a force setpoint


def test_full_setpoint_keeps_feedforward_and_yaw() -> None:
    target = PositionTarget((0.5, 0.0, 1.0), (0.0, 0.25, 0.1), (-0.125, 0.0, 0.0), math.radians(90.0))
    ned = encode_target(target)
    assert ned.type_mask == IGNORE_YAW_RATE  # p, v, a and yaw all used
    assert ned.velocity == (0.0, -0.25, -0.1)
    assert ned.acceleration == (-0.125, -0.0, -0.0)
    assert ned.yaw == pytest.approx(-math.pi / 2)  # 90 deg left of north (CCW, z up) = west = -90 deg NED


def test_mode_names_follow_px4_and_pymavlink() -> None:
    cm, main, sub = custom_mode("OFFBOARD")
    assert (cm, main, sub) == (393216, 6, 0)
    assert custom_mode("hold") == custom_mode("AUTO.LOITER") == (50593792, 4, 3)
    for name in (
        "POSCTL",
        "AUTO.TAKEOFF",
        "AUTO.LOITER",
        "AUTO.MISSION",
        "AUTO.RTL",
        "AUTO.LAND",
        "OFFBOARD",
    ):
        value = custom_mode(name)[0]
        assert mode_name(value) == name
        hb = mavutil.mavlink.MAVLink_heartbeat_message(2, 12, 1, value, 4, 3)
        assert mavutil.mode_string_v10(hb) == name.split(".")[-1]  # pymavlink's short names
    with pytest.raises(ValueError, match="unknown PX4 mode"):
        custom_mode("ACROBATIC")


def test_urls_are_per_instance_and_loopback_only() -> None:
    ports = load_sitl().ports(3)  # sitl.toml's [ports] bases + 3 (the tests' own block: tests/ports.py)
    assert api_url(3) == f"udpin:127.0.0.1:{ports.api_remote}"
    assert gcs_url(3) == f"udpin:127.0.0.1:{ports.gcs_remote}"
    _check_loopback("udpin:127.0.0.1:14540")
    for bad in ("udpin:0.0.0.0:14540", "tcp:127.0.0.1:5760", "udpout:10.0.0.2:14550"):
        with pytest.raises(ValueError):
            _check_loopback(bad)


# -- fly_setpoints -------------------------------------------------------------------------------
def test_fly_setpoints_defaults_to_a_2_m_square_at_2_5_m() -> None:
    args, sps = fly_setpoints.parse_args([])
    assert [sp.position for sp in sps] == [(2.0, 0.0, 2.5), (2.0, 2.0, 2.5), (0.0, 2.0, 2.5), (0.0, 0.0, 2.5)]
    assert (args.instance, args.url, args.takeoff_alt, args.hold, args.tolerance) == (0, None, 2.5, 2.0, 0.1)


def test_fly_setpoints_command_line_setpoints() -> None:
    args, sps = fly_setpoints.parse_args(
        ["--instance", "4", "--setpoint", "1", "2", "3", "--setpoint", "0", "0", "2", "90", "--hold", "0.5"]
    )
    assert args.instance == 4 and args.hold == 0.5
    assert sps[0].position == (1.0, 2.0, 3.0) and sps[0].yaw_deg is None
    assert sps[1].yaw_deg == 90.0
    assert encode_target(sps[1].target()).yaw == pytest.approx(-math.pi / 2)
    assert encode_target(sps[0].target()).position == (1.0, -2.0, -3.0)


def test_fly_setpoints_file_text_and_json(tmp_path: Path) -> None:
    text = tmp_path / "sp.txt"
    text.write_text("# a comment\n1 0 2.5\n\n2, 0, 2.5, 45  # with yaw\n")
    _, sps = fly_setpoints.parse_args(["--setpoints-file", str(text)])
    assert [(s.position, s.yaw_deg) for s in sps] == [((1.0, 0.0, 2.5), None), ((2.0, 0.0, 2.5), 45.0)]
    js = tmp_path / "sp.json"
    js.write_text('[[1, 1, 2], {"x": 0, "y": 0, "z": 3, "yaw_deg": -90}]')
    _, sps = fly_setpoints.parse_args(["--setpoints-file", str(js)])
    assert sps[0].position == (1.0, 1.0, 2.0) and sps[1].yaw_deg == -90.0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--setpoint", "1", "2"], "expected 'x y z"),
        (["--setpoint", "1", "2", "-3"], "below 0.2 m"),
        (["--tolerance", "0"], "--tolerance"),
        (["--setpoints-file", "/nonexistent/sp.txt"], "cannot read"),
        (["--instance", "250"], "--instance"),
    ],
)
def test_fly_setpoints_bad_arguments_exit_2(argv, message, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        fly_setpoints.parse_args(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_fly_setpoints_bad_file_lines_name_the_line(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.txt"
    bad.write_text("1 0 2\nnorth 0 2\n")
    with pytest.raises(SystemExit):
        fly_setpoints.parse_args(["--setpoints-file", str(bad)])
    assert "bad.txt:2" in capsys.readouterr().err


# -- fly_trajectory ------------------------------------------------------------------------------
def test_fly_trajectory_arguments_and_reference_setpoints() -> None:
    args, scenario = fly_trajectory.parse_args(["--scenario", "helix"])
    assert scenario.name == "helix" and args.duration == scenario.duration_s and args.rate == 100.0
    args, _ = fly_trajectory.parse_args(["--scenario", "circle", "--duration", "5", "--rate", "50"])
    assert args.duration == 5.0 and args.rate == 50.0
    flight = fly_trajectory.TrajectoryFlight(None, _helix(), 10.0)  # type: ignore[arg-type]
    assert flight.start_target.position_m == pytest.approx((0.5, 0.0, 1.0))  # p_d(0) of the helix
    assert flight.start_target.velocity_m_s is None  # going to p_d(0) is a plain position setpoint
    ref = _helix().sample(1.0)
    full = encode_target(fly_trajectory.reference_target(ref))
    assert full.type_mask == IGNORE_YAW_RATE
    assert full.position == pytest.approx((ref.position_m[0], -ref.position_m[1], -ref.position_m[2]))


def test_fly_trajectory_gusts_option_loads_the_profile(tmp_path: Path, capsys) -> None:
    args, _ = fly_trajectory.parse_args(["--gusts", "paper_steps"])
    assert [step["channel"] for step in args.gust_profile["step"]][:2] == ["force_x", "torque_roll"]
    assert fly_trajectory.parse_args([])[0].gust_profile is None
    with pytest.raises(SystemExit):
        fly_trajectory.parse_args(["--gusts", "no_such_profile"])
    assert "--gusts" in capsys.readouterr().err


def test_trajectory_waits_for_t0_then_samples_from_it() -> None:
    flight = fly_trajectory.TrajectoryFlight(None, _helix(), 10.0)  # type: ignore[arg-type]
    assert flight.provide(3.0) is flight.start_target  # before start_at: hold p_d(0)
    flight.start_at(5.0)
    assert flight.provide(4.99) is flight.start_target  # planned t0 not reached yet
    flight.link = type("L", (), {"position_paper": None})()
    target = flight.provide(6.0)
    assert target.position_m == pytest.approx(_helix().sample(1.0).position_m)
    assert flight.provide(15.5) is flight.end_target and flight.finished_at == 15.5


def _helix():
    from quadcommon.config import load_scenario
    from quadcommon.trajectories import trajectory_from_spec

    return trajectory_from_spec(load_scenario("helix").trajectory)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--scenario", "nosuch"], "no scenarios named"),
        (["--rate", "20"], "--rate"),
        (["--duration", "0"], "--duration"),
    ],
)
def test_fly_trajectory_bad_arguments_exit_2(argv, message, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        fly_trajectory.parse_args(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


# -- record --------------------------------------------------------------------------------------
def test_record_paths_and_default_url(tmp_path: Path) -> None:
    rec = record.Recorder(record.RecorderOptions(instance=7, out=tmp_path / "runs" / "a.parquet"))
    assert rec.url == f"udpin:127.0.0.1:{load_sitl().ports(7).gcs_remote}"
    assert rec.tlog_path == tmp_path / "runs" / "a.tlog"
    assert rec.parquet_path == tmp_path / "runs" / "a.parquet"
    assert rec.parts_dir == tmp_path / "runs" / "a.parts"
    args = record.build_parser().parse_args(["--instance", "2", "--duration", "30", "--until-disarmed"])
    assert args.duration == 30.0 and args.until_disarmed
    assert str(record.default_out()).startswith("runs/")


@pytest.mark.timeout(10)
def test_upload_gusts_takes_a_profile_name_or_a_file(tmp_path):
    from gcs_scripts import upload_gusts as ug
    from quadcommon.config import SHIPPED_CONFIG_DIR

    assert ug.profile_path("mixed") == SHIPPED_CONFIG_DIR / "gusts" / "mixed.toml"
    assert ug.profile_path(tmp_path / "mine.json") == tmp_path / "mine.json"  # a file, read later
    with pytest.raises(ug.ProfileFileError, match=r"no gusts named 'nosuch'.*available: .*mixed"):
        ug.profile_path("nosuch")
