"""Every environment variable quadsitl reads, in one place: :data:`VARIABLES` names and explains
each (the table in docs/configuration.md is :func:`markdown_table`'s output, checked by a test).
Modules read them through the functions here, never through ``os.environ``.

``python -m quadcommon.environment`` prints the table.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping, MutableMapping
from pathlib import Path

PURE_PYTHON = "QUADSITL_PURE_PYTHON"
CONFIG_DIR = "QUADSITL_CONFIG_DIR"
LOCKSTEP_SPIN = "QUADSITL_LOCKSTEP_SPIN_S"
KERNEL_CACHE = "QUADSITL_KERNEL_CACHE"
NUMBA_CACHE = "NUMBA_CACHE_DIR"
XDG_CACHE = "XDG_CACHE_HOME"
MAVLINK20 = "MAVLINK20"
MAVLINK_DIALECT = "MAVLINK_DIALECT"
# What pymavlink must find when it is first imported: MAVLink 2 and the common dialect, what the
# autopilot speaks (use_mavlink2).
PYMAVLINK_SETTINGS = {MAVLINK20: "1", MAVLINK_DIALECT: "common"}

VARIABLES: dict[str, str] = {
    PURE_PYTHON: "`1`: run every equation as plain Python, numba unused (the reference path; slower). "
    "Default: compiled with numba.",
    CONFIG_DIR: "Your configuration directories, joined by `:`, looked up before the shipped files "
    "(vehicles, controllers, scenarios, gusts, sensors, campaigns, and your own control laws in `laws/`).",
    LOCKSTEP_SPIN: "Overrides `[lockstep] spin_s` of `sitl.toml` for every process started with it: `0` "
    "turns the lockstep's busy-wait off where cores are scarce (a test suite, several vehicles).",
    KERNEL_CACHE: "Where the compiled kernels' entry modules and numba's cache of them live. Default: "
    "`$XDG_CACHE_HOME/quadsitl/kernels` (`~/.cache/quadsitl/kernels`).",
    NUMBA_CACHE: "numba's own: where numba keeps every compiled kernel when set (numba reads it; quadsitl "
    "reads it to tell whether a kernel is compiled already). Default: beside the entry modules.",
    XDG_CACHE: "The user's cache directory (the XDG convention), the default home of the kernel cache. "
    "Default: `~/.cache`.",
    MAVLINK20: "pymavlink's own: `1` selects MAVLink 2 when pymavlink is first imported. quadsitl's "
    "ground-station modules set it to `1` when it is unset (the autopilot speaks MAVLink 2).",
    MAVLINK_DIALECT: "pymavlink's own: the dialect its `mavutil` loads. quadsitl's ground-station modules "
    "set it to `common` when it is unset.",
}


def pure_python(environ: Mapping[str, str] | None = None) -> bool:
    """True when the equations run as plain Python (``QUADSITL_PURE_PYTHON=1``)."""
    environ = os.environ if environ is None else environ
    return environ.get(PURE_PYTHON, "") == "1"


def lockstep_spin(environ: Mapping[str, str] | None = None) -> str | None:
    """The text of ``QUADSITL_LOCKSTEP_SPIN_S`` (seconds), or None when unset or empty."""
    environ = os.environ if environ is None else environ
    return environ.get(LOCKSTEP_SPIN) or None


def config_dir_list(environ: Mapping[str, str] | None = None) -> list[str]:
    """The entries of ``QUADSITL_CONFIG_DIR`` (joined by ``os.pathsep``), empty ones left out."""
    environ = os.environ if environ is None else environ
    return [text for text in environ.get(CONFIG_DIR, "").split(os.pathsep) if text.strip()]


def numba_cache_dir(environ: Mapping[str, str] | None = None) -> Path | None:
    """numba's cache directory when ``NUMBA_CACHE_DIR`` sets one, else None."""
    environ = os.environ if environ is None else environ
    return Path(environ[NUMBA_CACHE]) if environ.get(NUMBA_CACHE) else None


def use_mavlink2(environ: MutableMapping[str, str] | None = None) -> None:
    """Have pymavlink speak MAVLink 2 with the common dialect, as the autopilot does: it reads
    ``MAVLINK20`` and ``MAVLINK_DIALECT`` once, when first imported, so call this before that
    import. A value the user set stays."""
    environ = os.environ if environ is None else environ
    for name, value in PYMAVLINK_SETTINGS.items():
        environ.setdefault(name, value)


def markdown_table() -> str:
    """The variables as a Markdown table (the one in docs/configuration.md)."""
    rows = ["| variable | meaning |", "|---|---|"]
    rows += [f"| `{name}` | {text} |" for name, text in VARIABLES.items()]
    return "\n".join(rows)


def kernel_cache_dir(environ: Mapping[str, str] | None = None) -> Path:
    """The directory of the compiled kernels' entry modules (created; a temporary one when the
    user's cache directory cannot be written)."""
    environ = os.environ if environ is None else environ
    if environ.get(KERNEL_CACHE):
        path = Path(environ[KERNEL_CACHE]).expanduser()
    else:
        base = Path(environ.get(XDG_CACHE) or Path.home() / ".cache")
        path = base / "quadsitl" / "kernels"
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".probe-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError:
        path = Path(tempfile.gettempdir()) / f"quadsitl-kernels-{os.getuid()}"
        path.mkdir(parents=True, exist_ok=True)
    return path


if __name__ == "__main__":
    print(markdown_table())
