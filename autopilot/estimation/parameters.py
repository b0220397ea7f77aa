"""The estimator's parameters: PX4 EKF2 names, units and defaults where PX4 has the parameter.

:data:`ESTIMATOR_PARAMS` declares them as :class:`~autopilot.params.store.ParamSpec` (the form of
``autopilot/params/definitions.py``), so the autopilot can add them to its parameter table;
:class:`EstimatorParams` is the frozen record the filter reads, in SI units (delays in seconds),
built from any name -> value mapping (a :class:`ParameterStore`, a dict) by
:func:`estimator_params`, or from ``config/estimator/NAME.toml`` by :func:`load_estimator_params`.

How PX4's noise parameters are read (and why). PX4's EKF2 predicts its covariance every
``EKF2_PREDICT_US`` (10 ms) and adds ``(dt * EKF2_GYR_NOISE)^2`` of angle variance per prediction
(``covariance.cpp``), so a parameter in rad/s is a per-step standard deviation, not a density.
This filter predicts at every IMU sample (2 ms at 500 Hz) and would add five times less noise per
second with the same formula. It therefore converts each PX4 figure into the continuous density
that gives PX4's variance *per second*: ``density = value * sqrt(EKF2_PREDICT_US)``, e.g.
EKF2_GYR_NOISE 0.015 rad/s -> 1.5e-3 rad/s/sqrt(Hz), EKF2_ACC_NOISE 0.35 m/s^2 -> 0.035
m/s^2/sqrt(Hz); likewise for the bias random walks (EKF2_GYR_B_NOISE 1e-3 rad/s^2 -> 1e-4 rad/s
per sqrt(s)). The same parameter values then mean the same filter as PX4's, whatever our rate.

Measurement noises are floors, as in PX4: a GPS fix's reported ``eph``/``epv``/speed accuracy and a
vision pose's reported standard deviations are used when larger (EKF2_EV_NOISE_MD = 0). A floor
above the sensor's real noise makes the filter report a larger error than it has (the accuracies
ground stations and failsafes read): an estimator profile sets the floors at or below its sensors'
figures (``config/estimator/mocap.toml``).

Parameters PX4 does not have carry the prefix ``EST_``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from autopilot.params.storage import load_params_file
from autopilot.params.store import INT32, ParameterStore, ParamSpec
from quadcommon.config import config_path

# EKF2_MAG_TYPE (PX4 values): 0 automatic (3-axis field fusion here), 1 heading only, 5 none.
MAG_TYPE_AUTO, MAG_TYPE_HEADING, MAG_TYPE_NONE = 0, 1, 5
# EKF2_GPS_CTRL bits (PX4): 0 lon/lat, 1 altitude, 2 3D velocity (3 dual-antenna yaw: unsupported).
GPS_CTRL_HPOS, GPS_CTRL_VPOS, GPS_CTRL_VEL = 1, 2, 4
# EKF2_EV_CTRL bits (PX4): 0 horizontal position, 1 vertical position, 2 velocity, 3 yaw.
EV_CTRL_HPOS, EV_CTRL_VPOS, EV_CTRL_VEL, EV_CTRL_YAW = 1, 2, 4, 8
# EKF2_MAG_CHECK bits (PX4): 0 field strength, 1 inclination (2 "wait for WMM": not applicable).
MAG_CHECK_STRENGTH, MAG_CHECK_INCLINATION = 1, 2

_UNSUPPORTED_MAG_TYPE = {
    2.0: "not a PX4 value",
    3.0: "not a PX4 value",
    4.0: "not a PX4 value",
    6.0: "'Init' (heading at start only) is not supported",
}

ESTIMATOR_PARAMS: tuple[ParamSpec, ...] = (
    # -- IMU process noise (PX4 per-prediction figures; see the module docstring) -------------
    ParamSpec(
        "EKF2_PREDICT_US",
        10000,
        1000,
        20000,
        kind=INT32,
        unit="us",
        description="PX4's prediction period: the reference that turns the *_NOISE figures into densities",
    ),
    ParamSpec(
        "EKF2_GYR_NOISE",
        0.015,
        0.0001,
        0.1,
        unit="rad/s",
        description="rate gyro noise for covariance prediction",
    ),
    ParamSpec(
        "EKF2_ACC_NOISE",
        0.35,
        0.01,
        1.0,
        unit="m/s^2",
        description="accelerometer noise for covariance prediction",
    ),
    ParamSpec(
        "EKF2_GYR_B_NOISE", 0.001, 0.0, 0.01, unit="rad/s^2", description="process noise of the gyro bias"
    ),
    ParamSpec(
        "EKF2_ACC_B_NOISE",
        0.003,
        0.0,
        0.01,
        unit="m/s^3",
        description="process noise of the accelerometer bias",
    ),
    ParamSpec(
        "EKF2_MAG_B_NOISE",
        0.0001,
        0.0,
        0.1,
        unit="gauss/s",
        description="process noise of the body magnetic bias",
    ),
    ParamSpec(
        "EKF2_GBIAS_INIT",
        0.1,
        0.0,
        0.2,
        unit="rad/s",
        description="1-sigma gyro switch-on bias (used when alignment cannot measure it)",
    ),
    ParamSpec(
        "EKF2_ABIAS_INIT", 0.2, 0.0, 0.5, unit="m/s^2", description="1-sigma accelerometer switch-on bias"
    ),
    ParamSpec(
        "EKF2_ANGERR_INIT",
        0.1,
        0.0,
        0.5,
        unit="rad",
        description="1-sigma tilt uncertainty after alignment (floor on the computed one)",
    ),
    # -- GNSS -------------------------------------------------------------------------------
    ParamSpec(
        "EKF2_GPS_CTRL",
        7,
        0,
        7,
        kind=INT32,
        description="GNSS aiding bits: 0 lon/lat, 1 altitude, 2 3D velocity",
    ),
    ParamSpec(
        "EKF2_GPS_DELAY",
        110.0,
        0.0,
        300.0,
        unit="ms",
        description="GPS measurement delay relative to the IMU",
    ),
    ParamSpec(
        "EKF2_GPS_P_NOISE", 0.5, 0.01, 10.0, unit="m", description="GNSS position noise (floor on eph/epv)"
    ),
    ParamSpec(
        "EKF2_GPS_V_NOISE",
        0.3,
        0.01,
        5.0,
        unit="m/s",
        description="GNSS velocity noise (floor on the speed accuracy)",
    ),
    ParamSpec(
        "EKF2_GPS_P_GATE", 5.0, 1.0, 100.0, unit="SD", description="gate of the GNSS position innovation test"
    ),
    ParamSpec(
        "EKF2_GPS_V_GATE", 5.0, 1.0, 100.0, unit="SD", description="gate of the GNSS velocity innovation test"
    ),
    ParamSpec("EKF2_REQ_EPH", 3.0, 2.0, 100.0, unit="m", description="required eph to use a GPS fix"),
    ParamSpec("EKF2_REQ_EPV", 5.0, 2.0, 100.0, unit="m", description="required epv to use a GPS fix"),
    ParamSpec(
        "EKF2_REQ_NSATS", 6, 4, 12, kind=INT32, description="required satellite count to use a GPS fix"
    ),
    # -- barometer --------------------------------------------------------------------------
    ParamSpec("EKF2_BARO_CTRL", 1, 0, 1, kind=INT32, description="barometric height aiding"),
    ParamSpec("EKF2_BARO_RATE", 20.0, 1.0, 200.0, unit="Hz", description="maximum barometer fusion rate"),
    ParamSpec(
        "EKF2_BARO_DELAY", 0.0, 0.0, 300.0, unit="ms", description="barometer delay relative to the IMU"
    ),
    ParamSpec("EKF2_BARO_NOISE", 3.5, 0.01, 15.0, unit="m", description="barometric height noise"),
    ParamSpec(
        "EKF2_BARO_GATE", 5.0, 1.0, 100.0, unit="SD", description="gate of the baro and GPS height tests"
    ),
    ParamSpec(
        "EST_BARO_B_NSD",
        0.005,
        0.0,
        1.0,
        unit="m/sqrt(s)",
        description="random walk of the baro height offset state (not in PX4's EKF2)",
    ),
    # -- magnetometer -----------------------------------------------------------------------
    ParamSpec(
        "EKF2_MAG_TYPE",
        MAG_TYPE_AUTO,
        0,
        6,
        kind=INT32,
        description="magnetometer fusion: 0 automatic (3-axis field), 1 heading, 5 none",
        refused=_UNSUPPORTED_MAG_TYPE,
    ),
    ParamSpec("EKF2_MAG_RATE", 15.0, 1.0, 200.0, unit="Hz", description="maximum magnetometer fusion rate"),
    ParamSpec(
        "EKF2_MAG_DELAY", 0.0, 0.0, 300.0, unit="ms", description="magnetometer delay relative to the IMU"
    ),
    ParamSpec("EKF2_MAG_NOISE", 0.05, 0.001, 1.0, unit="gauss", description="magnetometer 3-axis noise"),
    ParamSpec(
        "EKF2_MAG_GATE", 3.0, 1.0, 100.0, unit="SD", description="gate of the magnetometer 3-axis test"
    ),
    ParamSpec(
        "EKF2_HEAD_NOISE", 0.3, 0.01, 1.0, unit="rad", description="magnetic heading noise (EKF2_MAG_TYPE 1)"
    ),
    ParamSpec(
        "EKF2_HDG_GATE",
        2.6,
        1.0,
        100.0,
        unit="SD",
        description="gate of the heading tests (mag heading, vision yaw)",
    ),
    ParamSpec(
        "EKF2_MAG_CHECK", 1, 0, 7, kind=INT32, description="field checks: bit 0 strength, bit 1 inclination"
    ),
    ParamSpec(
        "EKF2_MAG_CHK_STR", 0.2, 0.0, 1.0, unit="gauss", description="tolerance of the field strength check"
    ),
    ParamSpec(
        "EKF2_MAG_CHK_INC",
        20.0,
        0.0,
        90.0,
        unit="deg",
        description="tolerance of the field inclination check",
    ),
    ParamSpec(
        "EST_MAG_B_INIT",
        0.01,
        0.0,
        0.5,
        unit="gauss",
        description="1-sigma hard iron left after calibration (prior of the body magnetic bias)",
    ),
    # -- external vision / motion capture -----------------------------------------------------
    ParamSpec(
        "EKF2_EV_CTRL",
        EV_CTRL_HPOS | EV_CTRL_VPOS | EV_CTRL_YAW,
        0,
        15,
        kind=INT32,
        description="vision aiding bits: 0 horizontal pos, 1 vertical pos, 2 velocity, 3 yaw (PX4's default "
        "is 0; here vision is fused when it comes)",
    ),
    ParamSpec("EKF2_EV_DELAY", 0.0, 0.0, 300.0, unit="ms", description="vision delay relative to the IMU"),
    ParamSpec(
        "EKF2_EV_NOISE_MD",
        0,
        0,
        1,
        kind=INT32,
        description="0: the reported noise with the parameters as floor, 1: the parameters only",
    ),
    # PX4's minimums are 0.01 m and 0.05 rad; a motion capture reports a millimetre and a few mrad,
    # and with those minimums as floors the filter would claim ten times its real error.
    ParamSpec("EKF2_EVP_NOISE", 0.1, 0.0001, 10.0, unit="m", description="vision position noise"),
    ParamSpec("EKF2_EVA_NOISE", 0.1, 0.0005, 1.0, unit="rad", description="vision angle (yaw) noise"),
    ParamSpec("EKF2_EVP_GATE", 5.0, 1.0, 100.0, unit="SD", description="gate of the vision position test"),
    ParamSpec("EKF2_EVV_NOISE", 0.1, 0.01, 10.0, unit="m/s", description="vision velocity noise"),
    ParamSpec("EKF2_EVV_GATE", 3.0, 1.0, 100.0, unit="SD", description="gate of the vision velocity test"),
    ParamSpec(
        "EKF2_EV_QMIN",
        0,
        0,
        100,
        kind=INT32,
        description="minimum ODOMETRY quality fused (a client's vision; -1, failed, is always refused)",
    ),
    # -- health and start-up ----------------------------------------------------------------
    ParamSpec(
        "EKF2_NOAID_TOUT",
        5000000,
        500000,
        10000000,
        kind=INT32,
        unit="us",
        description="longest inertial dead reckoning before the horizontal solution is reported invalid",
    ),
    ParamSpec("EST_ALIGN_T", 1.0, 0.1, 10.0, unit="s", description="static alignment time (IMU at rest)"),
    ParamSpec(
        "EST_POS_RST_T",
        7.0,
        1.0,
        60.0,
        unit="s",
        description="reset to the position source after this long of rejected positions (PX4's internal 7 s)",
    ),
    ParamSpec("EST_CONV_TILT", 2.0, 0.1, 30.0, unit="deg", description="converged: tilt 1-sigma below this"),
    ParamSpec("EST_CONV_YAW", 5.0, 0.1, 90.0, unit="deg", description="converged: yaw 1-sigma below this"),
    ParamSpec(
        "EST_CONV_POS",
        1.0,
        0.01,
        50.0,
        unit="m",
        description="converged: horizontal position 1-sigma below this",
    ),
    ParamSpec(
        "EST_CONV_VPOS",
        0.3,
        0.01,
        50.0,
        unit="m",
        description="converged: vertical position 1-sigma below this",
    ),
)


@dataclass(frozen=True)
class EstimatorParams:
    """The filter's parameters in SI units (see :data:`ESTIMATOR_PARAMS` for names and ranges)."""

    # IMU process noise as continuous densities (converted from PX4's per-prediction figures)
    gyro_noise_density: float  # rad/s/sqrt(Hz)
    accel_noise_density: float  # m/s^2/sqrt(Hz)
    gyro_bias_rw: float  # rad/s/sqrt(s)
    accel_bias_rw: float  # m/s^2/sqrt(s)
    mag_bias_rw: float  # gauss/sqrt(s)
    baro_bias_rw: float  # m/sqrt(s)
    gyro_bias_init: float  # rad/s, 1-sigma
    accel_bias_init: float  # m/s^2, 1-sigma
    tilt_init: float  # rad, floor of the alignment's 1-sigma tilt
    # GNSS
    gps_ctrl: int
    gps_delay_s: float
    gps_pos_noise_m: float
    gps_vel_noise_m_s: float
    gps_pos_gate: float
    gps_vel_gate: float
    gps_req_eph_m: float
    gps_req_epv_m: float
    gps_req_nsats: int
    # barometer
    baro_enabled: bool
    baro_period_s: float  # 1 / EKF2_BARO_RATE
    baro_delay_s: float
    baro_noise_m: float
    baro_gate: float  # also the GPS height gate, as in PX4
    # magnetometer
    mag_type: int
    mag_period_s: float  # 1 / EKF2_MAG_RATE
    mag_bias_init_gauss: float
    mag_delay_s: float
    mag_noise_gauss: float
    mag_gate: float
    heading_noise_rad: float
    heading_gate: float
    mag_check: int
    mag_strength_tol_gauss: float
    mag_inclination_tol_rad: float
    # vision
    ev_ctrl: int
    ev_delay_s: float
    ev_noise_mode: int
    ev_pos_noise_m: float
    ev_yaw_noise_rad: float
    ev_pos_gate: float
    ev_vel_noise_m_s: float
    ev_vel_gate: float
    # health and start-up
    no_aid_timeout_s: float
    align_time_s: float
    pos_reset_timeout_s: float
    converged_tilt_rad: float
    converged_yaw_rad: float
    converged_pos_m: float
    converged_vpos_m: float


def estimator_params(values: Mapping[str, float] | ParameterStore | None = None) -> EstimatorParams:
    """:class:`EstimatorParams` from parameter values by name (defaults for the missing ones)."""
    v = {spec.name: float(spec.default) for spec in ESTIMATOR_PARAMS}
    if values is not None:
        names = values.names() if isinstance(values, ParameterStore) else list(values)
        for name in names:
            if name in v:
                v[name] = float(values[name])
    ref = math.sqrt(v["EKF2_PREDICT_US"] * 1e-6)  # sqrt(s): PX4's per-step figure -> density
    return EstimatorParams(
        gyro_noise_density=v["EKF2_GYR_NOISE"] * ref,
        accel_noise_density=v["EKF2_ACC_NOISE"] * ref,
        gyro_bias_rw=v["EKF2_GYR_B_NOISE"] * ref,
        accel_bias_rw=v["EKF2_ACC_B_NOISE"] * ref,
        mag_bias_rw=v["EKF2_MAG_B_NOISE"] * ref,
        baro_bias_rw=v["EST_BARO_B_NSD"],
        gyro_bias_init=v["EKF2_GBIAS_INIT"],
        accel_bias_init=v["EKF2_ABIAS_INIT"],
        tilt_init=v["EKF2_ANGERR_INIT"],
        gps_ctrl=int(v["EKF2_GPS_CTRL"]),
        gps_delay_s=v["EKF2_GPS_DELAY"] * 1e-3,
        gps_pos_noise_m=v["EKF2_GPS_P_NOISE"],
        gps_vel_noise_m_s=v["EKF2_GPS_V_NOISE"],
        gps_pos_gate=v["EKF2_GPS_P_GATE"],
        gps_vel_gate=v["EKF2_GPS_V_GATE"],
        gps_req_eph_m=v["EKF2_REQ_EPH"],
        gps_req_epv_m=v["EKF2_REQ_EPV"],
        gps_req_nsats=int(v["EKF2_REQ_NSATS"]),
        baro_enabled=bool(v["EKF2_BARO_CTRL"]),
        baro_period_s=1.0 / v["EKF2_BARO_RATE"],
        baro_delay_s=v["EKF2_BARO_DELAY"] * 1e-3,
        baro_noise_m=v["EKF2_BARO_NOISE"],
        baro_gate=v["EKF2_BARO_GATE"],
        mag_type=int(v["EKF2_MAG_TYPE"]),
        mag_period_s=1.0 / v["EKF2_MAG_RATE"],
        mag_bias_init_gauss=v["EST_MAG_B_INIT"],
        mag_delay_s=v["EKF2_MAG_DELAY"] * 1e-3,
        mag_noise_gauss=v["EKF2_MAG_NOISE"],
        mag_gate=v["EKF2_MAG_GATE"],
        heading_noise_rad=v["EKF2_HEAD_NOISE"],
        heading_gate=v["EKF2_HDG_GATE"],
        mag_check=int(v["EKF2_MAG_CHECK"]),
        mag_strength_tol_gauss=v["EKF2_MAG_CHK_STR"],
        mag_inclination_tol_rad=math.radians(v["EKF2_MAG_CHK_INC"]),
        ev_ctrl=int(v["EKF2_EV_CTRL"]),
        ev_delay_s=v["EKF2_EV_DELAY"] * 1e-3,
        ev_noise_mode=int(v["EKF2_EV_NOISE_MD"]),
        ev_pos_noise_m=v["EKF2_EVP_NOISE"],
        ev_yaw_noise_rad=v["EKF2_EVA_NOISE"],
        ev_pos_gate=v["EKF2_EVP_GATE"],
        ev_vel_noise_m_s=v["EKF2_EVV_NOISE"],
        ev_vel_gate=v["EKF2_EVV_GATE"],
        no_aid_timeout_s=v["EKF2_NOAID_TOUT"] * 1e-6,
        align_time_s=v["EST_ALIGN_T"],
        pos_reset_timeout_s=v["EST_POS_RST_T"],
        converged_tilt_rad=math.radians(v["EST_CONV_TILT"]),
        converged_yaw_rad=math.radians(v["EST_CONV_YAW"]),
        converged_pos_m=v["EST_CONV_POS"],
        converged_vpos_m=v["EST_CONV_VPOS"],
    )


DEFAULT_PARAMS = estimator_params()
"""PX4's defaults (and ours for the ``EST_`` parameters)."""


def estimator_store(values: Mapping[str, float] | None = None) -> ParameterStore:
    """A :class:`ParameterStore` of :data:`ESTIMATOR_PARAMS` (values checked as a PARAM_SET is)."""
    store = ParameterStore(ESTIMATOR_PARAMS)
    if values:
        problem = store.set_many(values)
        if problem:
            raise ValueError(problem)
    return store


def load_estimator_params(name_or_path: str | Path = "default") -> EstimatorParams:
    """``config/estimator/NAME.toml`` (``NAME = value`` lines, PX4 names and units) validated
    against :data:`ESTIMATOR_PARAMS`; an error names the file, key, value and allowed range."""
    path = config_path("estimator", name_or_path)
    store = ParameterStore(ESTIMATOR_PARAMS)
    load_params_file(path, store)
    return estimator_params(store)
