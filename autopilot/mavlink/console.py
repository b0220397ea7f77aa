"""The vehicle's console: PX4's shell commands that mean something here, run on a line of text.

What QGC's MAVLink Console, MAVSDK's Shell and PX4's ``Tools/mavlink_shell.py`` type reaches
:meth:`Console.run` through :mod:`.shell` (SERIAL_CONTROL). Every command acts through the path a
ground station's message takes, with the same checks and the same refusals:

* ``param show [-c] [PATTERN]``, ``param set NAME VALUE``, ``param reset NAME``: the parameter store
  (PARAM_SET's checks; the new value echoed as PARAM_VALUE on every link);
* ``commander arm|disarm [-f]``, ``takeoff``, ``land``, ``mode NAME``, ``status``, ``check``: the
  vehicle's commands (COMPONENT_ARM_DISARM, NAV_TAKEOFF, NAV_LAND, DO_SET_MODE) as COMMAND_LONG
  runs them, their refusals printed;
* ``failure UNIT TYPE [-i N]``: MAV_CMD_INJECT_FAILURE through the same command path (PX4's
  ``failure`` command; ``SYS_FAILURE_EN`` 0 refuses it);
* ``listener TOPIC``: the latest value of a flight-log topic (``vehicle_status``,
  ``vehicle_local_position``, ``battery_status``... as the log would hold it now);
* ``ver all|git|hw``, ``top``, ``help``.

No command touches a file or the host: there is no way from here to a shell of the machine.
Pure: the vehicle comes in as a :class:`ConsoleContext`.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from fnmatch import fnmatchcase

from quadcommon.build_info import BuildInfo
from quadcommon.failures import ALL_INSTANCES, Type, Unit

from ..commander.modes import FlightMode
from ..params.store import INT32, ParameterStore
from .codec import mavlink as m
from .validation import FORCE_MAGIC

NAN = math.nan
# PX4's ``commander mode`` names -> DO_SET_MODE (main, sub).
MODES = {
    "manual": FlightMode.MANUAL.value,
    "acro": FlightMode.ACRO.value,
    "stabilized": FlightMode.STABILIZED.value,
    "altctl": FlightMode.ALTCTL.value,
    "posctl": FlightMode.POSCTL.value,
    "position": FlightMode.POSCTL.value,
    "offboard": FlightMode.OFFBOARD.value,
    "auto:takeoff": FlightMode.AUTO_TAKEOFF.value,
    "auto:loiter": FlightMode.AUTO_LOITER.value,
    "auto:mission": FlightMode.AUTO_MISSION.value,
    "auto:rtl": FlightMode.AUTO_RTL.value,
    "auto:land": FlightMode.AUTO_LAND.value,
}
_RESULTS = {value: name[len("MAV_RESULT_") :] for name, value in vars(m).items()
            if name.startswith("MAV_RESULT_") and name != "MAV_RESULT_ENUM_END"}  # fmt: skip


@dataclass(frozen=True)
class ConsoleContext:
    """What the console reaches of the vehicle.

    ``command(command, params)``: a MAV_CMD through the vehicle's command path, ``(MAV_RESULT,
    reason)``; ``set_param(name, value)``: a parameter set as PARAM_SET does it, None or why not;
    ``topic(name)``: a flight-log topic now, ``(field names, values)`` or None; ``info()``: the
    autopilot's counters (``quadsitl/<N>/autopilot/info``); ``commander`` and ``sim_time()`` for
    ``commander status``."""

    params: ParameterStore
    set_param: Callable[[str, float], str | None]
    command: Callable[[int, tuple[float, ...]], tuple[int, str]]
    topic: Callable[[str], tuple[list[str], tuple] | None]
    topic_names: tuple[str, ...]
    info: Callable[[], dict]
    commander: object
    sim_time: Callable[[], float]
    build: BuildInfo


class Console:
    """PX4's shell commands on a line of text (module docstring): :meth:`run` gives a line's output, every
    command acting through the vehicle's own paths (:class:`ConsoleContext`)."""

    def __init__(self, context: ConsoleContext) -> None:
        self.vehicle = context
        self.commands: dict[str, tuple[Callable[[list[str]], str], str]] = {
            "help": (self._help, "this list"),
            "param": (self._param, "show [-c] [PATTERN] | set NAME VALUE | reset NAME"),
            "commander": (self._commander, "arm [-f] | disarm [-f] | takeoff | land | mode NAME | status"
                                           " | check"),
            "failure": (self._failure, "UNIT TYPE [-i INSTANCE]: inject a failure (SYS_FAILURE_EN 1)"),
            "listener": (self._listener, "TOPIC: the latest value of a flight-log topic"),
            "ver": (self._ver, "all | git | hw: what this vehicle runs"),
            "top": (self._top, "the autopilot's counters, once"),
        }

    def run(self, line: str) -> str:
        """The output of one command line (empty for an empty line or a comment)."""
        words = line.split()
        if not words or words[0].startswith("#"):
            return ""
        entry = self.commands.get(words[0])
        if entry is None:
            return f"nsh: {words[0]}: command not found\n"
        return entry[0](words[1:])

    # -- help, ver, top -------------------------------------------------------------------------
    def _help(self, args: list[str]) -> str:
        width = max(len(name) for name in self.commands)
        lines = ["Builtin Apps:"]
        lines += [f"  {name:<{width}}  {usage}" for name, (_, usage) in self.commands.items()]
        return "\n".join(lines) + "\n"

    def _ver(self, args: list[str]) -> str:
        build = self.vehicle.build
        hw = "HW arch: quadsitl SITL (PX4's SITL interface)"
        git = f"quadsitl git-hash: {build.commit_text}"
        if args[:1] == ["hw"]:
            return hw + "\n"
        if args[:1] == ["git"]:
            return git + "\n"
        if args[:1] != ["all"]:
            return "usage: ver all | git | hw\n"
        release = build.flight_sw_version
        python = ".".join(str(v) for v in sys.version_info[:3])
        return "\n".join((hw, git, f"quadsitl version: {build.version or 'unknown'} ({release:#010x})",
                          f"OS: Linux, Python {python}", "Toolchain: CPython")) + "\n"  # fmt: skip

    def _top(self, args: list[str]) -> str:
        info = self.vehicle.info()
        armed = "armed" if info["armed"] else "disarmed"
        lines = [f"simulation time {info['sim_time_s']:.3f} s, controller {info['controller']}, "
                 f"{info['control_hz']:g} Hz, {armed}, mode {info['mode']}"]
        for key, label in (("received", "messages not handled"), ("refused", "refusals"),
                           ("dropped", "datagrams dropped"), ("faults", "internal errors")):  # fmt: skip
            counts = info.get(key) or {}
            lines.append(f"{label}: " + ("; ".join(f"{k}: {v}" for k, v in sorted(counts.items())) or "none"))
        return "\n".join(lines) + "\n"  # fmt: skip

    # -- param ----------------------------------------------------------------------------------
    def _param(self, args: list[str]) -> str:
        if args[:1] == ["show"]:
            return self._param_show(args[1:])
        if args[:1] == ["set"] and len(args) == 3:
            return self._param_set(args[1], args[2])
        if args[:1] == ["reset"] and len(args) == 2:
            spec = self.vehicle.params.specs.get(args[1])
            if spec is None:
                return f"ERROR [param] parameter {args[1]} not found\n"
            return self._param_set(args[1], repr(spec.default))
        return "usage: param show [-c] [PATTERN] | param set NAME VALUE | param reset NAME\n"

    def _param_show(self, args: list[str]) -> str:
        changed_only = "-c" in args
        patterns = [a for a in args if a != "-c"] or ["*"]
        store = self.vehicle.params
        lines = ["Symbols: x = used, + = saved, * = unsaved"]
        shown = 0
        for index, name in enumerate(store.names()):
            spec, value = store.specs[name], store[name]
            changed = value != spec.default
            if (changed_only and not changed) or not any(fnmatchcase(name, p) for p in patterns):
                continue
            lines.append(f"x {'*' if changed else ' '} {name} [{index},{index}] : {_value(spec.kind, value)}")
            shown += 1
        lines.append(f"\n {shown}/{len(store)} parameters shown.")
        return "\n".join(lines) + "\n"

    def _param_set(self, name: str, text: str) -> str:
        store = self.vehicle.params
        spec = store.specs.get(name)
        if spec is None:
            return f"ERROR [param] parameter {name} not found\n"
        try:
            value = float(int(text, 0)) if spec.kind == INT32 else float(text)
        except ValueError:
            kind = "an integer" if spec.kind == INT32 else "a number"
            return f"ERROR [param] {name}: {text!r} is not {kind}\n"
        before = store[name]
        problem = self.vehicle.set_param(name, value)
        if problem:
            return f"ERROR [param] {problem}\n"
        return f"{name}: curr: {_value(spec.kind, before)} -> new: {_value(spec.kind, store[name])}\n"

    # -- commander, failure ---------------------------------------------------------------------
    def _commander(self, args: list[str]) -> str:
        what = args[0] if args else ""
        force = FORCE_MAGIC if "-f" in args[1:] else 0.0
        if what in ("arm", "disarm"):
            return self._command(what, m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if what == "arm" else 0.0, force)
        if what == "takeoff":
            return self._command(what, m.MAV_CMD_NAV_TAKEOFF, *(NAN,) * 7)
        if what == "land":
            return self._command(what, m.MAV_CMD_NAV_LAND, *(NAN,) * 7)
        if what == "mode" and len(args) == 2:
            mode = MODES.get(args[1])
            if mode is None:
                return f"commander mode: unknown mode {args[1]!r} (one of: {', '.join(MODES)})\n"
            return self._command(f"mode {args[1]}", m.MAV_CMD_DO_SET_MODE,
                                 m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, *mode)  # fmt: skip
        if what == "status":
            return self._status()
        if what == "check":
            problem = self.vehicle.commander.arm_problem(self.vehicle.sim_time())
            return f"Preflight check: {'FAILED: ' + problem if problem else 'OK'}\n"
        return "usage: commander arm [-f] | disarm [-f] | takeoff | land | mode NAME | status | check\n"

    def _command(self, what: str, command: int, *params: float, module: str = "commander") -> str:
        """Run ``command`` and say how it went, as PX4's modules log: ``INFO  [commander] ...``."""
        full = (*params, *(0.0,) * (7 - len(params)))
        result, reason = self.vehicle.command(command, full)
        if result == m.MAV_RESULT_ACCEPTED:
            return f"INFO  [{module}] {what}: accepted\n"
        return f"WARN  [{module}] {what}: {_RESULTS.get(result, result)}{': ' + reason if reason else ''}\n"

    def _status(self) -> str:
        c = self.vehicle.commander
        problem = c.arm_problem(self.vehicle.sim_time()) if not c.armed else None
        lines = [f"armed: {'yes' if c.armed else 'no'}", f"mode: {c.mode.px4_name}",
                 f"landed state: {c.landed_state.name}",
                 f"home: {'set' if c.home is not None else 'not set'}",
                 f"preflight: {'armed' if c.armed else problem or 'ready to arm'}"]  # fmt: skip
        return "\n".join(lines) + "\n"

    def _failure(self, args: list[str]) -> str:
        usage = (f"usage: failure UNIT TYPE [-i INSTANCE]\n  UNIT: {' '.join(u.name for u in Unit)}\n"
                 f"  TYPE: {' '.join(t.name for t in Type)}\n")  # fmt: skip
        instance = ALL_INSTANCES
        if len(args) == 4 and args[2] == "-i":
            try:
                instance = int(args[3])
            except ValueError:
                return usage
            args = args[:2]
        if len(args) != 2 or args[0] not in Unit.__members__ or args[1] not in Type.__members__:
            return usage
        unit, kind = Unit[args[0]], Type[args[1]]
        return self._command(f"{unit.name} {kind.name}", m.MAV_CMD_INJECT_FAILURE, float(unit), float(kind),
                             float(instance), module="failure")  # fmt: skip

    # -- listener -------------------------------------------------------------------------------
    def _listener(self, args: list[str]) -> str:
        names = self.vehicle.topic_names
        if not args or args[0] not in names:
            return f"usage: listener TOPIC\n  TOPIC: {' '.join(names)}\n"
        sample = self.vehicle.topic(args[0])
        if sample is None:
            return f"never published: {args[0]} (no data for it now)\n"
        fields, values = sample
        lines = [f"TOPIC: {args[0]}", f" {args[0]}"]
        for name, value in zip(fields, values, strict=False):
            lines.append(f"    {name}: {_field(value)}")
        return "\n".join(lines) + "\n"


def _value(kind: str, value: float) -> str:
    """A parameter's value as PX4's ``param show`` prints it."""
    return f"{int(value)}" if kind == INT32 else f"{value:.4f}"


def _field(value) -> str:
    """A topic field as PX4's ``listener`` prints it."""
    if isinstance(value, bool):
        return "True" if value else "False"
    if isinstance(value, float):
        return f"{value:.5f}" if math.isfinite(value) else ("nan" if math.isnan(value) else str(value))
    if isinstance(value, bytes):
        return repr(value)
    return str(value)
