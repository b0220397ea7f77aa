"""Parameter files: ``params.toml`` with one ``NAME = value`` line per writable parameter.

Read at start (``python -m autopilot --params FILE``, ``quadsitl up --params FILE``) and on
``MAV_CMD_PREFLIGHT_STORAGE`` param1 = 0; written on param1 = 1 and after every accepted change
(PX4 saves parameters as they change). A file is validated with the same checks as a PARAM_SET
(known name, writable, type, range) and applied all or nothing; an error names the file, the key,
the value and the allowed range. A file that does not exist yet is not an error at start: the
defaults stand and the first save creates it.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from quadcommon.schema import ConfigError, load_toml

from .store import INT32, ParameterStore


def read_params_file(path: str | Path, store: ParameterStore) -> dict[str, float]:
    """The values of ``path``, each checked against ``store``'s specs; ConfigError if any is bad."""
    path = Path(path)
    data = load_toml(path).data  # "PATH: file not found" / "PATH: not valid TOML: ..."
    values: dict[str, float] = {}
    for key, value in data.items():
        spec = store.specs.get(key)
        if spec is None:
            raise ConfigError(
                f"{path}: key '{key}' = {value!r} is not a parameter of this autopilot "
                "(names are case-sensitive; controller gains exist only for the active cascade)"
            )
        if spec.read_only:
            raise ConfigError(f"{path}: key '{key}' = {value!r} cannot be set: {spec.read_only}")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{path}: key '{key}' = {value!r} must be a number")
        if spec.kind == INT32 and not isinstance(value, int):
            raise ConfigError(
                f"{path}: key '{key}' = {value!r} must be an integer; allowed: {spec.range_text()}"
            )
        problem = spec.check(value)
        if problem:
            raise ConfigError(
                f"{path}: key '{key}' = {value!r} is refused ({problem}); allowed: {spec.range_text()}"
            )
        values[key] = float(value)
    return values


def load_params_file(path: str | Path, store: ParameterStore) -> dict[str, float]:
    """Read and apply ``path`` (all or nothing); returns the values read."""
    values = read_params_file(path, store)
    problem = store.set_many(values)
    if problem:  # not reachable after read_params_file's checks; kept as a guard
        raise ConfigError(f"{path}: {problem}")
    return values


def format_value(value: float, kind: str) -> str:
    """TOML text of a parameter value: integers bare, floats with the shortest exact repr."""
    if kind == INT32:
        return str(int(value))
    if not math.isfinite(value):
        raise ValueError(f"cannot write non-finite value {value!r}")
    return repr(float(value))


def write_params_file(path: str | Path, store: ParameterStore, header: str = "") -> None:
    """Write every writable parameter to ``path`` atomically (temporary file, then rename)."""
    path = Path(path)
    lines = ["# quadsitl autopilot parameters: NAME = value (see autopilot/params/definitions.py)"]
    if header:
        lines.append(f"# {header}")
    for name in sorted(store.writable()):
        spec = store.specs[name]
        lines.append(f"{name} = {format_value(store[name], spec.kind)}  # {spec.range_text()}")
    text = "\n".join(lines) + "\n"
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)
