"""Inject a failure into a running vehicle, as PX4's ``failure`` command: ``quadsitl fail UNIT TYPE``.

``quadsitl fail UNIT [N] TYPE [EFFECTIVENESS]``: ``quadsitl fail gps off``, ``quadsitl fail motor 2
off`` (PX4's motor 2, the left rotor; the same as ``-i 2``), ``quadsitl fail motor 3 wrong 0.7``
(motor 3 at 70 % of its thrust; without a figure the vehicle's ``SIM_MOT_EFF``).

Sends ``MAV_CMD_INJECT_FAILURE`` (param1 the unit, param2 the type, param3 the instance, 0 = all:
what MAVSDK's Failure plugin sends; param4 a motor's effectiveness) on the vehicle's API link and
prints its COMMAND_ACK and the reason or announcement the vehicle gave (STATUSTEXT). The vehicle
refuses it (DENIED) while its parameter ``SYS_FAILURE_EN`` is 0, the default: ``--enable`` sets it to
1 first. What each unit and type does here, and which are unsupported: ``quadcommon/failures.py``,
docs/failures.md.

Exit status: 0 accepted, 1 refused (or no answer), 2 a bad argument.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import NamedTuple

from quadcommon.cli_help import HelpFormatter
from quadcommon.failures import Type, Unit, help_text

from .link import LinkError, connect, mavutil

RESULT_NAMES = {value: enum.name.removeprefix("MAV_RESULT_")
                for value, enum in mavutil.mavlink.enums["MAV_RESULT"].items()}  # fmt: skip


def inject(link, unit: Unit, failure_type: Type, instance: int = 0, enable: bool = False,
           out=print, effectiveness: float = math.nan) -> int:  # fmt: skip
    """On a connected :class:`~gcs_scripts.link.Link`: (``enable``: SYS_FAILURE_EN = 1, then) the
    command (``effectiveness``: param4, a motor's ``wrong``; NaN: the vehicle's SIM_MOT_EFF);
    prints the ACK and the vehicle's texts; returns the MAV_RESULT."""
    if enable:
        now = link.set_parameter("SYS_FAILURE_EN", 1, integer=True)
        out(f"SYS_FAILURE_EN = {now:g}")
    mark = link.texts_seen
    params = (int(unit), int(failure_type), instance, effectiveness)
    result = link.command_long(mavutil.mavlink.MAV_CMD_INJECT_FAILURE, params, check=False)
    texts = link.texts_since(mark)
    answer = RESULT_NAMES.get(result, "no COMMAND_ACK" if result < 0 else str(result))
    figure = "" if math.isnan(effectiveness) else f" {effectiveness:g}"
    out(f"failure {unit.name} {failure_type.name}{figure} (instance {instance}): {answer}"
        + (f": {texts[-1]}" if texts else ""))  # fmt: skip
    return result


class Request(NamedTuple):
    """What the words on the command line ask for."""

    unit: Unit
    failure_type: Type
    instance: int
    effectiveness: float  # NaN: not given


def parse_words(unit: str, words: list[str], instance: int) -> Request:
    """``UNIT [N] TYPE [EFFECTIVENESS]`` (``-i N`` as ``instance``); ValueError saying what is wrong."""
    if unit not in Unit.__members__:
        raise ValueError(f"unit {unit!r}: one of {', '.join(Unit.__members__)}")
    rest = list(words)
    if rest and rest[0].isdigit():
        if instance != 0 and int(rest[0]) != instance:
            raise ValueError(f"instance {rest[0]} and -i {instance}: give one")
        instance = int(rest.pop(0))
    if not rest or rest[0] not in Type.__members__:
        found = repr(rest[0]) if rest else "nothing"
        raise ValueError(f"type: {found}; one of {', '.join(Type.__members__)}")
    failure_type = Type[rest.pop(0)]
    effectiveness = math.nan
    if rest:
        if unit != Unit.motor.name or failure_type != Type.wrong:
            raise ValueError(f"{' '.join(rest)!r}: a figure only for 'motor N wrong EFFECTIVENESS'")
        try:
            effectiveness = float(rest.pop(0))
        except ValueError:
            raise ValueError("EFFECTIVENESS: a number in (0, 1], the thrust the motor keeps") from None
        if not 0.0 < effectiveness <= 1.0:
            raise ValueError(f"EFFECTIVENESS {effectiveness:g}: in (0, 1] (a motor off: 'off')")
        if rest:
            raise ValueError(f"unexpected {' '.join(rest)!r}")
    if not 0 <= instance <= 255:
        raise ValueError(f"instance {instance}: 0 to 255")
    return Request(Unit[unit], failure_type, instance, effectiveness)


def build_parser(prog: str = "quadsitl fail") -> argparse.ArgumentParser:
    """The ``quadsitl fail`` command line, with PX4's ``failure`` units and types."""
    parser = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=HelpFormatter,
                                     usage="%(prog)s [options] UNIT [N] TYPE [EFFECTIVENESS]",
                                     epilog="units and their types here:\n" + help_text())  # fmt: skip
    parser.add_argument("unit", choices=[u.name for u in Unit], metavar="UNIT",
                        help="the failing unit, PX4's names: " + ", ".join(u.name for u in Unit))  # fmt: skip
    parser.add_argument("words", nargs="+", metavar="[N] TYPE [EFFECTIVENESS]",
                        help="the instance N (optional, as -i N), the failure type "
                        f"({', '.join(t.name for t in Type)}; ok ends it), and for 'motor N wrong' the "
                        "effectiveness the motor keeps, in (0, 1] (default: the vehicle's "
                        "SIM_MOT_EFF)")  # fmt: skip
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
    """Inject the failure named on the command line (PX4's ``failure UNIT TYPE``) into a running
    vehicle by MAV_CMD_INJECT_FAILURE; 0 when accepted, 1 when the link fails or the vehicle refuses
    (a parser error for bad words)."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    try:
        request = parse_words(args.unit, args.words, args.instance)
    except ValueError as exc:
        parser.error(str(exc))
    try:
        link = connect(args.url, args.vehicle_instance)
    except (LinkError, ValueError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    try:
        result = inject(link, request.unit, request.failure_type, request.instance, args.enable,
                        effectiveness=request.effectiveness)  # fmt: skip
    except LinkError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    finally:
        link.close()
    return 0 if result == mavutil.mavlink.MAV_RESULT_ACCEPTED else 1


if __name__ == "__main__":
    sys.exit(main())
