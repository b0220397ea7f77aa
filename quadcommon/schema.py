"""Validated reading of TOML configuration.

Every configuration file is read once, through a :class:`Section`, into frozen records. A wrong
key, type or out-of-range value raises :class:`ConfigError` whose message names the file, the
dotted key, the offending value and what is allowed, e.g.::

    config/vehicle/paper_quad.toml: key 'nominal.mass_kg' = -1.0 is out of range; allowed: > 0 (kg)

The reader also refuses keys it was not asked about (typos must not be silently ignored).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

_MISSING = object()


class ConfigError(ValueError):
    """A configuration file (or an uploaded profile) is invalid. The message says where and why."""


def load_toml(path: str | Path) -> Section:
    """Parse ``path`` as TOML and return its root :class:`Section`."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    return Section(data, source=str(path))


def _describe_range(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        left = "(" if lo_open else "["
        right = ")" if hi_open else "]"
        return f"{left}{lo:g}, {hi:g}{right}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return "any finite number"


class Section:
    """A TOML table being read: typed getters with ranges, and a check for unknown keys."""

    def __init__(self, data: dict[str, Any], source: str, prefix: str = "") -> None:
        if not isinstance(data, dict):
            raise ConfigError(f"{source}: key '{prefix.rstrip('.')}' must be a table")
        self.data = data
        self.source = source
        self.prefix = prefix
        self._used: set[str] = set()

    # -- helpers -------------------------------------------------------------------------------
    def key_name(self, key: str) -> str:
        """The key's full name in the file (the section's prefix and the key)."""
        return f"{self.prefix}{key}"

    def error(self, key: str, value: Any, allowed: str) -> ConfigError:
        """A ConfigError naming the file, the key, the value and what is allowed."""
        return ConfigError(
            f"{self.source}: key '{self.key_name(key)}' = {value!r} is invalid; allowed: {allowed}"
        )

    def has(self, key: str) -> bool:
        """Whether the section sets ``key``."""
        return key in self.data

    def _get(self, key: str, default: Any) -> Any:
        self._used.add(key)
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise ConfigError(f"{self.source}: missing key '{self.key_name(key)}'")
        return default

    # -- typed getters ---------------------------------------------------------------------------
    def number(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
        hi_open: bool = False,
        unit: str = "",
    ) -> float:
        """A finite float (TOML integers are accepted) within the stated range."""
        value = self._get(key, default)
        return self._check_number(key, value, lo, hi, lo_open, hi_open, unit)

    def _check_number(
        self,
        key: str,
        value: Any,
        lo: float | None,
        hi: float | None,
        lo_open: bool,
        hi_open: bool,
        unit: str,
    ) -> float:
        allowed = _describe_range(lo, hi, lo_open, hi_open) + (f" ({unit})" if unit else "")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, value, f"a number {allowed}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(key, value, f"a finite number {allowed}")
        too_low = lo is not None and (value <= lo if lo_open else value < lo)
        too_high = hi is not None and (value >= hi if hi_open else value > hi)
        if too_low or too_high:
            raise self.error(key, value, allowed)
        return value

    def integer(
        self, key: str, default: Any = _MISSING, *, lo: int | None = None, hi: int | None = None
    ) -> int:
        """An integer key, in ``[lo, hi]`` when given; ``default`` when absent (required without one)."""
        value = self._get(key, default)
        allowed = _describe_range(lo, hi, False, False)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, value, f"an integer {allowed}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.error(key, value, f"an integer {allowed}")
        return value

    def vector(
        self,
        key: str,
        length: int = 3,
        default: Any = _MISSING,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
        hi_open: bool = False,
        unit: str = "",
    ) -> tuple[float, ...]:
        """A list of ``length`` numbers, each within the stated range."""
        value = self._get(key, default)
        if not isinstance(value, list | tuple) or len(value) != length:
            raise self.error(key, value, f"a list of {length} numbers")
        return tuple(
            self._check_number(f"{key}[{i}]", item, lo, hi, lo_open, hi_open, unit)
            for i, item in enumerate(value)
        )

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        """A boolean key; ``default`` when absent (required without one)."""
        value = self._get(key, default)
        if not isinstance(value, bool):
            raise self.error(key, value, "true or false")
        return value

    def string(self, key: str, default: Any = _MISSING) -> str:
        """A string key; ``default`` when absent (required without one)."""
        value = self._get(key, default)
        if not isinstance(value, str):
            raise self.error(key, value, "a string")
        return value

    def choice(self, key: str, options: Iterable[str], default: Any = _MISSING) -> str:
        """A string key that must be one of ``options``; ``default`` when absent (required without one)."""
        options = tuple(options)
        value = self._get(key, default)
        if value not in options:
            raise self.error(key, value, "one of " + ", ".join(repr(o) for o in options))
        return value

    def section(self, key: str, optional: bool = False) -> Section:
        """A sub-table; an absent optional one reads as empty (so defaults apply)."""
        value = self._get(key, {} if optional else _MISSING)
        if not isinstance(value, dict):
            raise self.error(key, value, "a table")
        return Section(value, self.source, f"{self.key_name(key)}.")

    def sections(self, key: str) -> list[Section]:
        """An array of tables (``[[key]]``); absent reads as an empty list."""
        value = self._get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(key, value, "an array of tables")
        return [Section(v, self.source, f"{self.key_name(key)}[{i}].") for i, v in enumerate(value)]

    def finish(self) -> None:
        """Refuse any key that no getter asked for (a typo must not pass silently)."""
        unknown = sorted(set(self.data) - self._used)
        if unknown:
            names = ", ".join(f"'{self.key_name(k)}'" for k in unknown)
            known = ", ".join(sorted(self._used)) or "none"
            raise ConfigError(f"{self.source}: unknown key {names}; known keys here: {known}")
