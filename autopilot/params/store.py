"""Parameters: named, typed, range-checked values backed by configuration.

Names follow PX4 where PX4 has the same meaning (``MIS_TAKEOFF_ALT``, ``COM_OF_LOSS_T``, ...), so
existing scripts and MAVSDK work unchanged. Pure: the MAVLink parameter protocol and files live
in the shells around it. A set value is validated against the declared type, range, refused
values and read-only flag, and refused (old value kept) otherwise, with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

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
    read_only: str = ""  # non-empty: why a set is refused (the value is still reported)
    refused: Mapping[float, str] = field(default_factory=dict)  # in-range values refused, and why

    def check(self, value: float) -> str | None:
        """None if ``value`` is acceptable, else the reason it is not."""
        if self.read_only:
            return f"{self.name} is read-only: {self.read_only}"
        if not isinstance(value, int | float) or isinstance(value, bool):
            return f"{self.name}: value {value!r} is not a number"
        if not math.isfinite(value):
            return f"{self.name}: value {value!r} is not finite"
        if self.kind == INT32 and value != int(value):
            return f"{self.name}: {value!r} is not an integer"
        # Values that came through a float32 (MAVLink REAL32) may sit a rounding step outside a
        # decimal bound (float32(0.3) > 0.3): allow that much, relative to the bound.
        slack = 0.0 if self.kind == INT32 else 1e-6
        if not self.lo - slack * max(1.0, abs(self.lo)) <= value <= self.hi + slack * max(1.0, abs(self.hi)):
            return f"{self.name}: {value:g} out of range {self.range_text()}"
        why = self.refused.get(float(value))
        if why:
            return f"{self.name}: {value:g} refused: {why}"
        return None

    def range_text(self) -> str:
        """The allowed range as text, ``[lo, hi] unit``, for refusals and listings."""
        unit = f" {self.unit}" if self.unit else ""
        return f"[{self.lo:g}, {self.hi:g}]{unit}"


class ParameterStore:
    """Current values of a fixed set of parameters, with change listeners.

    The order of declaration is the MAVLink ``param_index`` order.
    """

    def __init__(self, specs: Iterable[ParamSpec]) -> None:
        self.specs: dict[str, ParamSpec] = {}
        for spec in specs:
            if len(spec.name) > 16:
                raise ValueError(f"parameter name {spec.name!r} longer than 16 characters")
            if spec.name in self.specs:
                raise ValueError(f"parameter {spec.name!r} declared twice")
            self.specs[spec.name] = spec
        self.values: dict[str, float] = {n: float(s.default) for n, s in self.specs.items()}
        self._index = {name: i for i, name in enumerate(self.specs)}
        self._listeners: list[Callable[[str, float], None]] = []

    def __contains__(self, name: str) -> bool:
        return name in self.specs

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def get(self, name: str, default: float) -> float:
        """The value of ``name``, or ``default`` when the store has no such parameter."""
        return self.values.get(name, default)

    def __len__(self) -> int:
        return len(self.specs)

    def names(self) -> list[str]:
        """Every parameter's name in declaration order (the MAVLink ``param_index`` order)."""
        return list(self.specs)

    def index(self, name: str) -> int:
        """The MAVLink ``param_index`` of ``name`` (KeyError if unknown)."""
        return self._index[name]

    def on_change(self, listener: Callable[[str, float], None]) -> None:
        """``listener(name, value)`` after every accepted change (not when the value is unchanged)."""
        self._listeners.append(listener)

    def validate(self, name: str, value: float) -> str | None:
        """Why ``name = value`` would be refused, or None if it would be accepted."""
        spec = self.specs.get(name)
        if spec is None:
            return f"unknown parameter {name!r}"
        return spec.check(value)

    def set(self, name: str, value: float) -> str | None:
        """Set ``name``; returns None on success, else why it was refused (value unchanged)."""
        problem = self.validate(name, value)
        if problem:
            return problem
        spec = self.specs[name]
        value = float(int(value)) if spec.kind == INT32 else float(value)
        if value == self.values[name]:
            return None  # no change: listeners (retunes, autosave) have nothing to do
        self.values[name] = value
        for listener in self._listeners:
            listener(name, value)
        return None

    def set_many(self, values: Mapping[str, float]) -> str | None:
        """Set several values, all or none: the first problem is returned and nothing changes."""
        for name, value in values.items():
            problem = self.validate(name, value)
            if problem:
                return problem
        for name, value in values.items():
            self.set(name, value)
        return None

    def writable(self) -> list[str]:
        """The names of the parameters a ground station may set (all but the read-only ones)."""
        return [n for n, s in self.specs.items() if not s.read_only]
