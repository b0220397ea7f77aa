"""Parameters: named, typed, range-checked values backed by configuration.

Names follow PX4 where PX4 has the same meaning (``MIS_TAKEOFF_ALT``, ``COM_OF_LOSS_T``, ...), so
existing scripts and MAVSDK work unchanged. Pure: the MAVLink parameter protocol and files live
in the shells around it. A set value is validated against the declared type and range and
refused (old value kept) otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

INT32 = "int32"
FLOAT = "float"


@dataclass(frozen=True)
class ParamSpec:
    name: str  # at most 16 characters (MAVLink param_id)
    default: float
    lo: float
    hi: float
    kind: str = FLOAT  # FLOAT or INT32
    unit: str = ""
    description: str = ""

    def check(self, value: float) -> str | None:
        """None if ``value`` is acceptable, else the reason it is not."""
        if not isinstance(value, int | float) or isinstance(value, bool):
            return f"{self.name}: value {value!r} is not a number"
        if not math.isfinite(value):
            return f"{self.name}: value {value!r} is not finite"
        if self.kind == INT32 and value != int(value):
            return f"{self.name}: {value!r} is not an integer"
        if not self.lo <= value <= self.hi:
            unit = f" {self.unit}" if self.unit else ""
            return f"{self.name}: {value:g} out of range [{self.lo:g}, {self.hi:g}]{unit}"
        return None


class ParameterStore:
    """Current values of a fixed set of parameters, with change listeners."""

    def __init__(self, specs: Iterable[ParamSpec]) -> None:
        self.specs: dict[str, ParamSpec] = {}
        for spec in specs:
            if len(spec.name) > 16:
                raise ValueError(f"parameter name {spec.name!r} longer than 16 characters")
            if spec.name in self.specs:
                raise ValueError(f"parameter {spec.name!r} declared twice")
            self.specs[spec.name] = spec
        self.values: dict[str, float] = {n: s.default for n, s in self.specs.items()}
        self._listeners: list[Callable[[str, float], None]] = []

    def __contains__(self, name: str) -> bool:
        return name in self.specs

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def names(self) -> list[str]:
        return list(self.specs)

    def index(self, name: str) -> int:
        return list(self.specs).index(name)

    def on_change(self, listener: Callable[[str, float], None]) -> None:
        self._listeners.append(listener)

    def set(self, name: str, value: float) -> str | None:
        """Set ``name``; returns None on success, else why it was refused (value unchanged)."""
        spec = self.specs.get(name)
        if spec is None:
            return f"unknown parameter {name!r}"
        problem = spec.check(value)
        if problem:
            return problem
        value = float(int(value)) if spec.kind == INT32 else float(value)
        self.values[name] = value
        for listener in self._listeners:
            listener(name, value)
        return None
