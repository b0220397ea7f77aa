"""Campaign specifications (``config/campaigns/NAME.toml``): what to fly, and what to randomise.

Validated like every configuration (:mod:`quadcommon.schema`): a wrong key, type or value is a
:class:`ConfigError` naming the file, the dotted key, the value and the allowed range; unknown
keys are refused.

Top level: ``name``, ``description``, ``scenario`` (``config/scenarios`` name or path: trajectory,
duration, nominal initial state, vehicle), ``controllers`` (cascade names), ``runs``, ``seed``;
optional ``vehicle`` (default: the scenario's), ``duration_s`` (default: the scenario's),
``wire_float32`` (default true: the state and controls cross as float32, as on the MAVLink
wire), ``chunk_runs`` (runs per task, default 20), ``[rates]`` (default ``config/sitl.toml``),
``[failure]`` (limits that end a run as failed).

Every randomised quantity is a *distribution*: a number (fixed), or a table with one of

* ``uniform = [low, high]``;
* ``normal = [mean, std]`` with ``clip = [lo, hi]`` (required where the quantity is bounded);
* ``choice = [a, b, ...]`` (equally likely).

``[plant]`` (the true vehicle the simulator flies; the controllers keep the nominal model):
``mass_scale``; ``inertia_scale`` (one distribution: a single draw scales Ixx, Iyy, Izz and the
products together, as the scenarios' +30 %; or a list of three: independent per axis, products
unscaled); ``com_offset_m`` and ``products_of_inertia_kg_m2`` (lists of three, absolute; default
the vehicle's); under ``actuation = "rotors"`` only: ``thrust_coefficient_scale``,
``drag_coefficient_scale``, ``rotor_time_constant_scale`` (the allocator keeps the nominal ones).

``[initial_state]``: ``position_offset_m``, ``euler_offset_rad`` (added to the scenario's),
``velocity_m_s`` (lists of three).

``[disturbances]``: ``base`` (a gust profile name, ``"scenario"`` or ``"none"``; default
``"none"``; without a ``[disturbances]`` table the scenario's profile is flown) plus randomised
elements, each key of the gust-profile format (:mod:`simulator.environment.gust_profile`)
a distribution: ``[[disturbances.step]]`` (``channel``, ``start_s``, ``value``, optional
``end_s``), ``[[disturbances.ramp]]``, ``[[disturbances.one_minus_cosine]]`` (``start_s``,
``duration_s``, ``amplitude_m_s``, ``axis`` or ``direction``), ``[disturbances.dryden]``
(``w20_m_s``, ``altitude_m``, optional ``airspeed_m_s``, ``start_s``, ``end_s``,
``mean_wind_m_s``, ``warm_start``; its ``seed`` is drawn per run unless fixed). Each run's
profile is then validated by the gust-profile parser itself.

On the estimate: ``estimator = "ekf"`` with ``sensors = "NAME"`` (a sensor profile,
``config/sensors``) flies the controllers on the autopilot's filter (its parameters:
``config/estimator/NAME.toml`` when there is one, as ``quadsitl up --sensors NAME`` picks them)
fed by the sensor models, each run with its own noise stream (``sensor_seed``, drawn per run).
``[sensor_parameters]`` draws the profile's figures per run (default: the profile's):
``accel_noise_density``, ``gyro_noise_density``, ``accel_turn_on_bias_std``,
``gyro_turn_on_bias_std``, ``mag_noise_std_gauss``, ``baro_noise_std_hpa``,
``gps_horizontal_noise_std_m``, ``gps_vertical_noise_std_m``, ``gps_velocity_noise_std_m_s``,
``vision_position_noise_std_m`` (a GNSS profile that reports its accuracy honestly reports the
drawn one). ``[[sensor_faults]]`` add faults per run: ``kind`` (``gps_glitch``, ``gps_outage``,
``mag_disturbance``, ``vision_outage``, ``accel_bias_step``, ``gyro_bias_step``, or a sensor
failure of :mod:`quadcommon.failures`: ``gps_off``, ``baro_stuck``, ...), ``start_s``,
``duration_s`` (default: to the end), ``value`` (three distributions: m, gauss, m/s^2 or rad/s;
default 0, a failure's the table's figure). ``kind`` may be drawn too: ``{ choice = ["gps_off",
"baro_stuck", ...] }`` (each equally likely; ``value`` then defaults to the drawn kind's figure).

Faults of the actuators: ``[[actuator_faults]]``, a motor's failure from a time on, as a scenario's
(:func:`quadcommon.failures.read_actuator_faults`) but drawn per run: ``motor`` (PX4's number, 1
right, 2 left, 3 front, 4 rear; 0 all; a distribution, e.g. ``{ choice = [1, 2, 3, 4] }``), ``type``
(``off``, ``stuck``, ``wrong``, or ``{ choice = [...] }`` of them), ``effectiveness`` (what a
``wrong`` motor keeps, in [0, 1]), ``start_s``. A spec that draws faults (of the actuators or the
sensors) has ``[survival]``: ``envelope_m`` (default 1 m: a run survived when it flew to its end
within this of the reference) and ``recovery_bound_m`` (default 0.1 m: it has recovered once its
error is back within this for good), and its results have the fault study's columns
(:data:`.engine.FAULT_COLUMNS`) and the faults drawn (``fault``).

(One module: one schema, validated in one place, with the messages naming file, key, value and
range.)
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from autopilot.control.config import ControllerConfig, load_controller
from autopilot.estimation.parameters import EstimatorParams, load_estimator_params
from quadcommon.config import (
    SHIPPED_CONFIG_DIR,
    Rates,
    ScenarioConfig,
    VehicleConfig,
    config_path,
    estimator_profile_for,
    load_rates,
    load_scenario,
    load_sitl,
    load_vehicle,
)
from quadcommon.failures import ACTUATOR_FAULT_TYPES, FAILURES, MOTOR_EFFECTIVENESS_DEFAULT, Unit
from quadcommon.schema import ConfigError, Section, load_toml
from simulator.environment.discrete_gust import (
    AXES,
    MAX_AMPLITUDE_M_S,
    MAX_DURATION_S,
    MIN_DURATION_S,
)
from simulator.environment.dryden import (
    LOW_ALTITUDE_LIMIT_M,
    MAX_AIRSPEED_M_S,
    MAX_MEAN_WIND_M_S,
    MAX_W20_M_S,
    MIN_AIRSPEED_M_S,
    MIN_ALTITUDE_M,
)
from simulator.environment.gust_profile import (
    CHANNELS,
    MAX_FORCE_N,
    MAX_TORQUE_N_M,
    GustProfile,
    load_gust_profile,
)
from simulator.sensors.config import FAULT_KINDS, SensorConfig, default_fault_value, load_sensors

from .engine import FailureLimits, SurvivalLimits

CAMPAIGN_DIR = SHIPPED_CONFIG_DIR / "campaigns"  # the shipped campaigns
MAX_RUNS = 1_000_000
# Bumped whenever the kernels or the sampling change what a run produces (results on disk from
# another version are then not mixed in on resume).
ENGINE_VERSION = "campaign-engine-4"
MAX_TIME_S = 1e6


# -------------------------------------------------------------------------------------------------
# Distributions
# -------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Distribution:
    """One randomised scalar. ``kind`` is "fixed", "uniform", "normal" or "choice"."""

    kind: str
    params: tuple[float, ...]
    clip: tuple[float, float] | None = None

    @property
    def varies(self) -> bool:
        """Whether draws can differ: a uniform with distinct bounds, a choice among distinct values or a
        normal with a positive standard deviation."""
        if self.kind == "fixed":
            return False
        if self.kind == "uniform":
            return self.params[0] != self.params[1]
        if self.kind == "choice":
            return len(set(self.params)) > 1
        return self.params[1] > 0.0

    def sample(self, rng) -> float:
        """One draw from ``rng`` (a ``numpy.random.Generator`` private to this quantity and run)."""
        if self.kind == "fixed":
            return self.params[0]
        if self.kind == "uniform":
            return float(rng.uniform(self.params[0], self.params[1]))
        if self.kind == "choice":
            return float(self.params[int(rng.integers(len(self.params)))])
        value = float(rng.normal(self.params[0], self.params[1]))
        if self.clip is not None:
            value = min(max(value, self.clip[0]), self.clip[1])
        return value

    def support(self) -> tuple[float, float]:
        """Smallest and largest value a draw can take."""
        if self.kind in ("fixed", "choice"):
            return min(self.params), max(self.params)
        if self.kind == "uniform":
            return self.params[0], self.params[1]
        return self.clip if self.clip is not None else (-math.inf, math.inf)

    def describe(self) -> str:
        """The distribution in notation, e.g. ``U[0.8, 1.2]`` or ``N(1, 0.1^2) clipped to [0.5, 1.5]``."""
        if self.kind == "fixed":
            return f"{self.params[0]:g}"
        if self.kind == "uniform":
            return f"U[{self.params[0]:g}, {self.params[1]:g}]"
        if self.kind == "choice":
            return "one of {" + ", ".join(f"{v:g}" for v in self.params) + "}"
        text = f"N({self.params[0]:g}, {self.params[1]:g}^2)"
        return text + (f" clipped to [{self.clip[0]:g}, {self.clip[1]:g}]" if self.clip else "")


def fixed(value: float) -> Distribution:
    """The distribution that always draws ``value``."""
    return Distribution("fixed", (float(value),))


def _range_text(lo: float, hi: float, unit: str) -> str:
    return f"[{lo:g}, {hi:g}]" + (f" ({unit})" if unit else "")


def read_distribution(
    sec: Section, key: str, default: Any, lo: float, hi: float, unit: str = ""
) -> Distribution:
    """A distribution under ``sec.key`` whose every draw lies in ``[lo, hi]``."""
    allowed = _range_text(lo, hi, unit)
    raw = sec.data.get(key, default) if sec.has(key) else default
    sec._used.add(key)  # noqa: SLF001  (Section's own bookkeeping of the keys read)
    if raw is None:
        raise ConfigError(f"{sec.source}: missing key '{sec.key_name(key)}'")
    if isinstance(raw, Distribution):
        return raw
    if not isinstance(raw, dict):
        value = sec._check_number(key, raw, lo, hi, False, False, unit)  # noqa: SLF001
        return fixed(value)
    table = Section(raw, sec.source, f"{sec.key_name(key)}.")
    kinds = [k for k in ("uniform", "normal", "choice") if table.has(k)]
    if len(kinds) != 1:
        raise sec.error(key, raw, "a number, or a table with exactly one of uniform, normal, choice")
    kind = kinds[0]
    if kind == "uniform":
        low, high = table.vector("uniform", 2, lo=lo, hi=hi, unit=unit)
        if low > high:
            raise table.error("uniform", raw["uniform"], f"[low, high] with low <= high, within {allowed}")
        dist = Distribution("uniform", (low, high))
    elif kind == "normal":
        mean, std = table.vector("normal", 2)
        if std < 0.0:
            raise table.error("normal", raw["normal"], "[mean, std] with std >= 0")
        clip = None
        if table.has("clip"):
            c_lo, c_hi = table.vector("clip", 2, lo=lo, hi=hi, unit=unit)
            if c_lo > c_hi:
                raise table.error("clip", raw["clip"], f"[lo, hi] with lo <= hi, within {allowed}")
            clip = (c_lo, c_hi)
        elif math.isfinite(lo) or math.isfinite(hi):
            raise ConfigError(
                f"{sec.source}: key '{table.key_name('clip')}' is missing; a normal distribution "
                f"needs clip = [lo, hi] within {allowed} (key '{sec.key_name(key)}' is bounded)"
            )
        dist = Distribution("normal", (mean, std), clip)
    else:
        values = raw["choice"]
        table._used.add("choice")  # noqa: SLF001
        if not isinstance(values, list) or not values:
            raise table.error("choice", values, "a non-empty list of numbers")
        dist = Distribution(
            "choice",
            tuple(
                table._check_number(f"choice[{i}]", v, lo, hi, False, False, unit)  # noqa: SLF001
                for i, v in enumerate(values)
            ),
        )
    table.finish()
    return dist


def read_distributions(
    sec: Section, key: str, default: tuple[Any, ...], lo: float, hi: float, unit: str = ""
) -> tuple[Distribution, ...]:
    """A list of three distributions (``[d, d, d]``, each a number or a table)."""
    raw = sec.data.get(key) if sec.has(key) else list(default)
    sec._used.add(key)  # noqa: SLF001
    if not isinstance(raw, list) or len(raw) != 3:
        raise sec.error(key, raw, "a list of 3 numbers or distributions")
    holder = Section({f"{key}[{i}]": v for i, v in enumerate(raw)}, sec.source, sec.prefix)
    return tuple(read_distribution(holder, f"{key}[{i}]", None, lo, hi, unit) for i in range(3))


# -------------------------------------------------------------------------------------------------
# The specification
# -------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlantDistributions:
    mass_scale: Distribution
    inertia_scale: tuple[Distribution, ...]  # one (shared draw) or three (per axis)
    com_offset_m: tuple[Distribution, ...]
    products_of_inertia_kg_m2: tuple[Distribution, ...]
    thrust_coefficient_scale: Distribution
    drag_coefficient_scale: Distribution
    rotor_time_constant_scale: Distribution


@dataclass(frozen=True)
class InitialDistributions:
    position_offset_m: tuple[Distribution, ...]
    euler_offset_rad: tuple[Distribution, ...]
    velocity_m_s: tuple[Distribution, ...]


@dataclass(frozen=True)
class ElementSpec:
    """One randomised gust-profile element: its kind and keys (distributions or strings)."""

    kind: str  # "step", "ramp", "one_minus_cosine"
    values: dict[str, Any]  # key -> Distribution, str, or tuple of Distributions


@dataclass(frozen=True)
class DrydenSpec:
    values: dict[str, Any]  # key -> Distribution / tuple / bool; "seed" None = drawn per run


# [sensor_parameters]: key -> (lower bound, upper bound, unit) of a draw.
SENSOR_PARAMETERS = {
    "accel_noise_density": (0.0, 1.0, "m/s^2/sqrt(Hz)"),
    "gyro_noise_density": (0.0, 0.1, "rad/s/sqrt(Hz)"),
    "accel_turn_on_bias_std": (0.0, 1.0, "m/s^2"),
    "gyro_turn_on_bias_std": (0.0, 0.2, "rad/s"),
    "mag_noise_std_gauss": (0.0, 0.1, "gauss"),
    "baro_noise_std_hpa": (0.0, 1.0, "hPa"),
    "gps_horizontal_noise_std_m": (0.0, 20.0, "m"),
    "gps_vertical_noise_std_m": (0.0, 20.0, "m"),
    "gps_velocity_noise_std_m_s": (0.0, 5.0, "m/s"),
    "vision_position_noise_std_m": (0.0, 1.0, "m"),
}
FAULT_VALUE_LIMIT = 1e4  # |value| per axis (m, gauss, m/s^2, rad/s or hPa), as a sensor profile's


@dataclass(frozen=True)
class FaultSpec:
    """One randomised sensor fault of ``[[sensor_faults]]``: its kind, or several to draw one of."""

    kinds: tuple[str, ...]
    start_s: Distribution
    duration_s: Distribution | None  # None: to the end of the run
    value: tuple[Distribution, ...] | None  # None: the drawn kind's figure

    @property
    def kind(self) -> str:
        """The kind when there is one (a drawn kind: its streams are named after the entry alone)."""
        return self.kinds[0] if len(self.kinds) == 1 else ""


@dataclass(frozen=True)
class ActuatorFaultSpec:
    """One randomised motor failure of ``[[actuator_faults]]``."""

    motor: Distribution  # PX4's motor number (0: all), drawn
    types: tuple[str, ...]  # one, or several to draw one of
    effectiveness: Distribution  # what a "wrong" motor keeps
    start_s: Distribution


@dataclass(frozen=True)
class EstimationSpec:
    """The sensors and the filter the controllers fly on (``estimator = "ekf"``)."""

    sensors_name: str
    sensors: SensorConfig  # the profile as shipped (a run's: drawn figures, its own seed)
    params: EstimatorParams
    parameters: dict[str, Distribution]  # [sensor_parameters]: key -> distribution
    faults: tuple[FaultSpec, ...]


@dataclass(frozen=True)
class CampaignSpec:
    path: str
    name: str
    description: str
    scenario: ScenarioConfig
    vehicle: VehicleConfig  # nominal (what the controllers know) with the vehicle's true structure
    controllers: tuple[ControllerConfig, ...]
    runs: int
    seed: int
    duration_s: float
    wire_float32: bool
    chunk_runs: int
    rates: Rates
    failure: FailureLimits
    plant: PlantDistributions
    initial: InitialDistributions
    base_profile: GustProfile
    base_profile_name: str
    elements: tuple[ElementSpec, ...]
    dryden: DrydenSpec | None
    text: str = field(repr=False, default="")  # the file as read (for the results' manifest)
    warnings: tuple[str, ...] = ()
    estimation: EstimationSpec | None = None  # None: the controllers fly on the truth
    actuator_faults: tuple[ActuatorFaultSpec, ...] = ()
    survival: SurvivalLimits = SurvivalLimits()

    @property
    def draws_faults(self) -> bool:
        """True when runs draw faults (of the actuators, or the sensors'): a fault study."""
        return bool(self.actuator_faults) or (self.estimation is not None and bool(self.estimation.faults))

    @property
    def estimator(self) -> str:
        """``truth`` when the runs fly on the true state, ``ekf`` when they fly on the estimator."""
        return "truth" if self.estimation is None else "ekf"

    @property
    def controller_names(self) -> tuple[str, ...]:
        """The names of the controllers compared, in the spec's order."""
        return tuple(c.name for c in self.controllers)

    def fingerprint(self) -> str:
        """Hash of everything that decides a run's rows; ``runs`` is left out (a campaign may grow).

        Taken over the resolved configuration (scenario, vehicle, cascades, distributions,
        profiles, rates, limits), so editing a referenced config file also changes it.
        """
        decisive = (
            ENGINE_VERSION, self.scenario, self.vehicle, self.controllers, self.seed, self.duration_s,
            self.wire_float32, self.rates, self.failure, self.plant, self.initial, self.base_profile,
            self.elements, self.dryden, self.estimation, self.actuator_faults, self.survival,
        )  # fmt: skip
        return hashlib.sha256(repr(decisive).encode()).hexdigest()[:16]


def flown_by(spec: CampaignSpec, controller: str) -> CampaignSpec:
    """``spec`` flown by the controller ``controller`` alone: the spec's own entry when it lists
    it, else the controller of that name from the configuration directories (a researcher's own
    included). The runs are the spec's: a run's plant and disturbances do not depend on the
    controllers (:mod:`.sampling`). A name found nowhere is a ConfigError listing the places
    looked in and the names there."""
    listed = [c for c in spec.controllers if c.name == controller]
    return replace(spec, controllers=(listed[0] if listed else load_controller(controller),))


def campaign_path(name_or_path: str | Path) -> Path:
    """A path, or ``campaigns/NAME.toml`` in the configuration directories."""
    return config_path("campaigns", name_or_path)


def load_campaign(name_or_path: str | Path, runs: int | None = None) -> CampaignSpec:
    """Read and validate a campaign spec; ``runs`` overrides the file's (``--runs N``)."""
    path = campaign_path(name_or_path)
    root = load_toml(path)
    text = path.read_text()
    name = root.string("name", path.stem)
    description = root.string("description", "")
    scenario_name = root.string("scenario")
    try:
        scenario = load_scenario(scenario_name)
    except ConfigError as exc:
        raise ConfigError(f"{path}: key 'scenario' = {scenario_name!r}: {exc}") from None
    vehicle_name = root.string("vehicle", scenario.vehicle)
    try:
        vehicle = load_vehicle(vehicle_name)
    except ConfigError as exc:
        raise ConfigError(f"{path}: key 'vehicle' = {vehicle_name!r}: {exc}") from None
    names = root.data.get("controllers")
    root._used.add("controllers")  # noqa: SLF001
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise root.error("controllers", names, "a non-empty list of cascade names (config/controllers)")
    if len(set(names)) != len(names):
        raise root.error("controllers", names, "each cascade at most once")
    controllers = []
    for i, cname in enumerate(names):
        try:
            controllers.append(load_controller(cname))
        except ConfigError as exc:
            raise ConfigError(f"{path}: key 'controllers[{i}]' = {cname!r}: {exc}") from None
    file_runs = root.integer("runs", lo=1, hi=MAX_RUNS)
    if runs is not None and not 1 <= runs <= MAX_RUNS:
        raise ConfigError(f"--runs {runs} is invalid; allowed: [1, {MAX_RUNS}] (file {path})")
    seed = root.integer("seed", lo=0, hi=2**63 - 1)
    duration = root.number("duration_s", scenario.duration_s, lo=0.0, lo_open=True, hi=3600.0, unit="s")
    wire = root.boolean("wire_float32", True)
    chunk = root.integer("chunk_runs", 20, lo=1, hi=10_000)

    sec = root.section("rates", optional=True)
    rates = load_rates(sec) if sec.data else load_sitl().rates
    sec.finish()

    sec = root.section("failure", optional=True)
    failure = FailureLimits(
        max_position_error_m=sec.number("max_position_error_m", 5.0, lo=0.01, hi=1e4, unit="m"),
        max_tilt_rad=sec.number("max_tilt_rad", 1.3, lo=0.05, hi=math.pi, unit="rad"),
        airborne_height_m=sec.number("airborne_height_m", 0.05, lo=0.0, hi=100.0, unit="m"),
    )
    sec.finish()

    plant = _read_plant(root.section("plant", optional=True), vehicle)
    initial = _read_initial(root.section("initial_state", optional=True), scenario, vehicle)
    estimation = _read_estimation(root, path, duration)
    actuator_faults = _read_actuator_faults(root, duration)
    sec = root.section("survival", optional=True)
    survival = SurvivalLimits(
        envelope_m=sec.number("envelope_m", SurvivalLimits.envelope_m, lo=0.001, hi=1e4, unit="m"),
        recovery_bound_m=sec.number("recovery_bound_m", SurvivalLimits.recovery_bound_m, lo=0.0, lo_open=True,
                                    hi=1e4, unit="m"),
    )  # fmt: skip
    sec.finish()
    draws = bool(actuator_faults) or (estimation is not None and bool(estimation.faults))
    if root.has("survival") and not draws:
        raise root.error("survival", root.data["survival"], "only in a spec that draws faults "
                         "([[actuator_faults]] or [[sensor_faults]])")  # fmt: skip
    warnings: list[str] = []
    if root.has("disturbances"):
        base_name, base, elements, dryden = _read_disturbances(root.section("disturbances"), scenario)
    else:
        base_name, elements, dryden = scenario.gusts or "none", (), None
        base = load_gust_profile(scenario.gusts)
    root.finish()
    has_wind = bool(base.one_minus_cosine or base.dryden or dryden) or any(
        e.kind == "one_minus_cosine" for e in elements
    )
    if has_wind and vehicle.plant.drag_coefficient_n_s_m == (0.0, 0.0, 0.0):
        warnings.append(
            f"{path}: wind (1-cos gusts, Dryden) acts through drag, and vehicle '{vehicle.name}' has none; "
            'use vehicle = "paper_quad_drag" for wind studies'
        )
    return CampaignSpec(
        path=str(path),
        name=name,
        description=description,
        scenario=scenario,
        vehicle=vehicle,
        controllers=tuple(controllers),
        runs=runs if runs is not None else file_runs,
        seed=seed,
        duration_s=duration,
        wire_float32=wire,
        chunk_runs=chunk,
        rates=rates,
        failure=failure,
        plant=plant,
        initial=initial,
        base_profile=base,
        base_profile_name=base_name,
        elements=elements,
        dryden=dryden,
        text=text,
        warnings=tuple(warnings),
        estimation=estimation,
        actuator_faults=actuator_faults,
        survival=survival,
    )


def _read_labels(sec: Section, key: str, options: tuple[str, ...]) -> tuple[str, ...]:
    """A string among ``options``, or ``{ choice = [...] }`` of them (drawn per run)."""
    raw = sec.data.get(key)
    if isinstance(raw, dict):
        sec._used.add(key)  # noqa: SLF001
        values = raw.get("choice")
        if set(raw) != {"choice"} or not isinstance(values, list) or not values:
            raise sec.error(key, raw, f"one of {', '.join(options)}, or {{ choice = [...] }} of them")
        for i, value in enumerate(values):
            if value not in options:
                raise sec.error(f"{key}.choice[{i}]", value, f"one of {', '.join(options)}")
        if len(set(values)) != len(values):
            raise sec.error(f"{key}.choice", values, "each at most once")
        return tuple(values)
    return (sec.choice(key, options),)


def _read_actuator_faults(root: Section, duration_s: float) -> tuple[ActuatorFaultSpec, ...]:
    """``[[actuator_faults]]``: a motor's failure drawn per run."""
    raw = root.data.get("actuator_faults", [])
    root._used.add("actuator_faults")  # noqa: SLF001
    if not isinstance(raw, list) or not all(isinstance(item, dict) for item in raw):
        raise root.error("actuator_faults", raw, "a list of tables ([[actuator_faults]])")
    motors = FAILURES[Unit.motor].instances
    out = []
    for i, item in enumerate(raw):
        sec = Section(item, root.source, f"actuator_faults[{i}].")
        motor = read_distribution(sec, "motor", None, 0.0, float(motors))
        if motor.kind not in ("fixed", "choice") or any(v != int(v) for v in motor.params):
            raise sec.error("motor", motor.describe(), f"a motor number 1-{motors} (0: all), or "
                            "{ choice = [...] } of them")  # fmt: skip
        types = _read_labels(sec, "type", ACTUATOR_FAULT_TYPES[:3])
        if sec.has("effectiveness") and "wrong" not in types:
            raise sec.error("effectiveness", sec.data["effectiveness"], 'only with type "wrong"')
        effectiveness = read_distribution(sec, "effectiveness", MOTOR_EFFECTIVENESS_DEFAULT, 0.0, 1.0)
        start = read_distribution(sec, "start_s", None, 0.0, duration_s, "s")
        sec.finish()
        out.append(ActuatorFaultSpec(motor, types, effectiveness, start))
    return tuple(out)


def _read_estimation(root: Section, path: Path, duration_s: float) -> EstimationSpec | None:
    """``estimator``, ``sensors``, ``[sensor_parameters]`` and ``[[sensor_faults]]``."""
    estimator = root.choice("estimator", ("truth", "ekf"), "truth")
    if estimator == "truth":
        for key in ("sensors", "sensor_parameters", "sensor_faults"):
            if root.has(key):
                allowed = 'nothing on the truth: set estimator = "ekf" to fly on sensors'
                raise root.error(key, root.data[key], allowed)
        return None
    if not root.has("sensors"):
        raise ConfigError(f'{path}: key \'sensors\' is missing; estimator = "ekf" needs a sensor profile '
                          "(config/sensors NAME, e.g. \"gps\")")  # fmt: skip
    name = root.string("sensors")
    try:
        base = estimation_spec(name)
    except ConfigError as exc:
        raise ConfigError(f"{path}: key 'sensors' = {name!r}: {exc}") from None
    sec = root.section("sensor_parameters", optional=True)
    parameters = {}
    for key, (lo, hi, unit) in SENSOR_PARAMETERS.items():
        if sec.has(key):
            parameters[key] = read_distribution(sec, key, None, lo, hi, unit)
    sec.finish()
    raw = root.data.get("sensor_faults", [])
    root._used.add("sensor_faults")  # noqa: SLF001
    if not isinstance(raw, list) or not all(isinstance(item, dict) for item in raw):
        raise root.error("sensor_faults", raw, "a list of tables ([[sensor_faults]])")
    faults = []
    for i, item in enumerate(raw):
        fs = Section(item, root.source, f"sensor_faults[{i}].")
        kinds = _read_labels(fs, "kind", FAULT_KINDS)
        start = read_distribution(fs, "start_s", None, 0.0, duration_s, "s")
        length = None
        if fs.has("duration_s"):
            length = read_distribution(fs, "duration_s", None, 0.0, MAX_TIME_S, "s")
        limit = FAULT_VALUE_LIMIT
        value = None
        if fs.has("value") or len(kinds) == 1:
            value = read_distributions(fs, "value", default_fault_value(kinds[0]), -limit, limit)
        fs.finish()
        faults.append(FaultSpec(kinds, start, length, value))
    return replace(base, parameters=parameters, faults=tuple(faults))


def estimation_spec(sensors: str) -> EstimationSpec:
    """Flying on the filter with the sensor profile ``sensors`` as shipped (nothing drawn but
    the noise), with the filter's parameters ``quadsitl up --sensors NAME`` gives the autopilot."""
    params = load_estimator_params(estimator_profile_for(sensors))
    return EstimationSpec(sensors, load_sensors(sensors), params, {}, ())


def _read_plant(sec: Section, vehicle: VehicleConfig) -> PlantDistributions:
    mass = read_distribution(sec, "mass_scale", 1.0, 0.5, 2.0)
    raw = sec.data.get("inertia_scale", 1.0)
    if isinstance(raw, list):
        inertia = read_distributions(sec, "inertia_scale", (1.0, 1.0, 1.0), 0.5, 2.0)
    else:
        inertia = (read_distribution(sec, "inertia_scale", 1.0, 0.5, 2.0),)
    com = read_distributions(sec, "com_offset_m", vehicle.plant.com_offset_m, -0.5, 0.5, "m")
    products = read_distributions(
        sec, "products_of_inertia_kg_m2", vehicle.plant.products_of_inertia_kg_m2, -1.0, 1.0, "kg m^2"
    )
    rotor_keys = ("thrust_coefficient_scale", "drag_coefficient_scale", "rotor_time_constant_scale")
    if vehicle.actuation.mode != "rotors":
        for key in rotor_keys:
            if sec.has(key):
                raise sec.error(
                    key,
                    sec.data[key],
                    f"only with actuation = 'rotors' (vehicle '{vehicle.name}' has 'wrench')",
                )
    rotors = [read_distribution(sec, key, 1.0, 0.5, 2.0) for key in rotor_keys]
    sec.finish()
    _check_inertia_box(sec, vehicle, inertia, products)
    return PlantDistributions(mass, inertia, com, products, *rotors)


def _check_inertia_box(sec: Section, vehicle: VehicleConfig, inertia, products) -> None:
    """Every sampled tensor must be positive definite: Gershgorin over the box is sufficient."""
    scales = inertia * 3 if len(inertia) == 1 else inertia
    shared = len(inertia) == 1
    lows = [vehicle.plant.inertia_kg_m2[i] * scales[i].support()[0] for i in range(3)]
    s_hi = scales[0].support()[1] if shared else 1.0
    mags = [max(abs(v) for v in d.support()) * s_hi for d in products]  # Ixy, Ixz, Iyz
    rows = (mags[0] + mags[1], mags[0] + mags[2], mags[1] + mags[2])
    for i, axis in enumerate("xyz"):
        if not lows[i] > rows[i]:
            raise ConfigError(
                f"{sec.source}: keys '{sec.prefix}inertia_scale' and '{sec.prefix}products_of_inertia_kg_m2' "
                f"allow an inertia tensor that may not be positive definite (axis {axis}: smallest "
                f"I{axis}{axis} {lows[i]:.3g} <= sum of |products| {rows[i]:.3g} kg m^2); allowed: ranges "
                "where every diagonal term exceeds the sum of the products in its row"
            )


def _read_initial(sec: Section, scenario: ScenarioConfig, vehicle: VehicleConfig) -> InitialDistributions:
    zero = (0.0, 0.0, 0.0)
    position = read_distributions(sec, "position_offset_m", zero, -100.0, 100.0, "m")
    margin = 0.5 * math.pi - 0.05 - abs(scenario.initial_euler_rad[1])
    euler = read_distributions(sec, "euler_offset_rad", zero, -math.pi, math.pi, "rad")
    lo, hi = euler[1].support()
    if max(abs(lo), abs(hi)) >= margin:
        raise sec.error(
            "euler_offset_rad[1]",
            euler[1].describe(),
            f"|theta offset| < {margin:.3f} rad (away from gimbal lock)",
        )
    velocity = read_distributions(sec, "velocity_m_s", zero, -20.0, 20.0, "m/s")
    sec.finish()
    if vehicle.plant.ground_contact and scenario.initial_position_m[2] + position[2].support()[0] < 0.0:
        raise sec.error(
            "position_offset_m[2]",
            position[2].describe(),
            f">= {-scenario.initial_position_m[2]:g} m: the scenario starts at z = "
            f"{scenario.initial_position_m[2]:g} m and the ground is at z = 0",
        )
    return InitialDistributions(position, euler, velocity)


_ELEMENT_KEYS = {
    "step": {"start_s": (0.0, MAX_TIME_S, "s"), "end_s": (0.0, MAX_TIME_S, "s")},
    "ramp": {
        "start_s": (0.0, MAX_TIME_S, "s"),
        "end_s": (0.0, MAX_TIME_S, "s"),
        "hold_until_s": (0.0, MAX_TIME_S, "s"),
    },
    "one_minus_cosine": {
        "start_s": (0.0, MAX_TIME_S, "s"),
        "duration_s": (MIN_DURATION_S, MAX_DURATION_S, "s"),
        "amplitude_m_s": (0.0, MAX_AMPLITUDE_M_S, "m/s"),
    },
}


def _read_disturbances(sec: Section, scenario: ScenarioConfig):
    base_name = sec.string("base", "none")
    if base_name == "scenario":
        base_name = scenario.gusts or "none"
    try:
        base = load_gust_profile(base_name)
    except ConfigError as exc:
        raise ConfigError(f"{sec.source}: key '{sec.key_name('base')}' = {base_name!r}: {exc}") from None
    elements: list[ElementSpec] = []
    for kind in ("step", "ramp", "one_minus_cosine"):
        for table in sec.sections(kind):
            elements.append(_read_element(table, kind))
    dryden = _read_dryden(sec.section("dryden")) if sec.has("dryden") else None
    sec.finish()
    return base_name, base, tuple(elements), dryden


def _read_element(sec: Section, kind: str) -> ElementSpec:
    values: dict[str, Any] = {}
    if kind in ("step", "ramp"):
        channel = sec.choice("channel", CHANNELS)
        values["channel"] = channel
        bound, unit = (MAX_FORCE_N, "N") if channel.startswith("force") else (MAX_TORQUE_N_M, "N m")
        values["value"] = read_distribution(sec, "value", None, -bound, bound, unit)
    for key, (lo, hi, unit) in _ELEMENT_KEYS[kind].items():
        optional = (kind == "step" and key == "end_s") or (kind == "ramp" and key == "hold_until_s")
        if optional and not sec.has(key):
            continue
        values[key] = read_distribution(sec, key, None, lo, hi, unit)
    if (
        kind in ("step", "ramp")
        and "end_s" in values
        and values["end_s"].support()[0] <= values["start_s"].support()[1]
    ):
        raise sec.error(
            "end_s", values["end_s"].describe(), f"always after start_s ({values['start_s'].describe()})"
        )
    if kind == "one_minus_cosine":
        if sec.has("axis") and sec.has("direction"):
            raise sec.error("axis", sec.data["axis"], "either 'direction' or 'axis', not both")
        if sec.has("direction"):
            values["direction"] = read_distributions(sec, "direction", (0.0, 0.0, 0.0), -1e3, 1e3)
        else:
            values["axis"] = sec.choice("axis", tuple(AXES))
    sec.finish()
    return ElementSpec(kind, values)


def _read_dryden(sec: Section) -> DrydenSpec:
    values: dict[str, Any] = {
        "w20_m_s": read_distribution(sec, "w20_m_s", None, 0.0, MAX_W20_M_S, "m/s"),
        "altitude_m": read_distribution(
            sec, "altitude_m", None, MIN_ALTITUDE_M, round(LOW_ALTITUDE_LIMIT_M, 1), "m"
        ),
        "airspeed_m_s": read_distribution(
            sec, "airspeed_m_s", 5.0, MIN_AIRSPEED_M_S, MAX_AIRSPEED_M_S, "m/s"
        ),
        "start_s": read_distribution(sec, "start_s", 0.0, 0.0, MAX_TIME_S, "s"),
        "mean_wind_m_s": read_distributions(
            sec, "mean_wind_m_s", (0.0, 0.0, 0.0), -MAX_MEAN_WIND_M_S, MAX_MEAN_WIND_M_S, "m/s"
        ),
        "warm_start": sec.boolean("warm_start", True),
        "seed": sec.integer("seed", lo=0) if sec.has("seed") else None,
    }
    if sec.has("end_s"):
        values["end_s"] = read_distribution(sec, "end_s", None, 0.0, MAX_TIME_S, "s")
    sec.finish()
    return DrydenSpec(values)
