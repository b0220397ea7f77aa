"""Controller configuration (``config/controllers/NAME.toml``): a cascade by name, validated.

A cascade is a translational law, a rotational law (each looked up by name in :mod:`.registry`,
each reading its own keys of its section), the tilt limit of the translational loop and the
command filter between the loops. Errors name file, key, value and the allowed range.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from quadcommon.config import config_path
from quadcommon.schema import ConfigError, Section, load_toml

from . import registry

PAPER_CONTROLLERS = ("intbs_nlhinf", "intbs", "bs_nlhinf")  # the paper's three cascades
# PX4's cascade (its default gains; autotuned on this vehicle: sitl/tune.py) and geometric control on
# SE(3), for comparison
BASELINES = ("px4_pid", "px4_pid_tuned", "se3")
CONTROLLER_NAMES = PAPER_CONTROLLERS + BASELINES


@dataclass(frozen=True)
class CommandFilter:
    """Second-order filter giving eta_d, eta_d', eta_d'' from the roll/pitch references (or, not
    enabled, the references passed through with zero rates: :mod:`.command_filter`)."""

    natural_frequency_rad_s: float
    damping: float
    enabled: bool = True


@dataclass(frozen=True)
class ControllerConfig:
    name: str
    description: str
    translational: Any  # the translational law's gains record (has .law)
    rotational: Any  # the rotational law's gains record (has .law)
    command_filter: CommandFilter
    tilt_max_rad: float = 0.7  # limit of phi_r, theta_r (translational loop, eq. 29)

    def with_gains(self, translational=None, rotational=None, **changes) -> ControllerConfig:
        """A copy with other gains records (``None`` keeps the loop's) and any other fields changed."""
        return replace(self, translational=translational or self.translational,
                       rotational=rotational or self.rotational, **changes)  # fmt: skip


def load_controller(name_or_path: str | Path = "intbs_nlhinf") -> ControllerConfig:
    """The controller file ``config/controllers/NAME.toml`` (a name or a path), validated: each loop's law by
    name with its gains, the tilt limit, the command filter; ConfigError naming file, key, value and range."""
    path = config_path("controllers", name_or_path)
    root = load_toml(path)
    name = root.string("name", Path(path).stem)
    description = root.string("description", "")

    sec = root.section("translational")
    law = _law(sec, registry.TRANSLATIONAL)
    tilt_max = sec.number("tilt_max_rad", 0.7, lo=0.05, hi=1.4, unit="rad")
    translational = law.load_gains(sec)
    sec.finish()

    sec = root.section("rotational")
    law = _law(sec, registry.ROTATIONAL)
    rotational = law.load_gains(sec)
    sec.finish()

    sec = root.section("command_filter", optional=True)
    command_filter = CommandFilter(
        natural_frequency_rad_s=sec.number("natural_frequency_rad_s", 60.0, lo=1.0, hi=1000.0, unit="rad/s"),
        damping=sec.number("damping", 1.0, lo=0.1, hi=5.0),
        enabled=sec.boolean("enabled", True),
    )
    sec.finish()
    root.finish()
    return ControllerConfig(name, description, translational, rotational, command_filter, tilt_max)


def _law(section: Section, loop: str) -> type:
    """The ``loop`` law named by ``section``'s key ``law``; ConfigError naming the file and key: an
    unknown name lists the known ones, a law in a file that did not import gives that file's error."""
    name = section.string("law")
    try:
        return registry.law(loop, name)
    except (KeyError, ConfigError) as error:
        key = section.key_name("law")
        raise ConfigError(f"{section.source}: key '{key}' = {name!r}: {error.args[0]}") from None
