"""A law's tunable gains declared once: each is a config key of the law's section, a parameter a
ground station may read and set, one range and one unit for both.

A law lists its gains as :class:`Tunable` rows; :func:`read` loads them from the controller file
(validated, errors naming file, key, value and range), :func:`parameter_specs` gives the
parameters (defaults: the loaded values) and :func:`from_params` maps parameter values back onto
the gains record (a frozen dataclass whose fields are the rows' keys). A law class that derives
from :class:`TunableLaw` and names its ``GAINS`` record and its ``TUNABLE`` rows gets the registry's
``load_gains`` / ``parameters`` / ``gains_from_params`` from them, without writing a range twice.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from quadcommon.schema import Section

from ..params.store import INT32, ParamSpec

AXES = ("R", "P", "Y")  # parameter suffixes of a per-axis gain: roll, pitch, yaw


@dataclass(frozen=True)
class Tunable:
    """One gain: ``key`` in the config section (and the gains record's field), ``param`` its
    parameter name (at most 16 characters; a per-axis gain's parameters are ``param_R``,
    ``param_P``, ``param_Y``), its range ``[lo, hi]`` and unit.

    ``per_axis``: the config value is a list of three (roll, pitch, yaw), the field a 3-tuple.
    ``switch``: a true/false setting, a TOML boolean and an INT32 parameter 0 or 1.
    """

    key: str
    param: str
    lo: float
    hi: float
    unit: str = ""
    description: str = ""
    per_axis: bool = False
    switch: bool = False

    def names(self) -> tuple[str, ...]:
        """The parameter names of this gain: ``param``, or ``param_R``, ``param_P``, ``param_Y`` for a
        per-axis gain."""
        return tuple(f"{self.param}_{a}" for a in AXES) if self.per_axis else (self.param,)


def read(section: Section, table: Sequence[Tunable]) -> dict[str, Any]:
    """The rows' values from ``section``, by key (every key required)."""
    values: dict[str, Any] = {}
    for row in table:
        if row.switch:
            values[row.key] = section.boolean(row.key)
        elif row.per_axis:
            values[row.key] = section.vector(row.key, lo=row.lo, hi=row.hi, unit=row.unit)
        else:
            values[row.key] = section.number(row.key, lo=row.lo, hi=row.hi, unit=row.unit)
    return values


def parameter_specs(gains: Any, table: Sequence[Tunable]) -> tuple[ParamSpec, ...]:
    """The rows as parameters, their defaults the values of ``gains``."""
    specs = []
    for row in table:
        value = getattr(gains, row.key)
        if row.switch:
            what = f"{row.description} (0/1)"
            specs.append(ParamSpec(row.param, int(value), 0, 1, kind=INT32, description=what))
        elif row.per_axis:
            for i, name in enumerate(row.names()):
                what = f"{row.description}, {('roll', 'pitch', 'yaw')[i]}"
                specs.append(ParamSpec(name, value[i], row.lo, row.hi, unit=row.unit, description=what))
        else:
            what = row.description
            specs.append(ParamSpec(row.param, value, row.lo, row.hi, unit=row.unit, description=what))
    return tuple(specs)


def from_params(gains: Any, table: Sequence[Tunable], params: Mapping[str, float]) -> Any:
    """``gains`` with each row that ``params`` holds replaced by its value."""
    changes: dict[str, Any] = {}
    for row in table:
        names = row.names()
        if not all(n in params for n in names):
            continue
        if row.switch:
            changes[row.key] = params[row.param] != 0.0
        elif row.per_axis:
            changes[row.key] = tuple(float(params[n]) for n in names)
        else:
            changes[row.key] = float(params[row.param])
    return replace(gains, **changes)


class TunableLaw:
    """The registry's ``load_gains``, ``parameters`` and ``gains_from_params`` of a law whose gains
    are ``TUNABLE`` rows of a ``GAINS`` record (``GAINS(law, **rows, **settings)``); ``settings``
    reads the law's other config keys (limits that are not parameters), none by default."""

    NAME: str
    STATE: tuple[str, ...] = ()  # no state unless the law says
    GAINS: type
    TUNABLE: tuple[Tunable, ...]

    @classmethod
    def settings(cls, section: Section) -> dict[str, Any]:
        return {}

    @classmethod
    def load_gains(cls, section: Section) -> Any:
        return cls.GAINS(cls.NAME, **read(section, cls.TUNABLE), **cls.settings(section))

    @classmethod
    def parameters(cls, gains: Any) -> tuple[ParamSpec, ...]:
        return parameter_specs(gains, cls.TUNABLE)

    @classmethod
    def gains_from_params(cls, gains: Any, params: Mapping[str, float]) -> Any:
        return from_params(gains, cls.TUNABLE, params)
