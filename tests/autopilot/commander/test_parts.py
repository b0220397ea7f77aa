"""The commander is one state in several modules (autopilot/commander/: arming, mode requests,
reactions, plans, Orbit and follow-me, the mission): every action the table names is carried out by
exactly one part, no part hides another's method, and the phase and the mode change only where the
table is applied (Commander._fire; _set_mode for the mode)."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

from autopilot.commander import commander as commander_module
from autopilot.commander.commander import TABLE, Commander

pytestmark = pytest.mark.timeout(30)

PACKAGE = Path(commander_module.__file__).parent


def test_every_action_of_the_table_is_carried_out_by_one_part():
    actions = {action for *_, action in TABLE if action is not None}
    for action in sorted(actions):
        owners = [part.__name__ for part in Commander.__mro__ if f"_act_{action}" in vars(part)]
        assert len(owners) == 1, (action, owners)


def test_no_part_hides_a_method_of_another():
    parts = [part for part in Commander.__mro__ if part is not object]
    seen: dict[str, str] = {}
    for part in parts:
        for name, member in vars(part).items():
            if inspect.isfunction(member) or isinstance(member, property):
                assert name not in seen, f"{name} in {part.__name__} and {seen[name]}"
                seen[name] = part.__name__


def _assignments(path: Path) -> list[tuple[str, str]]:
    """(function, attribute) of every assignment to ``self.phase`` or ``self.mode`` in ``path``."""
    found = []
    for function in ast.walk(ast.parse(path.read_text())):
        if not isinstance(function, ast.FunctionDef):
            continue
        for node in ast.walk(function):
            targets = node.targets if isinstance(node, ast.Assign) else []
            if isinstance(node, ast.AugAssign | ast.AnnAssign):
                targets = [node.target]
            for target in targets:
                if (isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name)
                        and target.value.id == "self" and target.attr in ("phase", "mode")):  # fmt: skip
                    found.append((f"{path.name}:{function.name}", target.attr))
    return found


def test_the_phase_and_the_mode_change_only_where_the_table_is_applied():
    changes = sorted(change for path in sorted(PACKAGE.glob("*.py")) for change in _assignments(path))
    assert changes == [
        ("commander.py:__init__", "mode"),
        ("commander.py:__init__", "phase"),
        ("commander.py:_fire", "phase"),
        ("commander.py:_set_mode", "mode"),
    ]


def test_the_check_sees_a_phase_changed_elsewhere(tmp_path):
    rogue = tmp_path / "rogue.py"
    rogue.write_text("class Rogue:\n    def land_now(self):\n        self.phase = None\n")
    assert _assignments(rogue) == [("rogue.py:land_now", "phase")]
