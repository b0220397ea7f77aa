"""The control laws; importing a module registers its law: one line per law."""

from . import backstepping as backstepping
from . import integral_backstepping_attitude as integral_backstepping_attitude
from . import integral_first_step as integral_first_step
from . import integral_second_step as integral_second_step
from . import nlhinf as nlhinf
