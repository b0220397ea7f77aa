"""Where each vehicle's flight logs go: ``quadsitl up --log-dir DIR`` / ``--no-log``, down to the
autopilot's own command line (``python -m autopilot --log-dir DIR`` / ``--no-log``)."""

from __future__ import annotations

from sitl.cli import _log_dir, build_parser
from sitl.launcher import VehicleSpec


def test_quadsitl_up_gives_each_vehicle_its_log_directory():
    parse = build_parser().parse_args
    one = parse(["up"])
    assert (one.log_dir, one.no_log) == ("log", False) and _log_dir(one, 0) == "log"
    two = parse(["up", "--count", "2", "--instance", "3", "--log-dir", "/data/logs"])
    assert [_log_dir(two, n) for n in (3, 4)] == ["/data/logs/instance_3", "/data/logs/instance_4"]
    assert _log_dir(parse(["up", "--no-log"]), 0) is None


def test_the_launcher_passes_it_to_the_autopilot():
    logged = VehicleSpec(log_dir="/data/logs").autopilot_command()
    assert logged[logged.index("--log-dir") + 1] == "/data/logs" and "--no-log" not in logged
    assert "--no-log" in VehicleSpec().autopilot_command()  # the default of the launcher's users
