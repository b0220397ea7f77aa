"""Drawing one run of a campaign: the true plant, the initial state and the disturbance profile.

Determinism: every quantity of every run has its own random stream,
``SeedSequence(seed, spawn_key=(run, crc32(name)))``, so a run's values depend only on the spec's
seed, the run's index and the quantity's name: not on how runs are chunked, which worker flies
them, in which order, or which other quantities the spec randomises. (Same numpy version: numpy
keeps ``SeedSequence`` and ``PCG64`` stable, and its distributions' streams across minor
versions except for announced fixes.)

The sampled vehicle is built the way the scalar runner builds its plant (``apply_uncertainty``
on a scenario whose mass and inertia scales are the drawn ones), so ``sitl.inprocess.run_scenario``
flies exactly the same numbers; rotor constants (``actuation = "rotors"``) are then scaled on the
plant only (the allocator keeps the nominal ones). The drawn motor failures are the sampled
scenario's ``actuator_faults``, which the simulator core applies as it applies a scenario's, and
the batch engine through the same fault table (:func:`simulator.dynamics.plant.schedule`).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from quadcommon.config import ScenarioConfig, VehicleConfig, apply_uncertainty
from quadcommon.failures import ActuatorFault
from simulator.environment.gust_profile import GustProfile, gust_profile_from_mapping, profile_to_mapping
from simulator.sensors.config import SensorConfig, SensorFault, default_fault_value

from .spec import CampaignSpec, Distribution, fixed

Vector3 = tuple[float, float, float]
AXES = ("x", "y", "z")
EULER = ("phi", "theta", "psi")
PRODUCTS = ("xy", "xz", "yz")
_KIND_PREFIX = {"step": "step", "ramp": "ramp", "one_minus_cosine": "gust"}


@dataclass(frozen=True)
class RunSample:
    """Everything that makes run ``run`` what it is."""

    run: int
    parameters: dict[str, float]  # column name -> drawn value, in a fixed order
    scenario: ScenarioConfig  # sampled initial state; mass/inertia scales as drawn (shared case)
    vehicle: VehicleConfig  # nominal model + sampled structure (what run_scenario takes)
    plant_vehicle: VehicleConfig  # the true plant flown (apply_uncertainty + rotor scaling)
    initial_velocity_m_s: Vector3
    gusts: GustProfile
    sensors: SensorConfig | None = None  # on the estimate: the run's sensors (seed, figures, faults)
    faults: tuple[str, ...] = ()  # the faults drawn, described (actuators' and sensors')
    fault_onset_s: float = math.inf  # the first drawn fault's onset (s)

    @property
    def fault(self) -> str:
        """The faults drawn, in words (the results' ``fault`` column)."""
        return "; ".join(self.faults)


def stream(seed: int, run: int, name: str) -> np.random.Generator:
    """The random stream of quantity ``name`` in run ``run``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, zlib.crc32(name.encode()))))


class _Draw:
    def __init__(self, seed: int, run: int) -> None:
        self.seed, self.run = seed, run
        self.values: dict[str, float] = {}

    def __call__(self, name: str, dist: Distribution) -> float:
        value = dist.sample(stream(self.seed, self.run, name))
        self.values[name] = value
        return value

    def vector(self, names: tuple[str, ...], dists: tuple[Distribution, ...]) -> Vector3:
        return tuple(self(n, d) for n, d in zip(names, dists, strict=True))  # type: ignore[return-value]


def sample_run(spec: CampaignSpec, run: int) -> RunSample:
    """Draw run ``run`` of ``spec`` (0-based)."""
    draw = _Draw(spec.seed, run)
    pd = spec.plant
    mass_scale = draw("mass_scale", pd.mass_scale)
    if len(pd.inertia_scale) == 1:
        shared = draw("inertia_scale", pd.inertia_scale[0])
        axis_scales = (1.0, 1.0, 1.0)
    else:
        shared = 1.0
        axis_scales = draw.vector(tuple(f"inertia_scale_{a}" for a in AXES), pd.inertia_scale)
    com = draw.vector(tuple(f"com_offset_{a}_m" for a in AXES), pd.com_offset_m)
    products = draw.vector(tuple(f"product_{p}_kg_m2" for p in PRODUCTS), pd.products_of_inertia_kg_m2)
    rotor_scales = None
    if spec.vehicle.actuation.mode == "rotors":
        rotor_scales = (
            draw("thrust_coefficient_scale", pd.thrust_coefficient_scale),
            draw("drag_coefficient_scale", pd.drag_coefficient_scale),
            draw("rotor_time_constant_scale", pd.rotor_time_constant_scale),
        )
    ini = spec.initial
    dpos = draw.vector(tuple(f"position_offset_{a}_m" for a in AXES), ini.position_offset_m)
    deul = draw.vector(tuple(f"euler_offset_{e}_rad" for e in EULER), ini.euler_offset_rad)
    velocity = draw.vector(tuple(f"velocity_{a}_m_s" for a in AXES), ini.velocity_m_s)

    base = spec.vehicle
    inertia = base.plant.inertia_kg_m2
    if len(pd.inertia_scale) == 3:
        inertia = tuple(inertia[i] * axis_scales[i] for i in range(3))
    vehicle = replace(
        base,
        plant=replace(
            base.plant, inertia_kg_m2=inertia, com_offset_m=com, products_of_inertia_kg_m2=products
        ),
    )
    s0 = spec.scenario
    scenario = replace(
        s0,
        duration_s=spec.duration_s,
        initial_position_m=tuple(s0.initial_position_m[i] + dpos[i] for i in range(3)),
        initial_euler_rad=tuple(s0.initial_euler_rad[i] + deul[i] for i in range(3)),
        mass_scale=mass_scale,
        inertia_scale=shared,
    )
    plant_vehicle = apply_uncertainty(vehicle, scenario)
    if rotor_scales is not None:
        rot = plant_vehicle.rotors
        plant_vehicle = replace(
            plant_vehicle,
            rotors=replace(
                rot,
                thrust_coefficient_n_s2=rot.thrust_coefficient_n_s2 * rotor_scales[0],
                drag_coefficient_n_m_s2=rot.drag_coefficient_n_m_s2 * rotor_scales[1],
                time_constant_s=rot.time_constant_s * rotor_scales[2],
            ),
        )
    gusts = _sample_profile(spec, run, draw)
    sensors = _sample_sensors(spec, run, draw)
    actuator_faults = _sample_actuator_faults(spec, run, draw)
    scenario = replace(scenario, actuator_faults=actuator_faults)
    described = [f.describe() for f in actuator_faults]
    onsets = [f.start_s for f in actuator_faults]
    if sensors is not None and spec.estimation is not None and spec.estimation.faults:
        drawn = sensors.faults[len(sensors.faults) - len(spec.estimation.faults) :]
        described += [f"{f.kind} from {f.start_s:.3g} s" for f in drawn]
        onsets += [f.start_s for f in drawn]
    return RunSample(run, draw.values, scenario, vehicle, plant_vehicle, velocity, gusts, sensors,
                     tuple(described), min(onsets, default=math.inf))  # fmt: skip


def _sample_actuator_faults(spec: CampaignSpec, run: int, draw: _Draw) -> tuple[ActuatorFault, ...]:
    """The run's motor failures (``[[actuator_faults]]``), as a scenario states them."""
    out = []
    for i, f in enumerate(spec.actuator_faults):
        prefix = f"actuator_fault{i}"
        motor = int(round(draw(f"{prefix}_motor", f.motor)))
        kind = f.types[0]
        if len(f.types) > 1:
            index = int(stream(spec.seed, run, f"{prefix}_type").integers(len(f.types)))
            draw.values[f"{prefix}_type_index"] = float(index)
            kind = f.types[index]
        effectiveness = draw(f"{prefix}_effectiveness", f.effectiveness) if "wrong" in f.types else 1.0
        if kind != "wrong":
            effectiveness = 0.0 if kind == "off" else 1.0
        start = draw(f"{prefix}_start_s", f.start_s)
        out.append(ActuatorFault(motor, kind, effectiveness, start))
    return tuple(out)


def _sample_sensors(spec: CampaignSpec, run: int, draw: _Draw) -> SensorConfig | None:
    """The run's sensors: the profile with its own noise seed, the drawn figures and faults."""
    est = spec.estimation
    if est is None:
        return None
    seed = int(stream(spec.seed, run, "sensor_seed").integers(2**62))
    draw.values["sensor_seed"] = float(seed)
    c = est.sensors
    v = {key: draw(key, dist) for key, dist in est.parameters.items()}
    accel, gyro, mag, baro, gps, vision = (
        c.accelerometer,
        c.gyroscope,
        c.magnetometer,
        c.barometer,
        c.gps,
        c.vision,
    )
    accel = replace(accel, noise_density=v.get("accel_noise_density", accel.noise_density),
                    turn_on_bias_std=v.get("accel_turn_on_bias_std", accel.turn_on_bias_std))  # fmt: skip
    gyro = replace(gyro, noise_density=v.get("gyro_noise_density", gyro.noise_density),
                   turn_on_bias_std=v.get("gyro_turn_on_bias_std", gyro.turn_on_bias_std))  # fmt: skip
    mag = replace(mag, noise_std_gauss=v.get("mag_noise_std_gauss", mag.noise_std_gauss))
    baro = replace(baro, noise_std_hpa=v.get("baro_noise_std_hpa", baro.noise_std_hpa))
    gps = replace(
        gps,
        horizontal_noise_std_m=v.get("gps_horizontal_noise_std_m", gps.horizontal_noise_std_m),
        vertical_noise_std_m=v.get("gps_vertical_noise_std_m", gps.vertical_noise_std_m),
        velocity_noise_std_m_s=v.get("gps_velocity_noise_std_m_s", gps.velocity_noise_std_m_s),
    )
    vision = replace(
        vision, position_noise_std_m=v.get("vision_position_noise_std_m", vision.position_noise_std_m)
    )
    faults = list(c.faults)
    for i, f in enumerate(est.faults):
        kind = f.kind
        if kind:
            prefix = f"fault{i}_{kind}"
        else:  # drawn among several: the entry's streams, and the index drawn
            prefix = f"fault{i}"
            index = int(stream(spec.seed, run, f"{prefix}_kind").integers(len(f.kinds)))
            draw.values[f"{prefix}_kind_index"] = float(index)
            kind = f.kinds[index]
        start = draw(f"{prefix}_start_s", f.start_s)
        duration = (
            draw(f"{prefix}_duration_s", f.duration_s) if f.duration_s is not None else spec.duration_s + 1.0
        )
        values = f.value if f.value is not None else tuple(fixed(v) for v in default_fault_value(kind))
        value = draw.vector(tuple(f"{prefix}_value_{a}" for a in AXES), values)
        faults.append(SensorFault(kind, start, duration, value))
    return replace(c, seed=seed, accelerometer=accel, gyroscope=gyro, magnetometer=mag, barometer=baro,
                   gps=gps, vision=vision, faults=tuple(faults))  # fmt: skip


def _sample_profile(spec: CampaignSpec, run: int, draw: _Draw) -> GustProfile:
    """The base profile plus the randomised elements, validated by the gust-profile parser."""
    if not spec.elements and spec.dryden is None:
        return spec.base_profile
    mapping: dict[str, Any] = profile_to_mapping(spec.base_profile)
    counters = {"step": 0, "ramp": 0, "one_minus_cosine": 0}
    for element in spec.elements:
        j = counters[element.kind]
        counters[element.kind] += 1
        prefix = f"{_KIND_PREFIX[element.kind]}{j}"
        item: dict[str, Any] = {}
        for key, value in element.values.items():
            if isinstance(value, Distribution):
                item[key] = draw(f"{prefix}_{key}", value)
            elif isinstance(value, tuple):
                item[key] = list(draw.vector(tuple(f"{prefix}_{key}_{a}" for a in AXES), value))
            else:
                item[key] = value  # channel, axis
        mapping.setdefault(element.kind, []).append(item)
    if spec.dryden is not None:
        d: dict[str, Any] = {}
        for key, value in spec.dryden.values.items():
            if isinstance(value, Distribution):
                d[key] = draw(f"dryden_{key}", value)
            elif isinstance(value, tuple):
                d[key] = list(draw.vector(tuple(f"dryden_{key}_{a}" for a in AXES), value))
            elif key == "seed":
                d[key] = (
                    value if value is not None else int(stream(spec.seed, run, "dryden_seed").integers(2**31))
                )
                draw.values["dryden_seed"] = float(d[key])
            else:
                d[key] = value
        mapping["dryden"] = d
    return gust_profile_from_mapping(mapping, source=f"{spec.path} (run {run})", prefix="disturbances.")
