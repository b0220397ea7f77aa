"""Inject a failure into a running vehicle, as PX4's ``failure`` command: ``quadsitl fail UNIT TYPE``.

Sends ``MAV_CMD_INJECT_FAILURE`` (param1 the unit, param2 the type, param3 the instance, 0 = all:
what MAVSDK's Failure plugin sends) on the vehicle's API link and prints its COMMAND_ACK and the
reason or announcement the vehicle gave (STATUSTEXT). The vehicle refuses it (DENIED) while its
parameter ``SYS_FAILURE_EN`` is 0, the default: ``--enable`` sets it to 1 first. What each unit and
type does here, and which are unsupported: ``quadcommon/failures.py``, docs/failures.md.

Exit status: 0 accepted, 1 refused (or no answer), 2 a bad argument.
"""

from __future__ import annotations

import argparse
import sys

from quadcommon.cli_help import HelpFormatter
from quadcommon.failures import Type, Unit, help_text

from .link import LinkError, connect, mavutil

RESULT_NAMES = {value: enum.name.removeprefix("MAV_RESULT_")
                for value, enum in mavutil.mavlink.enums["MAV_RESULT"].items()}  # fmt: skip


def inject(link, unit: Unit, failure_type: Type, instance: int = 0, enable: bool = False,
           out=print) -> int:  # fmt: skip
    """On a connected :class:`~gcs_scripts.link.Link`: (``enable``: SYS_FAILURE_EN = 1, then) the
    command; prints the ACK and the vehicle's texts; returns the MAV_RESULT."""
    if enable:
        now = link.set_parameter("SYS_FAILURE_EN", 1, integer=True)
        out(f"SYS_FAILURE_EN = {now:g}")
    mark = link.texts_seen
    params = (int(unit), int(failure_type), instance)
    result = link.command_long(mavutil.mavlink.MAV_CMD_INJECT_FAILURE, params, check=False)
    texts = link.texts_since(mark)
    answer = RESULT_NAMES.get(result, "no COMMAND_ACK" if result < 0 else str(result))
    out(f"failure {unit.name} {failure_type.name} (instance {instance}): {answer}"
        + (f": {texts[-1]}" if texts else ""))  # fmt: skip
    return result


def build_parser(prog: str = "quadsitl fail") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=HelpFormatter,
                                     epilog="units and their types here:\n" + help_text())  # fmt: skip
    parser.add_argument("unit", choices=[u.name for u in Unit], metavar="UNIT",
                        help="the failing unit, PX4's names: " + ", ".join(u.name for u in Unit))  # fmt: skip
    parser.add_argument("type", choices=[t.name for t in Type], metavar="TYPE",
                        help=f"the failure type: {', '.join(t.name for t in Type)} (ok ends it)")  # fmt: skip
    parser.add_argument("-i", "--instance", type=int, default=0,
                        help="the unit's instance, 1-based (a motor: 1 right, 2 left, 3 front, 4 rear); "
                        "0 = all, the default")  # fmt: skip
    parser.add_argument("--enable", action="store_true",
                        help="set the vehicle's SYS_FAILURE_EN to 1 first (failure injection is refused "
                        "while it is 0, PX4's default)")  # fmt: skip
    parser.add_argument("--vehicle-instance", type=int, default=0, metavar="N",
                        help="the vehicle: quadsitl up --instance N")  # fmt: skip
    parser.add_argument("--url", default=None, help="MAVLink URL (default: the vehicle's API port, udpin)")
    return parser


def main(argv: list[str] | None = None, prog: str = "quadsitl fail") -> int:
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    if not 0 <= args.instance <= 255:
        parser.error(f"--instance {args.instance}: 0 to 255")
    try:
        link = connect(args.url, args.vehicle_instance)
    except (LinkError, ValueError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    try:
        result = inject(link, Unit[args.unit], Type[args.type], args.instance, args.enable)
    except LinkError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    finally:
        link.close()
    return 0 if result == mavutil.mavlink.MAV_RESULT_ACCEPTED else 1


if __name__ == "__main__":
    sys.exit(main())
