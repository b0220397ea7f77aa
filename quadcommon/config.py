"""Configuration records (frozen) and their loaders from ``config/``.

Files and what they hold:

* ``config/vehicle/NAME.toml``: the nominal model the controllers know (Section IV), the "true"
  plant the simulator flies (CoM offset, products of inertia, drag), actuation, rotors and the
  battery.
* ``config/controllers/NAME.toml``: read by :mod:`autopilot.control.config` (the laws' own schemas).
* ``config/scenarios/NAME.toml``: trajectory, initial state, parametric uncertainty, gust profile,
  duration, motor failures at a time (``[[actuator_faults]]``, :mod:`.failures`).
* ``config/sitl.toml``: rates, ports, home position, zenoh endpoints, lockstep timeouts.

Gust profiles (``config/gusts/``) are read by :mod:`simulator.environment.gust_profile`.

Every loader accepts a bare name or a path. A name is looked up in the configuration
directories, first match wins (:func:`config_dirs`): the user's own, from ``--config-dir`` on the
command line and ``QUADSITL_CONFIG_DIR`` (several joined by ``:``), then the shipped defaults
(:data:`SHIPPED_CONFIG_DIR`: ``config/`` of the checkout, or the installed package
``quadsitl_config``, which is that same directory mapped into the wheel). A user's directory holds
only what it changes (``scenarios/mine.toml``); ``quadsitl config copy DIR`` writes the defaults out
for editing. Values are validated at load; errors name file, key, value and the allowed range (see
:mod:`.schema`).

(One module: one schema for the files a user edits, validated in one place with the messages
naming file, key, value and range; the laws' own schemas live with the laws.)
"""

from __future__ import annotations

import importlib.util
import math
import os
import shutil
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from . import environment, wire
from .failures import ActuatorFault, read_actuator_faults
from .impairment import LINKS, ImpairConfig, parse_impairment
from .schema import ConfigError, Section, load_toml

Vector3 = tuple[float, float, float]

CONFIG_ENV = environment.CONFIG_DIR  # the user's configuration directories, joined by os.pathsep
# Overrides [lockstep] spin_s of sitl.toml for every process started with it in the environment:
# on a machine with fewer free cores than lockstep processes (several vehicles, a test suite beside
# other jobs) a busy-waiting process takes the core its peer needs; 0 turns the spin off there.
SPIN_ENV = environment.LOCKSTEP_SPIN
SHIPPED_PACKAGE = "quadsitl_config"  # config/ as installed (pyproject.toml: package-dir)


def _shipped_config_dir() -> Path:
    """``config/`` beside the packages in a checkout, else the installed ``quadsitl_config``."""
    checkout = Path(__file__).resolve().parents[1] / "config"
    if (checkout / "sitl.toml").is_file():
        return checkout
    spec = importlib.util.find_spec(SHIPPED_PACKAGE)
    if spec is not None and spec.submodule_search_locations:
        for location in spec.submodule_search_locations:
            if (Path(location) / "sitl.toml").is_file():
                return Path(location)
    return checkout  # neither: every lookup fails and its error says where it looked


SHIPPED_CONFIG_DIR = _shipped_config_dir()
CONFIG_DIR = SHIPPED_CONFIG_DIR  # the shipped defaults (kept under this name for existing callers)


def config_dirs(environ: Mapping[str, str] | None = None) -> tuple[Path, ...]:
    """The directories a name is looked up in, first match wins: those in ``QUADSITL_CONFIG_DIR``
    (``--config-dir`` puts its directory first there), then the shipped defaults. A directory
    in the variable that does not exist is a :class:`ConfigError` naming it."""
    dirs: list[Path] = []
    for text in environment.config_dir_list(environ):
        path = Path(text).expanduser()
        if not path.is_dir():
            raise ConfigError(f"{CONFIG_ENV}: {text} is not a directory")
        dirs.append(path)
    dirs.append(SHIPPED_CONFIG_DIR)
    unique: list[Path] = []
    for d in dirs:
        if d.resolve() not in {u.resolve() for u in unique}:
            unique.append(d)
    return tuple(unique)


def with_config_dir(directory: str | Path, environ: Mapping[str, str]) -> dict[str, str]:
    """``environ`` with ``directory`` first in ``QUADSITL_CONFIG_DIR`` (child processes inherit
    it); a directory that does not exist is a :class:`ConfigError`."""
    path = Path(directory).expanduser()
    if not path.is_dir():
        raise ConfigError(f"--config-dir {directory} is not a directory")
    rest = environ.get(CONFIG_ENV, "")
    return {**environ, CONFIG_ENV: os.pathsep.join([str(path.resolve()), *([rest] if rest else [])])}


def available_names(kind: str, dirs: tuple[Path, ...] | None = None) -> list[str]:
    """The names of ``kind`` (``scenarios``, ``gusts``, ...) found in any configuration directory."""
    dirs = config_dirs() if dirs is None else dirs
    return sorted({p.stem for d in dirs for p in (d / kind).glob("*.toml")})


def config_path(kind: str, name_or_path: str | Path) -> Path:
    """Resolve ``name_or_path``: an existing path, or ``DIR/kind/NAME.toml`` in the first of
    :func:`config_dirs` that has it. A name found nowhere is a :class:`ConfigError` listing every
    place looked in and the names there are."""
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or candidate.exists():
        if not candidate.exists():
            raise ConfigError(f"{candidate}: file not found")
        return candidate
    return find_config(kind, str(name_or_path))


def find_config(kind: str, name: str) -> Path:
    """``DIR/kind/NAME.toml`` in the first of :func:`config_dirs` that has it (a name only)."""
    dirs = config_dirs()
    looked = [d / kind / f"{name}.toml" for d in dirs]
    for path in looked:
        if path.is_file():
            return path
    available = available_names(kind, dirs)
    what = kind or "file"
    raise ConfigError(
        f"no {what} named '{name}' (looked for {', '.join(map(str, looked))}); "
        f"available: {', '.join(available) or 'none'}"
    )


def shipped_files() -> list[Path]:
    """The shipped configuration files, relative to :data:`SHIPPED_CONFIG_DIR` (TOML only)."""
    return sorted(p.relative_to(SHIPPED_CONFIG_DIR) for p in SHIPPED_CONFIG_DIR.rglob("*.toml"))


def copy_shipped_config(target: str | Path, force: bool = False) -> list[Path]:
    """Write the shipped configuration into ``target`` (created) for editing; the files written.
    Without ``force`` nothing is written when any of them exists already (a :class:`ConfigError`
    names them)."""
    target = Path(target).expanduser()
    if target.exists() and not target.is_dir():
        raise ConfigError(f"{target}: exists and is not a directory")
    files = shipped_files()
    if not files:
        raise ConfigError(f"no shipped configuration found (looked in {SHIPPED_CONFIG_DIR})")
    existing = [target / f for f in files if (target / f).exists()]
    if existing and not force:
        more = f" and {len(existing) - 5} more" if len(existing) > 5 else ""
        shown = ", ".join(map(str, existing[:5])) + more
        raise ConfigError(f"{shown}: already there; nothing written (--force overwrites)")
    written = []
    for f in files:
        (target / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(SHIPPED_CONFIG_DIR / f, target / f)
        written.append(target / f)
    return written


# --------------------------------------------------------------------------------------------
# Vehicle
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NominalModel:
    """What the controllers believe (Section IV): the decoupled model of Section II."""

    mass_kg: float
    gravity_m_s2: float
    arm_length_m: float
    inertia_kg_m2: Vector3  # Ixx, Iyy, Izz

    @property
    def hover_thrust_n(self) -> float:
        """The thrust that holds the nominal vehicle in hover, ``m g`` (N)."""
        return self.mass_kg * self.gravity_m_s2


@dataclass(frozen=True)
class PlantStructure:
    """The "more accurate" plant of Section IV (simulator only). See CONTROL.md."""

    model: str  # "coupled" or "nominal" (the Section II equations, integrated in eta)
    mass_kg: float
    inertia_kg_m2: Vector3  # principal-axis terms about the CoM, before uncertainty scaling
    products_of_inertia_kg_m2: Vector3  # Ixy, Ixz, Iyz about the CoM
    com_offset_m: Vector3  # r_G: CoM position in the body frame, from the geometric centre O
    drag_coefficient_n_s_m: Vector3  # linear aerodynamic drag per world axis, F = -k (v - wind)
    ground_contact: bool


@dataclass(frozen=True)
class Actuation:
    mode: str  # "wrench" (saturated U1 and tau) or "rotors" (allocation + rotor dynamics)
    thrust_max_n: float
    torque_max_n_m: Vector3


@dataclass(frozen=True)
class Rotors:
    thrust_coefficient_n_s2: float  # b: thrust = b Omega^2
    drag_coefficient_n_m_s2: float  # d: reaction torque = d Omega^2
    inertia_kg_m2: float  # J_r, gyroscopic moment
    time_constant_s: float  # first-order speed dynamics
    speed_min_rad_s: float
    speed_max_rad_s: float


# PX4's battery-simulator parameters, their ranges (PX4's) and what they set in ``[battery]``: the
# vehicle file gives their values at start; the autopilot declares them (autopilot.params) and the
# simulator's model takes them (simulator.battery.BatteryModel.set_parameter).
SIM_BATTERY_PARAMETERS = {  # name: (lo, hi, unit, [battery] key)
    "SIM_BAT_ENABLE": (0.0, 1.0, "", "enabled"),
    "SIM_BAT_DRAIN": (0.0, 86400.0, "s", "drain_s"),
    "SIM_BAT_MIN_PCT": (0.0, 100.0, "%", "drain_min_pct"),
}


@dataclass(frozen=True)
class BatteryConfig:
    """The flight battery (``[battery]``): the pack the simulator flies (:mod:`simulator.battery`),
    and the defaults of the autopilot's battery parameters (``BAT1_*``, ``BAT_AVRG_CURRENT``,
    ``SIM_BAT_*``) for this vehicle. Every key has a default: a 3S 2200 mAh LiPo."""

    cells: int = 3  # in series (BAT1_N_CELLS)
    capacity_mah: float = 2200.0  # BAT1_CAPACITY
    initial_charge: float = 1.0  # state of charge at the start, 0-1
    internal_resistance_ohm: float = 0.045  # the whole pack's: the terminal voltage sags I R
    empty_cell_v: float = 3.6  # BAT1_V_EMPTY; SIM_BAT_DRAIN's voltage at 0 %
    charged_cell_v: float = 4.05  # BAT1_V_CHARGED; SIM_BAT_DRAIN's voltage at 100 %
    avionics_power_w: float = 3.0  # flight controller, receiver, GPS: drawn whenever powered
    motor_efficiency: float = 0.75  # electrical to shaft power, motors and speed controllers
    rotor_radius_m: float = 0.127  # actuation "wrench": the rotor disc of momentum theory
    figure_of_merit: float = 0.4  # actuation "wrench": ideal over actual rotor power
    average_current_a: float = 15.0  # BAT_AVRG_CURRENT: the expected current in flight
    enabled: bool = True  # SIM_BAT_ENABLE: the monitor reports the pack
    drain_s: float = 0.0  # SIM_BAT_DRAIN: 0 the pack model; > 0 PX4's linear drain, full to empty (s)
    drain_min_pct: float = 50.0  # SIM_BAT_MIN_PCT: where PX4's linear drain stops (%)


@dataclass(frozen=True)
class VehicleConfig:
    name: str
    nominal: NominalModel
    plant: PlantStructure
    actuation: Actuation
    rotors: Rotors
    battery: BatteryConfig = BatteryConfig()


def load_vehicle(name_or_path: str | Path = "paper_quad") -> VehicleConfig:
    """The vehicle file ``config/vehicle/<name>.toml`` (or a path), validated: a ConfigError names
    the file, key, value and range."""
    path = config_path("vehicle", name_or_path)
    root = load_toml(path)
    name = root.string("name", Path(path).stem)

    sec = root.section("nominal")
    nominal = NominalModel(
        mass_kg=sec.number("mass_kg", lo=0.0, lo_open=True, hi=100.0, unit="kg"),
        gravity_m_s2=sec.number("gravity_m_s2", 9.81, lo=0.0, lo_open=True, hi=30.0, unit="m/s^2"),
        arm_length_m=sec.number("arm_length_m", lo=0.0, lo_open=True, hi=5.0, unit="m"),
        inertia_kg_m2=sec.vector("inertia_kg_m2", lo=0.0, lo_open=True, hi=10.0, unit="kg m^2"),
    )
    sec.finish()

    sec = root.section("plant")
    plant = PlantStructure(
        model=sec.choice("model", ("coupled", "nominal"), "coupled"),
        mass_kg=sec.number("mass_kg", nominal.mass_kg, lo=0.0, lo_open=True, hi=100.0, unit="kg"),
        inertia_kg_m2=sec.vector(
            "inertia_kg_m2", 3, nominal.inertia_kg_m2, lo=0.0, lo_open=True, hi=10.0, unit="kg m^2"
        ),
        products_of_inertia_kg_m2=sec.vector(
            "products_of_inertia_kg_m2", 3, (0.0, 0.0, 0.0), lo=-1.0, hi=1.0, unit="kg m^2"
        ),
        com_offset_m=sec.vector("com_offset_m", 3, (0.0, 0.0, 0.0), lo=-0.5, hi=0.5, unit="m"),
        drag_coefficient_n_s_m=sec.vector(
            "drag_coefficient_n_s_m", 3, (0.0, 0.0, 0.0), lo=0.0, hi=50.0, unit="N s/m"
        ),
        ground_contact=sec.boolean("ground_contact", True),
    )
    sec.finish()

    sec = root.section("actuation")
    actuation = Actuation(
        mode=sec.choice("mode", ("wrench", "rotors"), "wrench"),
        thrust_max_n=sec.number("thrust_max_n", lo=0.0, lo_open=True, hi=1000.0, unit="N"),
        torque_max_n_m=sec.vector("torque_max_n_m", lo=0.0, lo_open=True, hi=100.0, unit="N m"),
    )
    sec.finish()

    sec = root.section("rotors")
    rotors = Rotors(
        thrust_coefficient_n_s2=sec.number(
            "thrust_coefficient_n_s2", lo=0.0, lo_open=True, hi=1.0, unit="N s^2"
        ),
        drag_coefficient_n_m_s2=sec.number(
            "drag_coefficient_n_m_s2", lo=0.0, lo_open=True, hi=1.0, unit="N m s^2"
        ),
        inertia_kg_m2=sec.number("inertia_kg_m2", lo=0.0, hi=1.0, unit="kg m^2"),
        time_constant_s=sec.number("time_constant_s", lo=0.0, lo_open=True, hi=1.0, unit="s"),
        speed_min_rad_s=sec.number("speed_min_rad_s", 0.0, lo=0.0, hi=1e4, unit="rad/s"),
        speed_max_rad_s=sec.number("speed_max_rad_s", lo=0.0, lo_open=True, hi=1e4, unit="rad/s"),
    )
    if rotors.speed_min_rad_s >= rotors.speed_max_rad_s:
        raise sec.error("speed_min_rad_s", rotors.speed_min_rad_s, "< rotors.speed_max_rad_s")
    sec.finish()
    battery = load_battery(root.section("battery", optional=True))
    root.finish()

    _check_inertia_tensor(path, plant)
    return VehicleConfig(name, nominal, plant, actuation, rotors, battery)


def load_battery(sec: Section) -> BatteryConfig:
    """``[battery]`` of a vehicle file (every key optional: :class:`BatteryConfig`'s defaults)."""
    d = BatteryConfig()
    empty = sec.number("empty_cell_v", d.empty_cell_v, lo=2.5, hi=4.2, unit="V")
    battery = BatteryConfig(
        cells=sec.integer("cells", d.cells, lo=1, hi=16),
        capacity_mah=sec.number("capacity_mah", d.capacity_mah, lo=0.0, lo_open=True, hi=100000.0,
                                unit="mAh"),
        initial_charge=sec.number("initial_charge", d.initial_charge, lo=0.0, hi=1.0),
        internal_resistance_ohm=sec.number("internal_resistance_ohm", d.internal_resistance_ohm, lo=0.0,
                                           hi=2.0, unit="ohm"),
        empty_cell_v=empty,
        charged_cell_v=sec.number("charged_cell_v", d.charged_cell_v, lo=empty, lo_open=True, hi=4.5,
                                  unit="V"),
        avionics_power_w=sec.number("avionics_power_w", d.avionics_power_w, lo=0.0, hi=1000.0, unit="W"),
        motor_efficiency=sec.number("motor_efficiency", d.motor_efficiency, lo=0.0, lo_open=True, hi=1.0),
        rotor_radius_m=sec.number("rotor_radius_m", d.rotor_radius_m, lo=0.0, lo_open=True, hi=2.0, unit="m"),
        figure_of_merit=sec.number("figure_of_merit", d.figure_of_merit, lo=0.0, lo_open=True, hi=1.0),
        average_current_a=sec.number("average_current_a", d.average_current_a, lo=0.0, hi=500.0, unit="A"),
        enabled=sec.boolean("enabled", d.enabled),
        drain_s=_sim_battery_number(sec, "SIM_BAT_DRAIN", d.drain_s),
        drain_min_pct=_sim_battery_number(sec, "SIM_BAT_MIN_PCT", d.drain_min_pct),
    )  # fmt: skip
    sec.finish()
    return battery


def _sim_battery_number(sec: Section, parameter: str, default: float) -> float:
    lo, hi, unit, key = SIM_BATTERY_PARAMETERS[parameter]
    return sec.number(key, default, lo=lo, hi=hi, unit=unit)


def _check_inertia_tensor(path: Path, plant: PlantStructure) -> None:
    """The true inertia tensor must be positive definite (else the plant is not a rigid body)."""
    Ixx, Iyy, Izz = plant.inertia_kg_m2
    Ixy, Ixz, Iyz = plant.products_of_inertia_kg_m2
    minors = (
        Ixx,
        Ixx * Iyy - Ixy * Ixy,
        Ixx * (Iyy * Izz - Iyz * Iyz) - Ixy * (Ixy * Izz - Iyz * Ixz) + Ixz * (Ixy * Iyz - Iyy * Ixz),
    )
    if min(minors) <= 0.0:
        raise ConfigError(
            f"{path}: key 'plant.products_of_inertia_kg_m2' = {plant.products_of_inertia_kg_m2} "
            "makes the inertia tensor not positive definite; allowed: products small enough that "
            "the tensor stays positive definite"
        )


# --------------------------------------------------------------------------------------------
# Scenarios
# --------------------------------------------------------------------------------------------
TRAJECTORY_KINDS = ("circle", "helix", "hover")


@dataclass(frozen=True)
class TrajectorySpec:
    """A named analytic reference (see :mod:`quadcommon.trajectories`)."""

    kind: str
    radius_m: float = 0.0
    angular_rate_rad_s: float = 0.0
    center_m: Vector3 = (0.0, 0.0, 0.0)
    vertical_amplitude_m: float = 0.0
    climb_rate_m_s: float = 0.0
    yaw_rad: float = 0.0


@dataclass(frozen=True)
class ScenarioConfig:
    name: str
    description: str
    vehicle: str
    duration_s: float
    trajectory: TrajectorySpec
    initial_position_m: Vector3
    initial_euler_rad: Vector3
    mass_scale: float
    inertia_scale: float
    gusts: str  # name or path of a gust profile; "" for none
    takeoff_altitude_m: float = field(default=2.5)
    sensors: str = field(default="ideal")  # sensor profile (config/sensors/NAME.toml)
    estimator: str = field(default="truth")  # what the autopilot flies on: "truth" or "ekf"
    # Motor failures at a time ([[actuator_faults]]; quadcommon.failures.ActuatorFault): the
    # simulator applies each from the first frame at or after its start_s.
    actuator_faults: tuple[ActuatorFault, ...] = field(default=())


def estimator_profile_for(sensors: str) -> str:
    """The EKF profile that goes with a sensor profile (by name; an alias followed):
    ``config/estimator/<sensors>.toml`` when there is one (tuned for those sensors), else
    ``default`` (PX4's EKF2 defaults). A sensor file given by path gets ``default``."""
    if "/" in sensors or sensors.endswith(".toml"):
        return "default"
    for _ in range(4):  # follow aliases (sensors/default.toml: alias = "ideal")
        try:
            root = load_toml(config_path("sensors", sensors))
        except ConfigError:
            break
        if not root.has("alias"):
            break
        sensors = root.string("alias")
    try:
        config_path("estimator", sensors)
    except ConfigError:
        return "default"
    return sensors


def load_scenario(name_or_path: str | Path = "circle") -> ScenarioConfig:
    """The scenario file ``config/scenarios/<name>.toml`` (or a path), validated: a ConfigError names
    the file, key, value and range."""
    path = config_path("scenarios", name_or_path)
    root = load_toml(path)
    name = root.string("name", Path(path).stem)
    description = root.string("description", "")
    vehicle = root.string("vehicle", "paper_quad")
    duration = root.number("duration_s", lo=0.0, lo_open=True, hi=3600.0, unit="s")
    gusts = root.string("gusts", "")
    takeoff_alt = root.number("takeoff_altitude_m", 2.5, lo=0.1, hi=100.0, unit="m")
    sensors = root.string("sensors", "ideal")
    estimator = root.choice("estimator", ("truth", "ekf"), "truth")

    sec = root.section("trajectory")
    kind = sec.choice("kind", TRAJECTORY_KINDS)
    if kind == "hover":
        spec = TrajectorySpec(
            kind,
            center_m=sec.vector("position_m", lo=-1e4, hi=1e4, unit="m"),
            yaw_rad=sec.number("yaw_rad", 0.0, lo=-math.pi, hi=math.pi, unit="rad"),
        )
    else:
        spec = TrajectorySpec(
            kind,
            radius_m=sec.number("radius_m", lo=0.0, hi=1e3, unit="m"),
            angular_rate_rad_s=sec.number("angular_rate_rad_s", lo=-10.0, hi=10.0, unit="rad/s"),
            center_m=sec.vector("center_m", lo=-1e4, hi=1e4, unit="m"),
            vertical_amplitude_m=sec.number("vertical_amplitude_m", 0.0, lo=-1e3, hi=1e3, unit="m")
            if kind == "circle"
            else 0.0,
            climb_rate_m_s=sec.number("climb_rate_m_s", 0.0, lo=-20.0, hi=20.0, unit="m/s")
            if kind == "helix"
            else 0.0,
            yaw_rad=sec.number("yaw_rad", 0.0, lo=-math.pi, hi=math.pi, unit="rad"),
        )
    sec.finish()

    sec = root.section("initial_state")
    position = sec.vector("position_m", lo=-1e4, hi=1e4, unit="m")
    euler = sec.vector("euler_rad", lo=-math.pi, hi=math.pi, unit="rad")
    if abs(euler[1]) >= 0.5 * math.pi - 0.05:
        raise sec.error("euler_rad", euler, "|theta| < pi/2 - 0.05 (away from gimbal lock)")
    sec.finish()

    sec = root.section("uncertainty", optional=True)
    mass_scale = sec.number("mass_scale", 1.0, lo=0.5, hi=2.0)
    inertia_scale = sec.number("inertia_scale", 1.0, lo=0.5, hi=2.0)
    sec.finish()
    faults = read_actuator_faults(root.data.get("actuator_faults", []), str(path), "", duration)
    root._used.add("actuator_faults")  # noqa: SLF001  (Section's own bookkeeping of the keys read)
    root.finish()
    return ScenarioConfig(
        name,
        description,
        vehicle,
        duration,
        spec,
        position,
        euler,
        mass_scale,
        inertia_scale,
        gusts,
        takeoff_alt,
        sensors,
        estimator,
        faults,
    )


def apply_uncertainty(vehicle: VehicleConfig, scenario: ScenarioConfig) -> VehicleConfig:
    """The vehicle with the scenario's parametric uncertainty applied to the plant only."""
    plant = vehicle.plant
    s_i = scenario.inertia_scale
    plant = replace(
        plant,
        mass_kg=plant.mass_kg * scenario.mass_scale,
        inertia_kg_m2=tuple(v * s_i for v in plant.inertia_kg_m2),
        products_of_inertia_kg_m2=tuple(v * s_i for v in plant.products_of_inertia_kg_m2),
    )
    return replace(vehicle, plant=plant)


# --------------------------------------------------------------------------------------------
# SITL: rates, ports, home, zenoh
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rates:
    physics_hz: float
    control_hz: float
    gps_hz: float

    @property
    def physics_steps_per_control(self) -> int:
        """Physics steps per control step (``physics_hz / control_hz``, rounded)."""
        return round(self.physics_hz / self.control_hz)


@dataclass(frozen=True)
class SitlConfig:
    rates: Rates
    hil_port_base: int
    gcs_port_base: int
    api_port_base: int
    home: tuple[float, float, float]  # lat deg, lon deg, alt m (AMSL)
    zenoh_port_base: int
    zenoh_router: str  # "" for peer-to-peer on loopback, else an endpoint like tcp/host:7447
    lockstep_timeout_s: float
    lockstep_spin_s: float = 0.002  # busy-wait for the peer's datagram this long before blocking
    lockstep_resend_s: float = 0.01  # wall: a frame unanswered this long is sent again
    impair: ImpairConfig = ImpairConfig()  # loss, delay ... per link ([impair], --impair)

    def ports(self, instance: int) -> wire.Ports:
        """Every port of vehicle ``instance`` under this file's ``[ports]`` bases (:func:`wire.ports`)."""
        return wire.ports(instance, self.hil_port_base, self.gcs_port_base, self.api_port_base,
                          self.zenoh_port_base)  # fmt: skip

    def spaced(self, instance: int, spacing_m: float) -> SitlConfig:
        """This configuration with vehicle ``instance``'s home ``instance * spacing_m`` metres north
        of :attr:`home` (``--spacing``: PX4's multi-vehicle SITL spawns its instances 3 m apart), so
        a ground station's map shows several vehicles apart; each flies its own local frame about
        its own home. ValueError outside [0, :data:`MAX_SPACING_M`]."""
        if not 0.0 <= spacing_m <= MAX_SPACING_M:
            raise ValueError(f"--spacing {spacing_m}: metres between homes, in [0, {MAX_SPACING_M:g}]")
        if spacing_m == 0.0:
            return self
        from .frames import ned_to_geodetic  # (frames compiles kernels: imported when spaced)

        return replace(self, home=ned_to_geodetic(instance * spacing_m, 0.0, 0.0, self.home))


# --spacing's bound: instance 249 stays within 5 km of the configured home, where the local frames'
# projection (quadcommon.frames.ned_to_geodetic) is millimetre-exact.
MAX_SPACING_M = 20.0


def load_rates(sec: Section) -> Rates:
    """The ``[rates]`` section: physics, control and GPS rates (Hz), validated against their ranges."""
    rates = Rates(
        physics_hz=sec.number("physics_hz", 1000.0, lo=100.0, hi=20000.0, unit="Hz"),
        control_hz=sec.number("control_hz", 500.0, lo=50.0, hi=2000.0, unit="Hz"),
        gps_hz=sec.number("gps_hz", 10.0, lo=1.0, hi=50.0, unit="Hz"),
    )
    ratio = rates.physics_hz / rates.control_hz
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9:
        raise sec.error(
            "control_hz", rates.control_hz, f"a whole divisor of physics_hz ({rates.physics_hz:g})"
        )
    return rates


def _spin_from_environment(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 <= value <= 0.05:
        raise ConfigError(f"environment variable {SPIN_ENV}: {text!r} is not a number of seconds in "
                          "[0, 0.05]")  # fmt: skip
    return value


def load_sitl(name_or_path: str | Path | None = None) -> SitlConfig:
    """The SITL file (``sitl.toml``, or a path): its rates and the rest of its sections, validated."""
    path = config_path("", name_or_path) if name_or_path else find_config("", "sitl")
    root = load_toml(path)
    sec = root.section("rates", optional=True)
    rates = load_rates(sec)
    sec.finish()
    sec = root.section("ports", optional=True)
    top = 65535 - wire.INSTANCE_MAX  # the highest base whose instance 249 is still a port
    gcs_link_above = wire.GCS_LOCAL_BASE - wire.GCS_REMOTE_BASE  # the autopilot's links move with their bases
    api_link_above = wire.API_LOCAL_BASE - wire.API_REMOTE_BASE
    hil = sec.integer("hil_base", wire.HIL_PORT_BASE, lo=1024, hi=top)
    gcs = sec.integer("gcs_base", wire.GCS_REMOTE_BASE, lo=1024, hi=top - gcs_link_above)
    api = sec.integer("api_base", wire.API_REMOTE_BASE, lo=1024, hi=top - api_link_above)
    zenoh_port = sec.integer("zenoh_base", wire.ZENOH_PORT_BASE, lo=1024, hi=top)
    sec.finish()
    sec = root.section("home", optional=True)
    home = (
        sec.number("latitude_deg", 47.397742, lo=-89.0, hi=89.0, unit="deg"),
        sec.number("longitude_deg", 8.545594, lo=-180.0, hi=180.0, unit="deg"),
        sec.number("altitude_m", 488.0, lo=-500.0, hi=9000.0, unit="m"),
    )
    sec.finish()
    sec = root.section("zenoh", optional=True)
    router = sec.string("router", "")
    sec.finish()
    sec = root.section("lockstep", optional=True)
    timeout = sec.number("timeout_s", 2.0, lo=0.05, hi=600.0, unit="s")
    spin = sec.number("spin_s", 0.002, lo=0.0, hi=0.05, unit="s")
    resend = sec.number("resend_s", 0.01, lo=0.001, hi=1.0, unit="s")
    sec.finish()
    if resend >= timeout:
        raise sec.error("resend_s", resend, f"less than timeout_s ({timeout:g} s)")
    impair = load_impair(root.section("impair", optional=True))
    root.finish()
    spin_text = environment.lockstep_spin()
    if spin_text is not None:
        spin = _spin_from_environment(spin_text)
    return SitlConfig(rates, hil, gcs, api, home, zenoh_port, router, timeout, spin, resend, impair)


def load_impair(sec: Section) -> ImpairConfig:
    """``[impair]``: ``seed`` and one spec string per link (``hil = "loss=1%,dup=0.5%"``)."""
    seed = sec.integer("seed", 0, lo=0, hi=2**31 - 1)
    links = {}
    for link in LINKS:
        text = sec.string(link, "")
        links[link] = parse_impairment(text, f"{sec.source}: key '{sec.key_name(link)}' = {text!r}")
    sec.finish()
    return ImpairConfig(seed, **links)
