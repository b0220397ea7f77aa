"""The ``--help`` layout of every command line (``quadsitl ...`` and the ground-station scripts)."""

from __future__ import annotations

import argparse


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """The description as written (the module docstrings are laid out by hand); an option's help
    gets "(default: X)" unless its text already says its default, or it has none to say (a flag,
    or None: such help says in words what happens without the option)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text.lower() or not action.option_strings:
            return text
        if not has_default_to_show(action):
            return text
        return f"{text} (default: %(default)s)" if text else "default: %(default)s"


def has_default_to_show(action: argparse.Action) -> bool:
    """Whether ``action``'s default is worth stating: not None, not a flag's False, not ""
    (0 is: ``--instance`` defaults to 0)."""
    default = action.default
    return not (default is None or default is False or default is argparse.SUPPRESS or default == "")
