"""``quadsitl fly|mission ... --instance 0-9`` (sitl/fan_out.py): the ranges it reads, the
arguments each instance's script gets, what it refuses, and real scripts run side by side (their
lines prefixed, the first failure's exit status)."""

from __future__ import annotations

import sys

import pytest

from sitl import cli
from sitl.fan_out import (
    InstanceError,
    check_several,
    parse_instances,
    run_each,
    script_argv,
    several_instances,
)

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize(("text", "instances"), [
    ("3", [3]), ("0-2", [0, 1, 2]), ("0..2", [0, 1, 2]), ("8,3,5-6", [3, 5, 6, 8]), ("1,1-2", [1, 2]),
    ("247-249", [247, 248, 249]),
])  # fmt: skip
def test_ranges_and_lists_of_instances(text, instances):
    assert parse_instances(text) == instances


@pytest.mark.parametrize("text", ["", "a", "3-", "-3", "5-3", "0-250", "1,,2", "2.5", "0-1-2"])
def test_a_bad_range_is_refused_naming_it(text):
    with pytest.raises(InstanceError, match="--instance"):
        parse_instances(text)


def test_one_instance_is_left_to_the_script_and_several_are_fanned_out():
    assert several_instances(["--scenario", "helix"]) is None
    assert several_instances(["--instance", "4"]) is None
    assert several_instances(["--instance=4-4"]) is None  # one vehicle: the script itself
    assert several_instances(["--instance", "4-5", "--rate", "5"]) == [4, 5]
    assert several_instances(["--instance=4,6"]) == [4, 6]
    assert several_instances(["--", "--instance", "4-5"]) is None  # past "--": not ours


def test_each_script_gets_its_instance_and_its_own_files():
    argv = ["--download", "--instance", "0-9", "--save", "m_{instance}.txt"]
    assert script_argv(argv, 7) == ["--download", "--instance", "7", "--save", "m_7.txt"]
    assert script_argv(["--instance=0-9"], 3) == ["--instance", "3"]


@pytest.mark.parametrize(("argv", "said"), [
    (["--url", "udpin:127.0.0.1:14540"], "--url names one vehicle"),
    (["--url=udpin:127.0.0.1:14540"], "--url names one vehicle"),
    (["--save", "mission.txt"], "--save mission.txt: with several instances the path must contain"),
    (["--out=runs/a"], "--out runs/a: with several"),
])  # fmt: skip
def test_what_cannot_go_with_several_instances_is_refused(argv, said):
    with pytest.raises(InstanceError, match=said.replace("{", r"\{").replace("}", r"\}")):
        check_several(argv)
    check_several(["--save", "m_{instance}.txt", "--rate", "5"])  # (a per-instance file is fine)


def test_the_cli_refuses_a_bad_range_with_status_2(capsys):
    assert cli.main(["mission", "download", "--instance", "3-250"]) == 2
    assert "quadsitl mission download: --instance '3-250'" in capsys.readouterr().err
    assert cli.main(["fly", "setpoints", "--instance", "0-1", "--url", "udpin:127.0.0.1:14540"]) == 2


def test_the_scripts_run_side_by_side_their_lines_prefixed_the_first_failure_returned(capfd):
    """Real processes: instance 4 fails with 3, 6 with 5; every line comes out under its instance."""
    script = ("import sys; n = int(sys.argv[sys.argv.index('--instance') + 1]); "
              "sys.stdout.buffer.write(b'\\xff not UTF-8\\n'); sys.stdout.flush(); "
              "print('flying', sys.argv[1:]); sys.exit({4: 3, 6: 5}.get(n, 0))")  # fmt: skip
    argv = ["--log", "l{instance}", "--instance", "3-6"]
    code = run_each([sys.executable, "-c", script], argv, [3, 4, 5, 6], "quadsitl fly x")
    out, err = capfd.readouterr()
    assert code == 3
    for n in (3, 4, 5, 6):
        assert f"[{n}] flying ['--log', 'l{n}', '--instance', '{n}']" in out.splitlines()
        assert f"[{n}] \ufffd not UTF-8" in out.splitlines()  # (relayed, not a stopped relay)
    assert "quadsitl fly x: 2 of 4 failed: instance 4 (exit 3), instance 6 (exit 5)" in err
    assert run_each([sys.executable, "-c", "pass"], ["--instance", "0,2"], [0, 2], "p") == 0
    assert "p: instances 0, 2: all 2 succeeded" in capfd.readouterr().out
