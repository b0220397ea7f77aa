"""Campaign specs are validated like every config; sampling is deterministic per run."""

from pathlib import Path

import numpy as np
import pytest

from autopilot.control.config import load_controller
from quadcommon.schema import ConfigError
from sitl.campaign.sampling import sample_run, stream
from sitl.campaign.spec import CAMPAIGN_DIR, flown_by, load_campaign
from tests.own_law import laws_forgotten_afterwards, write_overlay

from . import specs

pytestmark = pytest.mark.timeout(120)

MINIMAL = """
name = "t"
scenario = "helix"
controllers = ["intbs_nlhinf"]
runs = 4
seed = 1
{extra}
"""


def _load(tmp_path: Path, extra: str):
    path = tmp_path / "spec.toml"
    path.write_text(MINIMAL.format(extra=extra))
    return load_campaign(path), path


def _error(tmp_path: Path, extra: str) -> str:
    path = tmp_path / "spec.toml"
    path.write_text(MINIMAL.format(extra=extra))
    with pytest.raises(ConfigError) as info:
        load_campaign(path)
    message = str(info.value)
    assert str(path) in message  # every error names the file
    return message


@pytest.mark.parametrize("path", sorted(CAMPAIGN_DIR.glob("*.toml")), ids=lambda p: p.stem)
def test_every_example_spec_loads_and_samples(path):
    spec = load_campaign(path)
    assert spec.runs >= 1 and spec.controllers
    sample = sample_run(spec, 0)
    assert sample.parameters and sample.plant_vehicle.plant.mass_kg > 0.0
    assert not spec.warnings  # the examples put wind on vehicles that feel it


def test_the_paper_box_is_the_six_cascades_within_30_percent():
    spec = load_campaign("paper_box")
    assert spec.controller_names == ("intbs_nlhinf", "intbs", "bs_nlhinf", "px4_pid", "px4_pid_tuned", "se3")
    assert spec.plant.mass_scale.support() == (0.7, 1.3)
    assert [d.support() for d in spec.plant.inertia_scale] == [(0.7, 1.3)] * 3
    assert spec.runs == 1000 and spec.wire_float32
    assert len(spec.base_profile.steps) == 6  # the paper's schedule (the helix scenario's)
    drawn = np.array([sample_run(spec, r).parameters["inertia_scale_y"] for r in range(200)])
    assert 0.7 <= drawn.min() < 0.75 and 1.25 < drawn.max() <= 1.3


@pytest.mark.parametrize(
    "extra, key, value, allowed",
    [
        ("[plant]\nmass_scale = { uniform = [0.3, 1.3] }", "plant.mass_scale.uniform[0]", "0.3", "[0.5, 2]"),
        ("[plant]\nmass_scale = 3.0", "plant.mass_scale", "3.0", "[0.5, 2]"),
        ("[plant]\nmass_scale = { uniform = [1.2, 0.8] }",
         "plant.mass_scale.uniform", "[1.2, 0.8]", "low <= high"),
        ("[plant]\nmass_scale = { normal = [1.0, 0.1] }",
         "plant.mass_scale.clip", "", "clip = [lo, hi] within [0.5, 2]"),
        ("[plant]\nmass_scale = { gauss = [1.0, 0.1] }",
         "plant.mass_scale", "gauss", "exactly one of uniform, normal, choice"),
        (
            "[plant]\ncom_offset_m = [0.0, { uniform = [0.0, 0.9] }, 0.0]",
            "plant.com_offset_m[1].uniform[1]", "0.9", "[-0.5, 0.5] (m)",
        ),
        (
            "[plant]\nthrust_coefficient_scale = 1.1",
            "plant.thrust_coefficient_scale", "1.1", "only with actuation = 'rotors'",
        ),
        ("[initial_state]\nposition_offset_m = [0.0, 0.0, { uniform = [-2.0, 0.0] }]",
         "initial_state.position_offset_m[2]", "U[-2, 0]", ">= -1 m"),
        ("runs = 0", "runs", "0", "[1, 1e+06]"),
        ("[failure]\nmax_tilt_rad = 9.0", "failure.max_tilt_rad", "9.0", "[0.05, 3.14159] (rad)"),
        ("[disturbances]\n[[disturbances.step]]\nchannel = 'force_w'\nstart_s = 1.0\nvalue = 1.0",
         "disturbances.step[0].channel", "force_w", "one of 'force_x'"),
        ("[disturbances]\n[[disturbances.step]]\nchannel = 'torque_yaw'\nstart_s = 1.0\n"
         "value = { uniform = [0, 20] }",
         "disturbances.step[0].value.uniform[1]", "20", "[-10, 10] (N m)"),
        ("[disturbances]\n[[disturbances.step]]\nchannel = 'force_x'\nstart_s = { uniform = [1, 5] }\n"
         "end_s = 4.0\nvalue = 1.0", "disturbances.step[0].end_s", "4", "always after start_s"),
    ],
)  # fmt: skip
def test_errors_name_file_key_value_and_range(tmp_path, extra, key, value, allowed):
    if extra.startswith("runs"):
        message = _error_replacing(tmp_path, "runs = 4", extra)
    else:
        message = _error(tmp_path, extra)
    assert f"'{key}'" in message, message
    assert value in message, message
    assert allowed in message, message


def _error_replacing(tmp_path: Path, old: str, new: str) -> str:
    path = tmp_path / "spec.toml"
    path.write_text(MINIMAL.format(extra="").replace(old, new))
    with pytest.raises(ConfigError) as info:
        load_campaign(path)
    assert str(path) in str(info.value)
    return str(info.value)


def test_unknown_keys_and_cascades_are_refused(tmp_path):
    assert "'plant.mass_scael'" in _error(tmp_path, "[plant]\nmass_scael = 1.0")
    message = _error_replacing(tmp_path, '["intbs_nlhinf"]', '["intbs_nlhinf", "pid"]')
    assert "'controllers[1]'" in message and "'pid'" in message and "intbs_nlhinf" in message


def test_a_box_that_allows_a_non_rigid_body_is_refused(tmp_path):
    message = _error(
        tmp_path,
        "[plant]\ninertia_scale = { uniform = [0.5, 1.0] }\n"
        "products_of_inertia_kg_m2 = [{ uniform = [0.0, 0.002] }, 0.0, 0.0]",
    )
    assert "positive definite" in message and "'plant.inertia_scale'" in message


def test_wind_on_a_drag_free_vehicle_is_warned(tmp_path):
    spec, _ = _load(tmp_path, "[disturbances]\n[disturbances.dryden]\nw20_m_s = 5.0\naltitude_m = 2.5")
    assert spec.warnings and "drag" in spec.warnings[0]


def test_a_run_depends_only_on_seed_run_and_name(tmp_path):
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box"))
    a = sample_run(spec, 4)
    assert sample_run(spec, 4) == a  # repeatable
    assert sample_run(spec, 5).parameters != a.parameters
    # another randomised quantity does not move the others
    more = load_campaign(
        specs.write(tmp_path, specs.BOX.replace("[initial_state]", "[initial_state]\nvelocity_m_s = "
                                                "[{{ uniform = [-1, 1] }}, 0.0, 0.0]"), "more")
    )  # fmt: skip
    b = sample_run(more, 4)
    assert b.parameters["velocity_x_m_s"] != 0.0
    assert {k: v for k, v in b.parameters.items() if k != "velocity_x_m_s"} == {
        k: v for k, v in a.parameters.items() if k != "velocity_x_m_s"
    }
    # the stream is a pure function of (seed, run, name)
    assert stream(1, 2, "mass_scale").random() == stream(1, 2, "mass_scale").random()
    assert stream(1, 2, "mass_scale").random() != stream(1, 3, "mass_scale").random()


def test_sampled_plant_is_what_run_scenario_would_fly(tmp_path):
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box"))
    s = sample_run(spec, 0)
    p = s.parameters
    nominal = spec.vehicle.plant
    assert s.plant_vehicle.plant.mass_kg == nominal.mass_kg * p["mass_scale"]
    assert s.plant_vehicle.plant.inertia_kg_m2 == tuple(
        nominal.inertia_kg_m2[i] * p[f"inertia_scale_{a}"] for i, a in enumerate("xyz")
    )
    assert s.vehicle.nominal == spec.vehicle.nominal  # the controllers keep the nominal model
    assert s.scenario.initial_position_m[0] == spec.scenario.initial_position_m[0] + p["position_offset_x_m"]
    steps = {st.channel: st for st in s.gusts.steps}
    assert steps["force_x"].value == p["step0_value"] and steps["force_x"].start_s == p["step0_start_s"]
    assert steps["torque_yaw"].end_s == p["step2_end_s"]


def test_dryden_seed_is_drawn_per_run(tmp_path):
    spec = load_campaign(specs.write(tmp_path, specs.WIND, "wind"))
    seeds = {sample_run(spec, r).gusts.dryden.seed for r in range(4)}
    assert len(seeds) == 4


def test_a_spec_flown_by_one_controller_listed_or_not(tmp_path):
    """What ``benchmarks/campaign.py --controller NAME`` and ``quadsitl compile`` fly: the spec's
    runs with one controller, the spec's own entry or any controller found by name (a researcher's
    from a configuration directory included); a name found nowhere is refused, naming it."""
    box = load_campaign("paper_box", runs=3)
    alone = flown_by(box, "se3")
    assert alone.controllers == (box.controllers[box.controller_names.index("se3")],)
    same = ("runs", "seed", "plant", "initial", "elements", "duration_s")
    assert all(getattr(alone, field) == getattr(box, field) for field in same)
    with laws_forgotten_afterwards(tmp_path):
        name = write_overlay(tmp_path, "toy_pd_spec")
        mine = flown_by(box, name)
        assert mine.controller_names == (name,) and mine.controllers[0] == load_controller(name)
        assert mine.fingerprint() != box.fingerprint()
    with pytest.raises(ConfigError, match="no controllers named 'nosuch'"):
        flown_by(box, "nosuch")
