"""The autopilot's parameters and their defaults (PX4 names where the meaning matches).

Three groups:

* commander and failsafe parameters (fixed defaults, PX4's where PX4 has the parameter);
* controller gains of the ACTIVE cascade, whose defaults are the controller config's values
  (``config/controllers/NAME.toml``); only the laws the cascade runs have parameters;
* rates (read-only: ``config/sitl.toml`` fixes them for both processes, and lockstep depends on
  them, so a change is refused with that reason rather than half-applied).

:func:`controller_config_from_params` maps the gain parameters back onto a
:class:`~autopilot.control.config.ControllerConfig` for :meth:`~autopilot.control.cascade.Cascade.retune`;
:func:`consistency_problems` is the "bad parameters" pre-arm check.
"""

from __future__ import annotations

from dataclasses import replace

from quadcommon.config import SIM_BATTERY_PARAMETERS, BatteryConfig, Rates, VehicleConfig
from quadcommon.failures import MOTOR_EFFECTIVENESS_DEFAULT, MOTOR_EFFECTIVENESS_PARAMETER

from ..control import registry
from ..control.config import ControllerConfig
from .store import FLOAT, INT32, ParameterStore, ParamSpec

# NAV_DLL_ACT (GCS data link loss action): PX4's enum values (0 disabled, 1 hold, 2 return,
# 3 land; PX4's 5 terminate and 6 disarm are not supported here).
DLL_NONE, DLL_HOLD, DLL_RTL, DLL_LAND = 0, 1, 2, 3
# GF_ACTION (geofence breach action): PX4's values; 4 (terminate) is not supported here.
GF_NONE, GF_WARN, GF_HOLD, GF_RTL, GF_TERMINATE, GF_LAND = 0, 1, 2, 3, 4, 5
# NAV_RCL_ACT (manual control loss action in a manual mode): PX4's values (1 hold, 2 return, 3 land;
# 5 terminate and 6 disarm are refused here).
RCL_HOLD, RCL_RTL, RCL_LAND = 1, 2, 3
# COM_RC_OVERRIDE bits: moving sticks take over the AUTO modes, OFFBOARD.
RC_OVERRIDE_AUTO, RC_OVERRIDE_OFFBOARD = 1, 2
# RTL_TYPE (PX4's values): 0 closest of home and rally points; 1 closest rally point (else home: no
# mission landing here); 3 closest of home, rally points (and a mission landing, which missions here
# do not have); 5 closest rally point, or land where the vehicle is if there is none.
RTL_HOME_OR_RALLY, RTL_RALLY_OR_HOME, RTL_CLOSEST, RTL_RALLY_ONLY = 0, 1, 3, 5
RTL_TYPES_REFUSED = {
    2: "the mission-path return is not supported (missions have no landing pattern here)",
    4: "the mission-path return is not supported (missions have no landing pattern here)",
    6: "the return chosen by the remaining flight time is not supported",
}
# COM_LOW_BAT_ACT (PX4's LowBatteryAction): what the critical and emergency battery levels do.
# PX4 documents 0, 2 and 3; its code also takes 1 (return at both levels), and so does this one.
LOW_BAT_WARN, LOW_BAT_RTL, LOW_BAT_LAND, LOW_BAT_RTL_THEN_LAND = 0, 1, 2, 3

COMMANDER_PARAMS = (
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.2, 100.0, unit="m", description="takeoff altitude above home"),
    ParamSpec("MPC_XY_VEL_MAX", 2.0, 0.1, 20.0, unit="m/s", description="horizontal speed limit"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 1.5, 0.1, 8.0, unit="m/s", description="climb speed limit"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.0, 0.1, 4.0, unit="m/s", description="descent speed limit"),
    ParamSpec("MPC_ACC_HOR", 2.0, 0.2, 15.0, unit="m/s^2", description="acceleration limit"),
    ParamSpec("MPC_TKO_SPEED", 1.5, 0.1, 5.0, unit="m/s", description="takeoff climb speed"),
    ParamSpec("MPC_LAND_SPEED", 0.7, 0.1, 3.0, unit="m/s", description="landing descent speed"),
    ParamSpec("MPC_YAWRAUTO_MAX", 1.0, 0.1, 6.0, unit="rad/s", description="yaw rate limit"),
    # The manual modes (MANUAL_CONTROL): autopilot/guidance/manual.py, docs/manual-control.md.
    # PX4's names, units and defaults, except MPC_VEL_MANUAL (this project's MPC_XY_VEL_MAX; PX4:
    # 10 m/s) and MPC_THR_HOVER (this vehicle's hover thrust: manual_params()).
    ParamSpec("MPC_VEL_MANUAL", 2.0, 0.1, 20.0, unit="m/s", description="POSCTL speed at full stick"),
    ParamSpec("MPC_MAN_Y_MAX", 150.0, 1.0, 400.0, unit="deg/s",
              description="POSCTL, ALTCTL, STABILIZED: yaw rate at full stick"),
    ParamSpec("MPC_HOLD_DZ", 0.1, 0.0, 0.9,
              description="stick deadzone (fraction of full deflection): POSCTL, the ALTCTL throttle"),
    ParamSpec("MPC_MAN_TILT_MAX", 35.0, 1.0, 80.0, unit="deg",
              description="ALTCTL, STABILIZED: tilt at full roll/pitch stick"),
    ParamSpec("MPC_MANTHR_MIN", 0.08, 0.0, 1.0,
              description="STABILIZED, ACRO: thrust at the throttle's bottom (of U1_max, the vehicle's "
                          "thrust_max_n)"),
    ParamSpec("MPC_THR_MAX", 1.0, 0.0, 1.0, description="STABILIZED, ACRO: thrust at the throttle's top "
                                                        "(of U1_max)"),
    ParamSpec("MPC_THR_CURVE", 0, 0, 1, kind=INT32,
              description="STABILIZED, ACRO throttle: 0 rescale (centre = MPC_THR_HOVER), 1 linear"),
    ParamSpec("MC_ACRO_R_MAX", 100.0, 0.0, 1800.0, unit="deg/s", description="ACRO: roll rate, full stick"),
    ParamSpec("MC_ACRO_P_MAX", 100.0, 0.0, 1800.0, unit="deg/s", description="ACRO: pitch rate, full stick"),
    ParamSpec("MC_ACRO_Y_MAX", 100.0, 0.0, 1800.0, unit="deg/s", description="ACRO: yaw rate, full stick"),
    ParamSpec("MC_ACRO_EXPO", 0.0, 0.0, 1.0, description="ACRO roll/pitch expo: 0 linear, 1 cubic"),
    ParamSpec("MC_ACRO_EXPO_Y", 0.0, 0.0, 1.0, description="ACRO yaw expo: 0 linear, 1 cubic"),
    ParamSpec("MC_ACRO_SUPEXPO", 0.0, 0.0, 0.95, description="ACRO roll/pitch super-expo"),
    ParamSpec("MC_ACRO_SUPEXPOY", 0.0, 0.0, 0.95, description="ACRO yaw super-expo"),
    ParamSpec("ACRO_TILT_LIM", 60.0, 10.0, 80.0, unit="deg",
              description="not in PX4: ACRO's attitude stays within this roll and pitch (the attitude "
                          "law's Euler angles are singular at 90 deg: no flips)"),
    ParamSpec("COM_RC_LOSS_T", 0.5, 0.1, 35.0, unit="s",
              description="no MANUAL_CONTROL for this long (sim time): manual control lost"),
    ParamSpec("RTL_RETURN_ALT", 5.0, 0.5, 150.0, unit="m",
              description="return altitude above the return destination (home or rally point)"),
    ParamSpec("RTL_TYPE", RTL_HOME_OR_RALLY, 0, 6, kind=INT32,
              description="return destination: 0 closest of home and rally points, 1 closest rally "
                          "point (home if none), 3 as 0, 5 closest rally point (land here if none)",
              refused={float(v): why for v, why in RTL_TYPES_REFUSED.items()}),
    ParamSpec("NAV_ACC_RAD", 0.2, 0.01, 20.0, unit="m", description="waypoint acceptance radius"),
    # Orbit (MAV_CMD_DO_ORBIT, autopilot/guidance/orbit.py) and follow-me (AUTO.FOLLOW_TARGET,
    # autopilot/guidance/follow.py): PX4's names, defaults and ranges (FLW_TGT_HT, FLW_TGT_DST: PX4 sets
    # no maximum; here 1000 m).
    ParamSpec("MC_ORBIT_RAD_MAX", 1000.0, 1.0, 10000.0, unit="m",
              description="Orbit: largest radius accepted (a larger one is refused)"),
    ParamSpec("MC_ORBIT_YAW_MOD", 0, 0, 4, kind=INT32,
              description="Orbit's yaw behaviour until a DO_ORBIT sets one: 0 front to the centre, 1 hold "
                          "the initial heading, 2 uncontrolled, 3 front tangent to the circle, 4 yaw stick"),
    ParamSpec("FLW_TGT_HT", 8.0, 8.0, 1000.0, unit="m", description="follow-me: height above the target "
                                                                   "(FLW_TGT_ALT_M 2) or home (0, 1)"),
    ParamSpec("FLW_TGT_DST", 8.0, 1.0, 1000.0, unit="m", description="follow-me: horizontal distance to the "
                                                                    "target"),
    ParamSpec("FLW_TGT_FA", 180.0, -180.0, 180.0, unit="deg",
              description="follow-me: angle from the target's course, clockwise (0 in front, 90 right, "
                          "180 behind)"),
    ParamSpec("FLW_TGT_ALT_M", 0, 0, 2, kind=INT32,
              description="follow-me altitude: 0 FLW_TGT_HT above home, 1 above the terrain (flat: as 0), "
                          "2 FLW_TGT_HT above the target"),
    ParamSpec("FLW_TGT_MAX_VEL", 5.0, 0.0, 20.0, unit="m/s",
              description="follow-me: tangential speed at which the vehicle circles the target to a new "
                          "follow angle"),
    ParamSpec("FLW_TGT_RS", 0.1, 0.0, 1.0,
              description="follow-me: the target estimator's responsiveness (lower: follows the reports "
                          "faster, filters less noise)"),
    ParamSpec(
        "NAV_REF_MAX_DIST",
        1000.0,
        10.0,
        10000.0,
        unit="m",
        description="offboard setpoints and mission items farther than this from home are refused",
    ),
    ParamSpec(
        "MIS_ITEMS_MAX",
        10000,
        1,
        50000,
        kind=INT32,
        description="largest mission accepted (items); more: MAV_MISSION_NO_SPACE",
    ),
    ParamSpec(
        "COM_OF_LOSS_T",
        1.0,
        0.1,
        60.0,
        unit="s",
        description="offboard setpoint loss timeout (sim time); then hold",
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
        description="MAVLink system id",
        read_only="set by --instance N (sysid 1+N)",
    ),
)

FAILSAFE_PARAMS = (
    ParamSpec(
        "COM_DL_LOSS_T",
        10,
        5,
        300,
        kind=INT32,
        unit="s",
        description="GCS heartbeat loss timeout (sim time; PX4's int32 seconds)",
    ),
    ParamSpec(
        "NAV_DLL_ACT",
        DLL_NONE,
        0,
        3,
        kind=INT32,
        description="GCS heartbeat loss action: 0 none, 1 hold, 2 return (RTL), 3 land (PX4 values)",
    ),
    ParamSpec(
        "COM_SIM_LOSS_T",
        1.0,
        0.2,
        30.0,
        unit="s",
        description="no sensor frame for this long (wall): simulator lost, motors off",
    ),
    ParamSpec(
        "NAV_RCL_ACT", RCL_RTL, 1, 6, kind=INT32,
        description="manual control lost in a manual mode: 1 hold, 2 return (RTL), 3 land (PX4 values)",
        refused={4.0: "not a PX4 action", 5.0: "flight termination is not supported",
                 6.0: "disarming in flight is not supported"},
    ),  # fmt: skip
    ParamSpec("COM_RC_OVERRIDE", RC_OVERRIDE_AUTO, 0, 3, kind=INT32,
              description="moving sticks take over (into POSCTL): bit 0 the AUTO modes, bit 1 OFFBOARD"),
    ParamSpec("COM_RC_STICK_OV", 30.0, 5.0, 80.0, unit="%",
              description="stick override threshold: a stick moving faster than this (of full travel "
                          "per second, filtered over 0.1 s)"),
    ParamSpec(
        "GF_MAX_HOR_DIST",
        0.0,
        0.0,
        10000.0,
        unit="m",
        description="geofence: horizontal distance from home (0 = disabled)",
    ),
    ParamSpec(
        "GF_MAX_VER_DIST",
        0.0,
        0.0,
        10000.0,
        unit="m",
        description="geofence: height above home (0 = disabled)",
    ),
    ParamSpec(
        "GF_ACTION",
        GF_HOLD,
        0,
        5,
        kind=INT32,
        description="geofence breach action: 0 none, 1 warning, 2 hold, 3 return (RTL), 5 land (PX4 values)",
        refused={float(GF_TERMINATE): "flight termination is not supported"},
    ),
)

def battery_params(vehicle: VehicleConfig | None = None) -> tuple[ParamSpec, ...]:
    """The battery library's and the low-battery failsafe's parameters (PX4's names, ranges and
    defaults; :mod:`autopilot.battery.estimator`), and PX4's battery-simulator parameters. The
    vehicle's ``[battery]`` gives the defaults of the cell count, capacity, cell voltages, internal
    resistance (its pack's, per cell), average current and the ``SIM_BAT_*``, as a PX4 airframe
    file sets them. (PX4's default ``BAT1_R_INTERNAL`` is -1, estimated online: in a steady hover
    the estimate barely leaves its 5 mOhm start, and the charge then reads low.)"""
    b = vehicle.battery if vehicle is not None else BatteryConfig()

    def sim(name: str, default: float, kind: str, description: str) -> ParamSpec:
        lo, hi, unit, key = SIM_BATTERY_PARAMETERS[name]
        return ParamSpec(name, default, lo, hi, kind=kind, unit=unit,
                         description=f"{description} (the vehicle's [battery] {key} at start)")  # fmt: skip

    return (
        ParamSpec("BAT1_N_CELLS", b.cells, 0, 16, kind=INT32,
                  description="cells in series (0: not configured, no charge estimate)"),
        ParamSpec("BAT1_V_EMPTY", b.empty_cell_v, 2.5, 4.2, unit="V",
                  description="cell voltage at 0 % charge"),
        ParamSpec("BAT1_V_CHARGED", b.charged_cell_v, 3.0, 4.5, unit="V",
                  description="cell voltage at 100 % charge, under a mild load"),
        ParamSpec("BAT1_CAPACITY", b.capacity_mah, -1.0, 100000.0, unit="mAh",
                  description="capacity (-1: unknown: the charge from the voltage alone, no time remaining)"),
        ParamSpec("BAT1_R_INTERNAL", round(min(b.internal_resistance_ohm / b.cells, 0.2), 6), -1.0, 0.2,
                  unit="Ohm",
                  description="internal resistance per cell for the load compensation (negative: estimated "
                              "online)"),
        ParamSpec("BAT_LOW_THR", 0.15, 0.12, 0.5, unit="norm",
                  description="low battery below this charge (warning); above BAT_CRIT_THR"),
        ParamSpec("BAT_CRIT_THR", 0.07, 0.05, 0.25, unit="norm",
                  description="critical battery below this charge (COM_LOW_BAT_ACT; arming refused)"),
        ParamSpec("BAT_EMERGEN_THR", 0.05, 0.03, 0.1, unit="norm",
                  description="emergency battery below this charge (COM_LOW_BAT_ACT); below BAT_CRIT_THR"),
        ParamSpec("BAT_AVRG_CURRENT", b.average_current_a, 0.0, 500.0, unit="A",
                  description="expected current in flight: starts the average of the time remaining"),
        ParamSpec("COM_LOW_BAT_ACT", LOW_BAT_WARN, 0, 3, kind=INT32,
                  description="battery failsafe: 0 warning, 1 return, 2 land, 3 return at critical and land "
                              "at emergency (PX4 values)"),
        sim("SIM_BAT_ENABLE", 1 if b.enabled else 0, INT32, "simulated battery monitor on"),
        sim("SIM_BAT_DRAIN", b.drain_s, FLOAT,
            "simulated battery: 0 the pack model; > 0 PX4's linear drain, full to empty in this time "
            "while armed"),
        sim("SIM_BAT_MIN_PCT", b.drain_min_pct, FLOAT, "simulated battery: PX4's linear drain stops here"),
    )  # fmt: skip

# COM_POSCTL_NAVL (PX4): what POSCTL does when its position estimate goes: 0 fly on in ALTCTL (then
# STABILIZED), 1 land (then descend).
POSCTL_NAVL_ALTITUDE, POSCTL_NAVL_LAND = 0, 1
# COM_POS_LOW_ACT (PX4's values, as GF_ACTION's): the low position accuracy failsafe.
POS_LOW_NONE, POS_LOW_WARN, POS_LOW_HOLD, POS_LOW_RTL, POS_LOW_TERMINATE, POS_LOW_LAND = 0, 1, 2, 3, 4, 5

# What the vehicle does when an estimate or a sensor goes bad (autopilot/commander/health.py, the
# mode requirements and fallbacks of autopilot/commander/failsafe.py): PX4's names and defaults.
NAVIGATION_FAILSAFE_PARAMS = (
    ParamSpec("COM_POS_FS_EPH", 5.0, -1.0, 400.0, unit="m",
              description="horizontal position 1-sigma above which the position is invalid (2.5x while "
                          "valid: hysteresis; -1 no accuracy check)"),
    ParamSpec("COM_VEL_FS_EVH", 1.0, 0.0, 100.0, unit="m/s",
              description="horizontal velocity 1-sigma above which the velocity is invalid "
                          "(2.5x while valid)"),
    ParamSpec("COM_POS_LOW_EPH", -1.0, -1.0, 1000.0, unit="m",
              description="position still valid but less accurate than this: COM_POS_LOW_ACT in AUTO.MISSION "
                          "and AUTO.LOITER (-1 disabled)"),
    ParamSpec("COM_POS_LOW_ACT", POS_LOW_RTL, 0, 5, kind=INT32,
              description="low position accuracy action: 0 none, 1 warning, 2 hold, 3 return, 5 land "
                          "(PX4 values)",
              refused={float(POS_LOW_TERMINATE): "terminating on a low accuracy is not supported"}),
    ParamSpec("COM_POSCTL_NAVL", POSCTL_NAVL_ALTITUDE, 0, 1, kind=INT32,
              description="POSCTL without a position: 0 ALTCTL (then STABILIZED), 1 land (then descend)"),
)  # fmt: skip

# The flight log (autopilot/logger/): PX4's SDLOG_MODE values; 3 (by an RC switch) is not supported.
LOGGER_PARAMS = (
    ParamSpec(
        "SDLOG_MODE", 0, -1, 4, kind=INT32,
        description="flight log (ULog): -1 off, 0 from arming to disarming, 1 from boot until disarming, "
        "2 from boot until shutdown, 4 from the first arming until shutdown (PX4 values)",
        refused={3.0: "logging by an RC switch (AUX1) is not supported"},
    ),
)  # fmt: skip

# Failure injection (MAV_CMD_INJECT_FAILURE, autopilot/mavlink/failure_injection.py): PX4's switch.
FAILURE_PARAMS = (
    ParamSpec(
        "SYS_FAILURE_EN", 0, 0, 1, kind=INT32,
        description="enable failure injection (MAV_CMD_INJECT_FAILURE, quadsitl fail): 0 refused (PX4's "
        "default), 1 accepted. The failures can easily cause crashes: use with caution",
    ),
    ParamSpec(
        MOTOR_EFFECTIVENESS_PARAMETER, MOTOR_EFFECTIVENESS_DEFAULT, 0.0, 1.0,
        description="the effectiveness (fraction of thrust and reaction torque) a motor keeps under an "
        "injected 'wrong' failure (a loss of effectiveness) whose command gives none in param4",
    ),
)  # fmt: skip

RATES_READ_ONLY = (
    "fixed by config/sitl.toml [rates] for simulator and autopilot (lockstep); edit it and restart"
)

def controller_params(config: ControllerConfig) -> tuple[ParamSpec, ...]:
    """Parameters of the cascade ``config`` (defaults = the config's values): those its two laws
    declare (:mod:`autopilot.control.registry`), the tilt limit and the command filter."""
    tr = registry.law(registry.TRANSLATIONAL, config.translational.law)
    rot = registry.law(registry.ROTATIONAL, config.rotational.law)
    cf = config.command_filter
    return (
        *tr.parameters(config.translational),
        ParamSpec("BS_TILT_MAX", config.tilt_max_rad, 0.05, 1.4, unit="rad",
                  description="tilt limit of phi_r, theta_r"),
        *rot.parameters(config.rotational),
        ParamSpec("CF_WN", cf.natural_frequency_rad_s, 1.0, 1000.0, unit="rad/s",
                  description="command filter natural frequency (roll/pitch references)"),
        ParamSpec("CF_ZETA", cf.damping, 0.1, 5.0, description="command filter damping ratio"),
    )  # fmt: skip


def rate_params(rates: Rates) -> tuple[ParamSpec, ...]:
    """The SITL rates, reported read-only."""
    return (
        ParamSpec("SITL_PHYS_HZ", rates.physics_hz, rates.physics_hz, rates.physics_hz, unit="Hz",
                  description="simulator physics rate", read_only=RATES_READ_ONLY),
        ParamSpec("SITL_CTRL_HZ", rates.control_hz, rates.control_hz, rates.control_hz, unit="Hz",
                  description="control rate (one step per sensor frame)", read_only=RATES_READ_ONLY),
        ParamSpec("SITL_GPS_HZ", rates.gps_hz, rates.gps_hz, rates.gps_hz, unit="Hz",
                  description="HIL_GPS rate", read_only=RATES_READ_ONLY),
    )  # fmt: skip


ESTIMATOR_SWITCH = ParamSpec(
    "EKF2_EN", 0, 0, 1, kind=INT32,
    description="1: fly on the EKF's estimate of HIL_SENSOR/HIL_GPS/vision; 0: on the simulator's "
    "truth (the paper's assumption). A change takes effect while disarmed",
)  # fmt: skip


def hover_thrust_param(vehicle: VehicleConfig | None = None) -> ParamSpec:
    """``MPC_THR_HOVER``: the normalised thrust (U1 / U1_max) of the centred throttle in STABILIZED and
    ACRO. PX4's default is 0.5 (its airframes'); here it is the vehicle's own hover thrust, the
    nominal ``m g / thrust_max_n`` (0.259 for the paper's quadrotor), when the vehicle is known."""
    hover = 0.5
    if vehicle is not None:
        nominal = vehicle.nominal
        hover = nominal.mass_kg * nominal.gravity_m_s2 / vehicle.actuation.thrust_max_n
    return ParamSpec("MPC_THR_HOVER", round(min(max(hover, 0.1), 0.8), 3), 0.1, 0.8,
                     description="STABILIZED, ACRO: thrust at the centred throttle (of U1_max); default: "
                                 "the vehicle's m g / U1_max")  # fmt: skip


def default_parameters(
    controller: ControllerConfig | None = None,
    rates: Rates | None = None,
    estimator: bool = False,
    vehicle: VehicleConfig | None = None,
) -> ParameterStore:
    """Commander and failsafe parameters, plus the gains of ``controller`` and ``rates`` if given,
    and the estimator's (EKF2_EN and the EKF2_* of :mod:`autopilot.estimation.parameters`);
    ``vehicle`` gives ``MPC_THR_HOVER`` its default (:func:`hover_thrust_param`) and the battery's
    (:func:`battery_params`)."""
    specs = [*COMMANDER_PARAMS, hover_thrust_param(vehicle), *FAILSAFE_PARAMS, *NAVIGATION_FAILSAFE_PARAMS,
             *battery_params(vehicle), *LOGGER_PARAMS, *FAILURE_PARAMS]  # fmt: skip
    if controller is not None:
        specs += controller_params(controller)
    if rates is not None:
        specs += rate_params(rates)
    if estimator:
        from ..estimation.parameters import ESTIMATOR_PARAMS

        specs += [ESTIMATOR_SWITCH, *ESTIMATOR_PARAMS]
    return ParameterStore(specs)


def controller_config_from_params(base: ControllerConfig, params: ParameterStore) -> ControllerConfig:
    """``base`` with every gain that ``params`` holds replaced by its current value."""
    tr = registry.law(registry.TRANSLATIONAL, base.translational.law)
    rot = registry.law(registry.ROTATIONAL, base.rotational.law)
    values = params.values
    cf = base.command_filter
    return replace(
        base,
        translational=tr.gains_from_params(base.translational, values),
        rotational=rot.gains_from_params(base.rotational, values),
        tilt_max_rad=params.get("BS_TILT_MAX", base.tilt_max_rad),
        command_filter=replace(cf, natural_frequency_rad_s=params.get("CF_WN", cf.natural_frequency_rad_s),
                               damping=params.get("CF_ZETA", cf.damping)),
    )  # fmt: skip


def consistency_problems(params: ParameterStore) -> list[str]:
    """Combinations of individually valid values that make no sense (pre-arm: "bad parameters").

    * with a vertical geofence, the takeoff altitude and the return altitude must lie inside it
      (else takeoff or RTL would breach the fence by themselves);
    * the takeoff and landing speeds must respect the climb and descent limits;
    * the battery's levels in order (``BAT_EMERGEN_THR`` < ``BAT_CRIT_THR`` < ``BAT_LOW_THR``, as
      PX4 asks) and its empty cell below its charged one.
    """
    p = params
    problems = []
    fence_z = p["GF_MAX_VER_DIST"]
    if fence_z > 0.0:
        if p["MIS_TAKEOFF_ALT"] >= fence_z:
            problems.append(
                f"MIS_TAKEOFF_ALT {p['MIS_TAKEOFF_ALT']:g} m is not below GF_MAX_VER_DIST {fence_z:g} m"
            )
        if p["RTL_RETURN_ALT"] >= fence_z:
            problems.append(
                f"RTL_RETURN_ALT {p['RTL_RETURN_ALT']:g} m is not below GF_MAX_VER_DIST {fence_z:g} m"
            )
    if p["MPC_TKO_SPEED"] > p["MPC_Z_VEL_MAX_UP"]:
        problems.append(
            f"MPC_TKO_SPEED {p['MPC_TKO_SPEED']:g} m/s exceeds MPC_Z_VEL_MAX_UP {p['MPC_Z_VEL_MAX_UP']:g} m/s"
        )
    if p["MPC_LAND_SPEED"] > p["MPC_Z_VEL_MAX_DN"]:
        problems.append(
            f"MPC_LAND_SPEED {p['MPC_LAND_SPEED']:g} m/s exceeds "
            f"MPC_Z_VEL_MAX_DN {p['MPC_Z_VEL_MAX_DN']:g} m/s"
        )
    if "BAT_LOW_THR" in p:
        low, critical, emergency = p["BAT_LOW_THR"], p["BAT_CRIT_THR"], p["BAT_EMERGEN_THR"]
        if not emergency < critical < low:
            problems.append(f"battery levels out of order: BAT_EMERGEN_THR {emergency:g} < BAT_CRIT_THR "
                            f"{critical:g} < BAT_LOW_THR {low:g} is needed")  # fmt: skip
        if p["BAT1_V_EMPTY"] >= p["BAT1_V_CHARGED"]:
            problems.append(f"BAT1_V_EMPTY {p['BAT1_V_EMPTY']:g} V is not below BAT1_V_CHARGED "
                            f"{p['BAT1_V_CHARGED']:g} V")  # fmt: skip
    return problems
