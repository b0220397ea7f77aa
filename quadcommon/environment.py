"""Every environment variable quadsitl reads, in one place (the docs' table is generated from
:data:`VARIABLES`). Modules read them through the functions here, never through ``os.environ``.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from pathlib import Path

PURE_PYTHON = "QUADSITL_PURE_PYTHON"
CONFIG_DIR = "QUADSITL_CONFIG_DIR"
LOCKSTEP_SPIN = "QUADSITL_LOCKSTEP_SPIN_S"
KERNEL_CACHE = "QUADSITL_KERNEL_CACHE"

VARIABLES: dict[str, str] = {
    PURE_PYTHON: "`1`: run every equation as plain Python, numba unused (the reference path; slower). "
    "Default: compiled with numba.",
    CONFIG_DIR: "Your configuration directories, joined by `:`, looked up before the shipped files "
    "(vehicles, controllers, scenarios, gusts, sensors, campaigns, and your own control laws in `laws/`).",
    LOCKSTEP_SPIN: "Overrides `[lockstep] spin_s` of `sitl.toml` for every process started with it: `0` "
    "turns the lockstep's busy-wait off where cores are scarce (a test suite, several vehicles).",
    KERNEL_CACHE: "Where the compiled kernels' entry modules and numba's cache of them live. Default: "
    "`$XDG_CACHE_HOME/quadsitl/kernels` (`~/.cache/quadsitl/kernels`).",
}


def pure_python(environ: Mapping[str, str] | None = None) -> bool:
    """True when the equations run as plain Python (``QUADSITL_PURE_PYTHON=1``)."""
    environ = os.environ if environ is None else environ
    return environ.get(PURE_PYTHON, "") == "1"


def kernel_cache_dir(environ: Mapping[str, str] | None = None) -> Path:
    """The directory of the compiled kernels' entry modules (created; a temporary one when the
    user's cache directory cannot be written)."""
    environ = os.environ if environ is None else environ
    if environ.get(KERNEL_CACHE):
        path = Path(environ[KERNEL_CACHE]).expanduser()
    else:
        base = Path(environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
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
