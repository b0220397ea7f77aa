"""The ``quadsitl`` command line as installed users see it (in-process, no SITL started): the
ground-station scripts as subcommands with their own flags, --version, --config-dir, ``config
copy``, help that states defaults, configuration errors without a traceback."""

from __future__ import annotations

import argparse
import importlib
import math
import re

import pytest

from autopilot.control import registry
from quadcommon import config
from quadcommon.cli_help import has_default_to_show
from quadcommon.kernel import compiling
from sitl import cli
from tests.own_law import laws_forgotten_afterwards, nan_above, write_overlay

SCRIPTS = ["fly_setpoints", "fly_trajectory", "fly_paper", "upload_mission", "upload_gusts", "record", "fail"]


def _parsers(parser: argparse.ArgumentParser, name: str):
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


def _all_parsers():
    yield from _parsers(cli.build_parser(), "quadsitl")
    for module in SCRIPTS:
        yield module, importlib.import_module(f"gcs_scripts.{module}").build_parser()
    yield "quadsitl analyze", importlib.import_module("gcs_scripts.analysis.analyze").build_parser()
    yield "quadsitl view", importlib.import_module("gcs_scripts.view.server").build_parser("quadsitl view")


@pytest.mark.timeout(30)
def test_every_option_has_help_and_says_its_default():
    missing, silent = [], []
    for name, parser in _all_parsers():
        formatter = parser._get_formatter()
        for action in parser._actions:
            if not action.option_strings or action.help == argparse.SUPPRESS:
                continue
            if not action.help:
                silent.append(f"{name} {action.option_strings[0]}")
            if not has_default_to_show(action):
                continue
            text = formatter._get_help_string(action) % {"default": action.default}
            if "default" not in text.lower():
                missing.append(f"{name} {action.option_strings[0]}")
    assert not missing, missing
    assert not silent, silent


@pytest.mark.timeout(10)
def test_a_default_of_zero_is_shown():
    parser = argparse.ArgumentParser(formatter_class=cli.HelpFormatter)
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance N")
    parser.add_argument("--fast", action="store_true", help="go")
    text = parser.format_help()
    assert "vehicle instance N (default: 0)" in text
    assert "go (default" not in text


@pytest.mark.timeout(30)
@pytest.mark.parametrize(
    ("argv", "module", "forwarded"),
    [
        (["fly", "setpoints", "--instance", "16"], "fly_setpoints", ["--instance", "16"]),
        (["fly", "trajectory", "--scenario", "helix"], "fly_trajectory", ["--scenario", "helix"]),
        (["fly", "paper", "--rate", "5"], "fly_paper", ["--rate", "5"]),
        (["mission", "upload", "m.toml", "--fly"], "upload_mission", ["m.toml", "--fly"]),
        (["mission", "download", "--save", "x"], "upload_mission", ["--download", "--save", "x"]),
        (["mission", "clear"], "upload_mission", ["--clear"]),
        (["gusts", "upload", "mixed", "--now"], "upload_gusts", ["mixed", "--now"]),
        (["record", "--duration", "3"], "record", ["--duration", "3"]),
        (["fail", "gps", "off", "--enable"], "fail", ["gps", "off", "--enable"]),
    ],
)
def test_subcommands_delegate_to_the_scripts_with_their_flags(monkeypatch, argv, module, forwarded):
    calls = []
    mod = importlib.import_module(f"gcs_scripts.{module}")
    monkeypatch.setattr(mod, "main", lambda a, prog: calls.append((a, prog)) or 7)
    assert cli.main(argv) == 7
    assert calls == [(forwarded, "quadsitl " + " ".join(argv[: 1 if argv[0] in ("record", "fail") else 2]))]


@pytest.mark.timeout(30)
@pytest.mark.parametrize(
    "argv", [["fly", "setpoints"], ["fly", "paper"], ["mission", "download"], ["gusts", "upload"], ["record"]]
)
def test_subcommand_help_is_the_scripts_under_the_new_name(capsys, argv):
    with pytest.raises(SystemExit) as info:
        cli.main([*argv, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: quadsitl {' '.join(argv)} ")
    assert "--instance" in out and "(default" in out


@pytest.mark.timeout(30)
def test_unknown_subcommand_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["fly", "loops"])
    assert info.value.code == 2
    assert "invalid choice: 'loops'" in capsys.readouterr().err


@pytest.mark.timeout(30)
@pytest.mark.skipif(not compiling(), reason="numba compiles nothing here (QUADSITL_PURE_PYTHON=1)")
def test_compile_missing_with_the_cache_full_loads_nothing(capsys):
    """After the suite's own ``quadsitl compile --missing`` (tests/conftest.py) every target is
    cached: the check (file names only) finds nothing to do and loads no entry."""
    assert cli.main(["compile", "--missing", "--no-campaign", "--controllers", "intbs_nlhinf", "se3"]) == 0
    assert capsys.readouterr().out.strip() == "quadsitl compile: every target is in the cache"


@pytest.mark.timeout(30)
def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"quadsitl {cli.version()}"


@pytest.mark.timeout(30)
def test_config_copy_writes_then_refuses_then_forces(tmp_path, capsys):
    target = tmp_path / "cfg"
    assert cli.main(["config", "copy", str(target)]) == 0
    assert (target / "scenarios" / "circle.toml").is_file()
    assert (target / "sitl.toml").is_file()
    assert cli.main(["config", "copy", str(target)]) == 2
    err = capsys.readouterr().err
    assert "already there; nothing written (--force overwrites)" in err and "Traceback" not in err
    assert cli.main(["config", "copy", str(target), "--force"]) == 0


@pytest.mark.timeout(30)
def test_config_dir_overlays_and_a_missing_name_lists_the_places(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(config.CONFIG_ENV, raising=False)
    monkeypatch.setattr(cli.os, "environ", dict(cli.os.environ))  # --config-dir writes the environment
    mine = tmp_path / "mine"
    (mine / "scenarios").mkdir(parents=True)
    assert cli.main(["--config-dir", str(mine), "run", "nosuch", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quadsitl: configuration error: no scenarios named 'nosuch'")
    assert str(mine.resolve() / "scenarios" / "nosuch.toml") in err
    assert str(config.SHIPPED_CONFIG_DIR / "scenarios" / "nosuch.toml") in err
    assert "available: circle, helix, hover" in err


@pytest.mark.timeout(30)
def test_config_dir_that_does_not_exist(tmp_path, capsys):
    assert cli.main(["--config-dir", str(tmp_path / "nope"), "config", "where"]) == 2
    assert "is not a directory" in capsys.readouterr().err


@pytest.mark.timeout(120)
@pytest.mark.parametrize("command", [["run", "hover", "--controller", "toy_nan_cli"],
                                     ["paper", "--scenarios", "hover", "--controllers", "toy_nan_cli",
                                      "--workers", "1"]])  # fmt: skip
def test_a_law_giving_nan_in_process_is_an_error_naming_it(tmp_path, capsys, monkeypatch, command):
    """``quadsitl run`` and ``quadsitl paper`` end where the autopilot terminates the flight, exit
    non-zero and say which controller gave a non-finite output: no table of NaN is written."""
    monkeypatch.setattr(cli.os, "environ", dict(cli.os.environ))  # --config-dir writes the environment
    mine = tmp_path / "mine"
    with laws_forgotten_afterwards(mine):
        write_overlay(mine, "toy_nan_cli", failure=nan_above(1.5))
        out = tmp_path / "out"
        extra = ["--out", str(out)] if command[0] == "paper" else []
        assert cli.main(["--config-dir", str(mine), *command, "--duration", "6", *extra]) == 1
    captured = capsys.readouterr()
    assert re.search(r"^quadsitl: hover: flight terminated at t=\S+ s: controller toy_nan_cli: non-finite "
                     r"output \(U1 nan", captured.err, re.M), captured.err  # fmt: skip
    assert "nan" not in captured.out and "Traceback" not in captured.err
    assert not (out / "tables.md").exists()


@pytest.mark.timeout(60)
def test_a_broken_law_file_leaves_the_shipped_controllers_flying(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cli.os, "environ", dict(cli.os.environ))
    mine = tmp_path / "mine"
    (mine / "laws").mkdir(parents=True)
    (mine / "laws" / "draft.py").write_text('NAME = "draft"\ndef step(:\n')
    reported = pytest.warns(registry.LawFileWarning, match=r"draft\.py, line 2: SyntaxError")
    with laws_forgotten_afterwards(mine), reported:
        assert cli.main(["--config-dir", str(mine), "run", "hover", "--controller", "intbs_nlhinf",
                         "--duration", "0.5"]) == 0  # fmt: skip
    assert capsys.readouterr().out.startswith("hover / intbs_nlhinf: final error")


@pytest.mark.timeout(30)
def test_fail_help_lists_px4s_units_and_types_and_what_is_modelled(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["fail", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: quadsitl fail ") and "SYS_FAILURE_EN to 1 first" in out
    assert "mavlink_signal" in out and "intermittent" in out and "gyro: ok, off, stuck" in out
    with pytest.raises(SystemExit) as info:
        cli.main(["fail", "propeller", "off"])
    assert info.value.code == 2 and "invalid choice: 'propeller'" in capsys.readouterr().err


@pytest.mark.timeout(30)
def test_fail_takes_the_motor_before_the_type_and_its_effectiveness_after():
    """``quadsitl fail motor 2 off`` (as ``-i 2``), ``motor 3 wrong 0.7``; a figure anywhere else,
    an instance given twice or an effectiveness outside (0, 1] are refused with the reason."""
    from gcs_scripts.fail import Request, parse_words
    from quadcommon.failures import Type, Unit

    assert parse_words("motor", ["2", "off"], 0)[:3] == (Unit.motor, Type.off, 2)
    assert parse_words("motor", ["off"], 2)[:3] == (Unit.motor, Type.off, 2)
    assert parse_words("motor", ["3", "wrong", "0.7"], 0) == Request(Unit.motor, Type.wrong, 3, 0.7)
    assert math.isnan(parse_words("motor", ["3", "wrong"], 0).effectiveness)  # the vehicle's SIM_MOT_EFF
    assert parse_words("gps", ["off"], 0)[:3] == (Unit.gps, Type.off, 0)
    for words, instance, why in (
        (["2", "off"], 3, "give one"),
        (["wrong", "1.5"], 1, "in (0, 1]"),
        (["wrong", "x"], 1, "a number in (0, 1]"),
        (["off", "0.5"], 1, "only for 'motor N wrong"),
        (["2"], 0, "type: nothing"),
        (["2", "broken"], 0, "type: 'broken'"),
    ):
        with pytest.raises(ValueError, match=re.escape(why)):
            parse_words("motor", words, instance)


@pytest.mark.timeout(30)
def test_compile_estimate_adds_the_campaign_flights_on_the_ekf():
    """``quadsitl compile --estimate``: each controller's campaign flight on the EKF too (the
    entry an ``[estimation]`` campaign flies), the slowest first; without it, not."""
    from sitl.campaign.kernels import ON_ESTIMATE, ON_TRUTH
    from sitl.compile import entries_of, targets

    assert targets(["a", "b"]) == ["plant", "estimator", "sensors", "campaign:a", "campaign:b", "cascade:a",
                                   "cascade:b"]  # fmt: skip
    assert targets(["a"], estimate=True) == ["plant", "estimator", "sensors", "campaign-ekf:a", "campaign:a",
                                             "cascade:a"]  # fmt: skip
    ((_, _, _, *on_ekf, nogil),) = entries_of("campaign-ekf:intbs_nlhinf")
    ((_, _, _, *on_truth, _),) = entries_of("campaign:intbs_nlhinf")
    assert tuple(on_ekf) == ON_ESTIMATE and tuple(on_truth) == ON_TRUTH and nogil is True
