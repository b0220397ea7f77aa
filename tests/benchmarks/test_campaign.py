"""``benchmarks/campaign.py`` takes any controller a user can name, as the docs tell a law's author to
time it: listed in the spec or not (the spec's runs flown by it alone); an unknown one is refused
before anything is flown, and a measurement that fails shows why."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from tests.own_law import laws_forgotten_afterwards, write_overlay

pytestmark = pytest.mark.timeout(60)

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "campaign.py"


@pytest.fixture(scope="module")
def benchmark():
    spec = importlib.util.spec_from_file_location("campaign_benchmark", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_law_of_ones_own_flies_the_spec_alone(benchmark, tmp_path):
    with laws_forgotten_afterwards(tmp_path):
        name = write_overlay(tmp_path, "toy_pd_bench")
        args = benchmark.build_parser().parse_args(["--controller", name, "--runs", "3"])
        spec = benchmark.flown_spec(args)
    assert spec.controller_names == (name,) and spec.runs == 3 and spec.name == "paper_box"
    shipped = benchmark.flown_spec(benchmark.build_parser().parse_args(["--runs", "3"]))
    assert shipped.controller_names == ("intbs_nlhinf",) and shipped.wire_float32


def test_an_unknown_controller_is_refused_before_anything_flies(benchmark, capsys):
    with pytest.raises(SystemExit) as refused:
        benchmark.main(["--controller", "nosuch", "--runs", "1"])
    assert refused.value.code == 2
    err = capsys.readouterr().err
    assert "benchmarks/campaign.py: configuration error: no controllers named 'nosuch'" in err
    assert "Traceback" not in err


def test_its_help_says_which_controllers_it_takes(benchmark):
    text = " ".join(benchmark.build_parser().format_help().split())
    assert "--controller NAME" in text and "--config-dir DIR" in text
    assert "not in the spec's list" in text


def test_a_spec_that_draws_faults_is_flown_again_without_them(benchmark):
    """``--spec paper_box_faults``: the same runs with and without their faults, for the cost."""
    parse = benchmark.build_parser().parse_args
    faults = benchmark.flown_spec(parse(["--spec", "paper_box_faults", "--runs", "3"]))
    healthy = benchmark.flown_spec(parse(["--spec", "paper_box_faults", "--runs", "3", "--healthy"]))
    assert faults.draws_faults and not healthy.draws_faults
    assert faults.vehicle == healthy.vehicle and faults.plant == healthy.plant and faults.seed == healthy.seed
