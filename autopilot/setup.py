"""What one autopilot is before it runs: its configuration, loaded and validated, and the parameter
table it starts from.

:class:`AutopilotSetup` is built by the command line (:mod:`autopilot.__main__`), the launcher and
the in-process runner (:mod:`sitl.inprocess`); :func:`starting_parameters` gives the parameter
table of a setup (PX4's defaults and the vehicle's, the estimator profile's ``EKF2_*`` values, then
the parameters file), which :class:`~autopilot.core.AutopilotCore` flies with.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from quadcommon import wire
from quadcommon.build_info import BuildInfo
from quadcommon.config import SitlConfig, VehicleConfig, config_path, load_scenario, load_sitl, load_vehicle
from quadcommon.schema import ConfigError
from quadcommon.trajectories import Trajectory, trajectory_from_spec

from .control.config import ControllerConfig, load_controller
from .estimation.parameters import load_estimator_params
from .logger.logger import LogOptions
from .mavlink.signing import SigningOptions
from .params.definitions import consistency_problems, default_parameters
from .params.storage import load_params_file
from .params.store import ParameterStore

ESTIMATORS = ("truth", "ekf")


@dataclass(frozen=True)
class AutopilotSetup:
    """What one autopilot is: configuration loaded and validated, nothing running."""

    sitl: SitlConfig
    vehicle: VehicleConfig
    controller: ControllerConfig
    instance: int = 0
    autostart: Trajectory | None = None  # armed at the first frame, flying this from t = 0
    use_odometry: bool = True  # the state from ODOMETRY (float32) or HIL_STATE_QUATERNION (1 cm)
    params_file: str | None = None  # params.toml: loaded at start if it exists, saved on change
    default_remotes: bool = True  # the GCS/API links send to 14550 / 14540+N (wire.ports) before anyone talks
    signing: SigningOptions = SigningOptions()  # MAVLink 2 signing on the GCS links: key, state, wall clock
    estimator: str = "truth"  # "truth": fly on the simulator's state; "ekf": on the EKF (EKF2_EN)
    estimator_profile: str = "default"  # config/estimator/NAME.toml: the EKF2_* values to start from
    log: LogOptions = LogOptions()  # the flight log (ULog): where, and the wall clock for its UTC times
    build: BuildInfo = BuildInfo()  # version and git commit (AUTOPILOT_VERSION); the shell reads them

    @classmethod
    def load(
        cls,
        instance: int = 0,
        controller: str = "intbs_nlhinf",
        vehicle: str = "paper_quad",
        sitl_config: str | None = None,
        autostart: str | None = None,
        state_source: str = "odometry",
        params_file: str | None = None,
        estimator: str = "truth",
        estimator_profile: str = "default",
    ) -> AutopilotSetup:
        """By names (config/...), as the command line gives them; ConfigError names file and key."""
        trajectory = trajectory_from_spec(load_scenario(autostart).trajectory) if autostart else None
        if estimator not in ESTIMATORS:
            raise ConfigError(f"estimator {estimator!r}: one of {', '.join(ESTIMATORS)}")
        load_estimator_params(estimator_profile)  # a bad profile fails here, naming file and key
        return cls(
            load_sitl(sitl_config), load_vehicle(vehicle), load_controller(controller), instance,
            trajectory, state_source == "odometry", params_file, estimator=estimator,
            estimator_profile=estimator_profile,
        )  # fmt: skip


def starting_parameters(setup: AutopilotSetup, log: Callable[[str], None]) -> ParameterStore:
    """The parameter table ``setup`` flies with at start: the defaults (PX4's, the cascade's gains,
    the vehicle's), ``MAV_SYS_ID`` of the instance, ``EKF2_EN`` of ``setup.estimator``, the estimator
    profile's values, then the parameters file if it exists (ConfigError names file and key). An
    inconsistent table is kept (arming refuses until it is fixed) and its problems are logged."""
    params = default_parameters(setup.controller, setup.sitl.rates, estimator=True, vehicle=setup.vehicle)
    params.values["MAV_SYS_ID"] = float(wire.system_id(setup.instance))
    params.values["EKF2_EN"] = 1.0 if setup.estimator == "ekf" else 0.0
    load_params_file(config_path("estimator", setup.estimator_profile), params)
    if setup.params_file and Path(setup.params_file).exists():
        loaded = load_params_file(setup.params_file, params)
        log(f"{len(loaded)} parameters loaded from {setup.params_file}")
    for problem in consistency_problems(params):
        log(f"warning: parameters inconsistent (arming refused until fixed): {problem}")
    return params
