"""Control laws by name: a law is one file and one registration, and then it flies everywhere: the
autopilot (``quadsitl up``), the in-process stack (``quadsitl paper`` / ``run``) and the batch
campaign engine (``quadsitl campaign``), compiled by numba from its own source.

A law's file holds its gains, its equations as a kernel (:mod:`quadcommon.kernel`) and a class
registered with ``@register(TRANSLATIONAL)`` or ``@register(ROTATIONAL)`` that gives:

* ``NAME``: the value of ``law = "..."`` in a controller file (``config/controllers/NAME.toml``);
* ``STATE``: the names of the law's state entries (integrals, filter states), ``()`` if none;
  the state is a float array the step reads and advances, zero at reset, logged under these names
  (a rotational law's body-rate integrals in PX4's normalised torque, named ``rate_int_x``,
  ``rate_int_y``, ``rate_int_z``, also as PX4's ``rate_ctrl_status``: docs/logs.md);
* ``load_gains(section) -> gains``: read and validate its keys of the controller file's
  ``[translational]`` / ``[rotational]`` section (a :class:`quadcommon.schema.Section`: errors name
  file, key, value and range); the gains record is frozen and carries ``law`` (= NAME);
* ``parameters(gains) -> tuple[ParamSpec, ...]`` and ``gains_from_params(gains, params) -> gains``:
  what a ground station may tune in flight (defaults: the gains);
* ``pack(gains, context) -> tuple[float, ...]``: the numbers the step reads (its gains array),
  given the vehicle's :class:`LawContext`;
* ``step``: the law itself, a ``@kernel`` function:

  - translational: ``step(g, x, position, velocity, euler, ref_position, ref_velocity,
    ref_acceleration, ref_yaw, dt, integrate) -> (U1, phi_r, theta_r, a_x, a_y, a_z,
    thrust_limited, tilt_limited)``: thrust (N), the roll/pitch references (rad) the attitude law
    will track, the commanded accelerations (m/s^2, for logs) and two flags (1.0 when a limit acted);
  - rotational: ``step(g, x, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt,
    integrate) -> (tau_x, tau_y, tau_z)``: the body torque (N m, body front-left-up);

  ``g`` is the gains array, ``x`` the state array (advanced by ``dt`` only when ``integrate``),
  vectors are 3-tuples in the paper's frames (world x-forward/y-left/z-up, ZYX Euler angles);
* optionally ``retune(old_gains, new_gains, context, state, euler, euler_rates) -> list[float]``:
  the state after an in-flight change of gains (keep the integral action continuous); by default
  the state is kept.

Where laws are found, by name: the built-in ones (every module of ``autopilot/control/laws/``);
the ``laws/`` directory of each configuration directory (``--config-dir``,
``QUADSITL_CONFIG_DIR``), imported as ``quadsitl_laws.<file name>``; installed packages that
declare an entry point in the group ``quadsitl.laws`` (the module is imported, its ``@register``
lines run). A law file that does not import (a syntax error, an exception) takes only its own laws
with it: it is reported once (:class:`LawFileWarning`, naming the file, line and error), the
other laws load, and asking for a law of that file gives the file's error. A law that breaks the
contract is refused with the reason when it registers or when a controller loads it
(:func:`check`); one that produces a non-finite output in flight trips the autopilot's failsafe
(:class:`ControllerFailure`, named by :func:`non_finite_output`).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import math
import pkgutil
import re
import sys
import traceback
import types
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from quadcommon.config import config_dirs
from quadcommon.kernel import is_kernel
from quadcommon.schema import ConfigError

TRANSLATIONAL, ROTATIONAL = "translational", "rotational"
USER_PACKAGE = "quadsitl_laws"  # a configuration directory's laws/FILE.py imports as quadsitl_laws.FILE
ENTRY_POINTS = "quadsitl.laws"

STEP_PARAMETERS = {
    TRANSLATIONAL: ("g", "x", "position", "velocity", "euler", "ref_position", "ref_velocity",
                    "ref_acceleration", "ref_yaw", "dt", "integrate"),
    ROTATIONAL: ("g", "x", "euler", "euler_rates", "body_rates", "eta_d", "eta_d_dot", "eta_d_ddot", "dt",
                 "integrate"),
}  # fmt: skip
STEP_OUTPUTS = {TRANSLATIONAL: 8, ROTATIONAL: 3}

_LAWS: dict[str, dict[str, type]] = {TRANSLATIONAL: {}, ROTATIONAL: {}}
_loaded = False
_BROKEN: dict[str, BrokenLawFile] = {}  # by module name: the law files that did not import


class LawError(ValueError):
    """A law that breaks the contract (named, with the reason)."""


class ControllerFailure(RuntimeError):
    """A law produced a non-finite output, or raised, in flight (the autopilot's failsafe acts)."""


def non_finite_output(controller: str) -> str:
    """How a controller whose applied U1 or torque is NaN or inf is named, by every runner that
    catches it (the cascade's check: the autopilot's flight termination, the in-process runs, the
    campaigns' failure reason)."""
    return f"controller {controller}: non-finite output"


class LawFileWarning(UserWarning):
    """A law file that did not import: its laws are unavailable, the other laws load."""


@dataclass(frozen=True)
class BrokenLawFile:
    """A law file (or an entry point's module) that did not import."""

    where: str  # the file (its line when known), or the entry point's module
    error: str  # the exception, "Type: message"
    names: tuple[str, ...]  # the law names its text gives (NAME = "..."), and the file's own name
    stamp: float  # the file's modification time: an edited file is imported again

    def message(self) -> str:
        """How the file's failure is reported: ``control law file WHERE: Type: message``."""
        return f"control law file {self.where}: {self.error}"


@dataclass(frozen=True)
class LawContext:
    """What a law's ``pack`` may use besides its gains: the nominal vehicle the controllers are
    designed on, the actuators' limits, the cascade's tilt limit and control period."""

    mass_kg: float
    gravity_m_s2: float
    inertia_kg_m2: tuple[float, float, float]  # nominal Ixx, Iyy, Izz
    arm_length_m: float
    thrust_max_n: float
    torque_max_n_m: tuple[float, float, float]
    tilt_max_rad: float
    dt_s: float


def register(loop: str) -> Callable[[type], type]:
    """Class decorator: the law becomes available under ``cls.NAME`` for ``loop``, once it passes
    the contract's static checks (LawError otherwise)."""
    if loop not in _LAWS:
        raise ValueError(f"loop must be {TRANSLATIONAL!r} or {ROTATIONAL!r}, got {loop!r}")

    def add(cls: type) -> type:
        _check_class(loop, cls)
        name = cls.NAME  # type: ignore[attr-defined]
        if name in _LAWS[loop]:
            raise LawError(f"two {loop} laws named {name!r}: {_where(_LAWS[loop][name])} and {_where(cls)}")
        _LAWS[loop][name] = cls
        return cls

    return add


def names(loop: str) -> tuple[str, ...]:
    """The names of the registered laws of ``loop`` (:data:`TRANSLATIONAL` or :data:`ROTATIONAL`): the
    built-in ones, those of the configuration directories' ``laws/`` and of entry points."""
    _load()
    return tuple(_LAWS[loop])


def law(loop: str, name: str) -> type:
    """The class of law ``name`` of ``loop``: KeyError with the available names (and the law files
    that did not load), or ConfigError with the error of the file that did not load and whose text
    gives that name."""
    _load()
    try:
        return _LAWS[loop][name]
    except KeyError:
        pass
    broken = [b for b in _BROKEN.values() if name in b.names]
    if broken:
        raise ConfigError(f"{loop} law {name!r} is in a file that did not load: {broken[0].message()}")
    not_loaded = "".join(f"; not loaded: {b.message()}" for b in _BROKEN.values())
    raise KeyError(f"no {loop} law {name!r}; available: {', '.join(_LAWS[loop])}{not_loaded}")


def check(loop: str, cls: type, gains: Any, context: LawContext) -> tuple[float, ...]:
    """The law's gains array, after one trial step at hover run as Python: a law whose ``pack`` or
    ``step`` raises, or returns the wrong number of values or non-finite ones, is refused here
    (ConfigError naming the law and its file), before anything flies."""
    where = f"{loop} law {cls.NAME!r} ({_where(cls)})"  # type: ignore[attr-defined]
    try:
        packed = tuple(float(v) for v in cls.pack(gains, context))  # type: ignore[attr-defined]
    except Exception as error:  # noqa: BLE001 - a user's law: any failure is reported, named
        raise ConfigError(f"{where}: pack() failed: {type(error).__name__}: {error}") from error
    if any(math.isnan(v) for v in packed):
        raise ConfigError(f"{where}: pack() gave NaN in its gains array {packed}")
    state = [0.0] * len(cls.STATE)  # type: ignore[attr-defined]
    g = context.gravity_m_s2
    zero = (0.0, 0.0, 0.0)
    if loop == TRANSLATIONAL:
        args = (list(packed), state, (0.0, 0.0, 1.0), zero, zero, (0.0, 0.0, 1.0), zero, zero, 0.0,
                context.dt_s, True)  # fmt: skip
    else:
        args = (list(packed), state, zero, zero, zero, zero, zero, zero, context.dt_s, True)
    try:
        out = tuple(cls.step(*args))  # type: ignore[attr-defined]
    except Exception as error:  # noqa: BLE001
        raise ConfigError(f"{where}: its step raised at hover: {type(error).__name__}: {error}") from error
    numbers = all(isinstance(v, int | float) and math.isfinite(v) for v in out)
    if len(out) != STEP_OUTPUTS[loop] or not numbers:
        raise ConfigError(f"{where}: its step must return {STEP_OUTPUTS[loop]} finite numbers, got {out}")
    if loop == TRANSLATIONAL and not 0.5 * context.mass_kg * g <= out[0] <= 2.0 * context.mass_kg * g:
        raise ConfigError(f"{where}: at hover on its reference it asks for {out[0]:.3g} N of thrust, not "
                          f"about m g = {context.mass_kg * g:.3g} N")
    return packed


class TranslationalOutput(NamedTuple):
    """A translational step's output, named."""

    thrust_n: float
    roll_ref_rad: float
    pitch_ref_rad: float
    acceleration_x_m_s2: float
    acceleration_y_m_s2: float
    acceleration_z_m_s2: float
    thrust_limited: float
    tilt_limited: float


class BoundLaw:
    """One law with its gains array and its state, stepped in Python: for a law's unit tests and
    for checking a law by hand (the cascade flies the same step, compiled)."""

    def __init__(self, loop: str, gains: Any, context: LawContext) -> None:
        self.loop, self.cls, self.gains, self.context = loop, law(loop, gains.law), gains, context
        self.g = list(check(loop, self.cls, gains, context))
        self.state = [0.0] * len(self.cls.STATE)
        self._last: tuple[Any, Any] = (None, None)

    def step(self, *args: Any) -> Any:
        """The law's step on (the arguments after ``g, x``); a translational law's output named."""
        out = self.cls.step(self.g, self.state, *args)
        if self.loop == TRANSLATIONAL:
            self._last = (args[2], None)
            return TranslationalOutput(*out)
        self._last = (args[0], args[1])
        return tuple(out)

    def retune(self, gains: Any) -> None:
        """Switch to ``gains`` as in flight: the law's ``retune`` (if it has one) maps the state at the last
        step's attitude, then the gains array is packed and checked again."""
        retune = getattr(self.cls, "retune", None)
        if retune is not None:
            self.state = list(retune(self.gains, gains, self.context, list(self.state), *self._last))
        self.gains, self.g = gains, list(check(self.loop, self.cls, gains, self.context))


# -------------------------------------------------------------------------------------------------
def _where(cls: type) -> str:
    module = sys.modules.get(cls.__module__)
    return str(getattr(module, "__file__", cls.__module__))


def _check_class(loop: str, cls: type) -> None:
    where = f"{loop} law {getattr(cls, '__name__', cls)} ({_where(cls)})"
    name = getattr(cls, "NAME", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise LawError(f"{where}: NAME must be a name (letters, digits, _), got {name!r}")
    state = getattr(cls, "STATE", None)
    if not isinstance(state, tuple) or not all(isinstance(s, str) for s in state):
        raise LawError(f"{where}: STATE must be a tuple of names (its state entries), got {state!r}")
    for member in ("load_gains", "parameters", "gains_from_params", "pack"):
        if not callable(getattr(cls, member, None)):
            raise LawError(f"{where}: no {member}() (see autopilot/control/registry.py)")
    step = getattr(cls, "step", None)
    if not is_kernel(step):
        raise LawError(f"{where}: step must be a @kernel function (quadcommon.kernel)")
    expected = STEP_PARAMETERS[loop]
    got = tuple(inspect.signature(step).parameters)
    if len(got) != len(expected):
        raise LawError(f"{where}: step{got} takes {len(got)} arguments; a {loop} law's step takes "
                       f"{len(expected)}: {', '.join(expected)}")  # fmt: skip


def _load() -> None:
    """Import every law: the built-in ones and the entry points once, the configuration
    directories' files whenever a new one appears (a directory can be added while running) or a
    file that did not import changes."""
    global _loaded
    if not _loaded:
        _loaded = True
        from . import laws

        for module in pkgutil.iter_modules(laws.__path__):
            importlib.import_module(f"{laws.__name__}.{module.name}")
        for entry in importlib.metadata.entry_points(group=ENTRY_POINTS):
            _import_user_law(entry.value, None)
    for directory in user_package().__path__:
        for path in sorted(Path(directory).glob("*.py")):
            module = f"{USER_PACKAGE}.{path.stem}"
            if path.stem.isidentifier() and not path.stem.startswith("_") and module not in sys.modules:
                broken = _BROKEN.get(module)
                if broken is None or broken.stamp != _stamp(path):
                    _import_user_law(module, path)


def _import_user_law(module: str, path: Path | None) -> None:
    """Import a user's law module; one that fails is recorded and reported, and the laws it had
    registered before failing are withdrawn (its module is gone: nothing could import them)."""
    try:
        importlib.import_module(module)
    except Exception as error:  # noqa: BLE001 - a user's file: any failure is reported, named
        for laws in _LAWS.values():
            for name in [n for n, cls in laws.items() if cls.__module__ == module]:
                del laws[name]
        line = _failing_line(error, path)
        where = str(path or module) + (f", line {line}" if line else "")
        names = _law_names(path) if path is not None else (module.rpartition(".")[2],)
        broken = BrokenLawFile(where, f"{type(error).__name__}: {_reason(error)}", names,
                               _stamp(path) if path is not None else 0.0)  # fmt: skip
        _BROKEN[module] = broken
        listed = ", ".join(repr(n) for n in names)
        warnings.warn_explicit(f"{broken.message()}; its laws ({listed}) are not loaded, the other laws are",
                               LawFileWarning, str(path or module), line or 0)  # fmt: skip
    else:
        _BROKEN.pop(module, None)


def _reason(error: Exception) -> str:
    if isinstance(error, SyntaxError):  # its str() repeats the file's name and line
        return str(error.msg)
    return str(error)


def _failing_line(error: Exception, path: Path | None) -> int | None:
    """The line of ``path`` where ``error`` arose (a syntax error's own, else the innermost frame
    of the traceback in that file)."""
    if path is None:
        return None
    path = path.resolve()
    if isinstance(error, SyntaxError) and error.filename and Path(error.filename).resolve() == path:
        return error.lineno
    frames = [f for f in traceback.extract_tb(error.__traceback__) if Path(f.filename).resolve() == path]
    return frames[-1].lineno if frames else None


def _law_names(path: Path) -> tuple[str, ...]:
    """The law names a file's text gives (``NAME = "..."``, read without importing it) and the
    file's own name: what a file that does not import would have defined."""
    try:
        text = path.read_text(errors="replace")
    except OSError:
        text = ""
    found = re.findall(r"""^\s*NAME\s*=\s*["']([A-Za-z_]\w*)["']""", text, flags=re.M)
    return tuple(dict.fromkeys([*found, path.stem]))


def _stamp(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:
        return 0.0


def user_package() -> types.ModuleType:
    """The package ``quadsitl_laws`` whose modules are the ``laws/`` files of the configuration
    directories (so a law file imports, and pickles, by name in any process that has the same
    configuration directories: campaign workers, the autopilot, compiled kernels' entries)."""
    package = sys.modules.get(USER_PACKAGE)
    if package is None:
        package = types.ModuleType(USER_PACKAGE, "Control laws of the configuration directories (laws/*.py).")
        package.__path__ = []
        sys.modules[USER_PACKAGE] = package
    package.__path__[:] = [str(d / "laws") for d in config_dirs() if (d / "laws").is_dir()]
    return package


user_package()  # at import: a pickled gains record of a user's law finds its module
