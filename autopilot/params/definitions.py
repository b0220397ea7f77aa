"""The autopilot's parameters and their defaults (PX4 names where the meaning matches)."""

from __future__ import annotations

from .store import INT32, ParameterStore, ParamSpec

COMMANDER_PARAMS = (
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.2, 100.0, unit="m", description="takeoff altitude above home"),
    ParamSpec("MPC_XY_VEL_MAX", 2.0, 0.1, 20.0, unit="m/s", description="horizontal speed limit"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 1.5, 0.1, 8.0, unit="m/s", description="climb speed limit"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.0, 0.1, 4.0, unit="m/s", description="descent speed limit"),
    ParamSpec("MPC_ACC_HOR", 2.0, 0.2, 15.0, unit="m/s^2", description="acceleration limit"),
    ParamSpec("MPC_TKO_SPEED", 1.0, 0.1, 5.0, unit="m/s", description="takeoff climb speed"),
    ParamSpec("MPC_LAND_SPEED", 0.7, 0.1, 3.0, unit="m/s", description="landing descent speed"),
    ParamSpec("MPC_YAWRAUTO_MAX", 1.0, 0.1, 6.0, unit="rad/s", description="yaw rate limit"),
    ParamSpec("RTL_RETURN_ALT", 5.0, 0.5, 150.0, unit="m", description="return altitude above home"),
    ParamSpec("NAV_ACC_RAD", 0.2, 0.01, 20.0, unit="m", description="waypoint acceptance radius"),
    ParamSpec(
        "COM_OF_LOSS_T",
        1.0,
        0.1,
        60.0,
        unit="s",
        description="offboard setpoint loss timeout (sim time)",
    ),
    ParamSpec("COM_DISARM_LAND", 2.0, 0.0, 20.0, unit="s", description="disarm this long after landing"),
    ParamSpec(
        "COM_DISARM_PRFLT",
        10.0,
        0.0,
        60.0,
        unit="s",
        description="disarm if no takeoff this long after arming",
    ),
    ParamSpec(
        "MAV_SYS_ID",
        1,
        1,
        250,
        kind=INT32,
        description="MAVLink system id (read-only in effect: set by --instance)",
    ),
)


def default_parameters() -> ParameterStore:
    return ParameterStore(COMMANDER_PARAMS)
