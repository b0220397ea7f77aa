"""Control laws by name: each law declares, in its own module, its name, its loop, its gains (the
config schema of its section in ``config/controllers/NAME.toml``) and its tunable parameters.

The cascade (:mod:`.cascade`), the controller config loader (:mod:`.config`) and the parameter
table (:mod:`autopilot.params.definitions`) look laws up here; none of them names a law.

Adding a law (README "Adding a control law"): write ``autopilot/control/laws/MY_LAW.py`` with a
class decorated ``@register(TRANSLATIONAL)`` or ``@register(ROTATIONAL)`` that provides

* ``NAME``: the value of ``law = "..."`` in a controller file;
* ``load_gains(section) -> gains`` (classmethod): read and validate its keys of the section (a
  :class:`quadcommon.schema.Section`: errors name file, key, value and range); the gains record is
  frozen and carries ``law`` (= NAME);
* ``parameters(gains) -> tuple[ParamSpec, ...]`` and ``gains_from_params(gains, params) -> gains``
  (classmethods): the parameters a ground station may tune in flight (defaults: the gains);
* ``__init__(gains, nominal)``, ``reset()``, ``retune(gains)`` (keep the integral action continuous)
  and the step: ``accelerations(e1, e1_dot, ref_acc, dt, integrate)`` for the translational loop,
  ``update(euler, euler_rates, ref, ref_rate, ref_acc, dt, integrate)`` for the rotational loop;

then add one line, its import, to ``autopilot/control/laws/__init__.py``.
"""

from __future__ import annotations

from collections.abc import Callable

TRANSLATIONAL, ROTATIONAL = "translational", "rotational"
_LAWS: dict[str, dict[str, type]] = {TRANSLATIONAL: {}, ROTATIONAL: {}}


def register(loop: str) -> Callable[[type], type]:
    """Class decorator: the law becomes available under ``cls.NAME`` for ``loop``."""
    if loop not in _LAWS:
        raise ValueError(f"loop must be {TRANSLATIONAL!r} or {ROTATIONAL!r}, got {loop!r}")

    def add(cls: type) -> type:
        name = cls.NAME  # type: ignore[attr-defined]
        if name in _LAWS[loop]:
            raise ValueError(f"two {loop} laws named {name!r}: {_LAWS[loop][name]} and {cls}")
        _LAWS[loop][name] = cls
        return cls

    return add


def names(loop: str) -> tuple[str, ...]:
    _load()
    return tuple(_LAWS[loop])


def law(loop: str, name: str) -> type:
    """The class of law ``name`` of ``loop`` (KeyError with the available names)."""
    _load()
    try:
        return _LAWS[loop][name]
    except KeyError:
        raise KeyError(f"no {loop} law {name!r}; available: {', '.join(_LAWS[loop])}") from None


def _load() -> None:
    from . import laws  # noqa: F401 - the registration lines
