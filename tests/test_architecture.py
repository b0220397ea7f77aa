"""The house's import rules (docs/architecture.md), read from the code's own import statements.

Every ``import`` counts, wherever it stands (module level, inside a function, behind
``TYPE_CHECKING``): the simulator and the autopilot never import each other, the ground stations
import neither, and ``quadcommon`` imports none of the packages that use it; ``sitl`` composes.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("autopilot", "simulator", "quadcommon", "gcs_scripts", "sitl")

# package -> the project packages it must never import
FORBIDDEN: dict[str, frozenset[str]] = {
    "autopilot": frozenset({"simulator", "gcs_scripts", "sitl"}),
    "simulator": frozenset({"autopilot", "gcs_scripts", "sitl"}),
    "gcs_scripts": frozenset({"autopilot", "simulator", "sitl"}),
    "quadcommon": frozenset({"autopilot", "simulator", "gcs_scripts", "sitl"}),
    "sitl": frozenset(),
}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path) -> list[tuple[int, str]]:
    """Every module ``path`` imports, as (line, absolute dotted name); relative imports resolved."""
    package = _module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join([*base, *(node.module.split(".") if node.module else [])])
            found.append((node.lineno, module))
            if node.module is None or node.level:  # `from . import x`: x may be a module
                found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return found


def package_files(package: str) -> list[Path]:
    return sorted(p for p in (ROOT / package).rglob("*.py") if "vendor" not in p.parts)


def forbidden_imports(package: str) -> list[str]:
    """``file:line -> module`` for every import from ``package`` into a package it must not import."""
    bad = []
    for path in package_files(package):
        for line, module in imported_modules(path):
            if module.split(".")[0] in FORBIDDEN[package]:
                bad.append(f"{path.relative_to(ROOT)}:{line} -> {module}")
    return bad


@pytest.mark.parametrize("package", PACKAGES)
def test_packages_import_only_what_they_may(package):
    assert forbidden_imports(package) == []


def test_the_rule_sees_a_ground_station_importing_the_autopilot(tmp_path, monkeypatch):
    """The check can fail: a gcs_scripts file importing the autopilot or the simulator is caught."""
    fake = tmp_path / "gcs_scripts" / "analysis"
    fake.mkdir(parents=True)
    (fake / "bad.py").write_text(
        "from autopilot.logger import topics\nimport simulator.core\nfrom ..link import mode_name\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert forbidden_imports("gcs_scripts") == [
        "gcs_scripts/analysis/bad.py:1 -> autopilot.logger",
        "gcs_scripts/analysis/bad.py:2 -> simulator.core",
    ]


# Inside the autopilot: its rooms from the ground up (docs/architecture.md, "Inside the autopilot").
# A module may import its own floor and the floors below, never one above; the longest prefix names
# a module's floor.
AUTOPILOT_FLOORS: tuple[tuple[str, ...], ...] = (
    # the records the rooms pass each other, the parameter store, the MAVLink vocabulary
    ("records", "params.store", "params.storage", "mavlink.codec", "mavlink.validation", "mavlink.commands"),
    ("control", "guidance", "battery", "estimation"),  # the laws, guidance, the estimators
    ("params",),  # the parameter table: gathers the laws' and the estimator's parameters
    ("mission",),  # missions: items, plans, the executor
    ("commander",),  # the commander: modes, transitions, failsafes, health
    ("mavlink", "mission.service"),  # the protocol handlers and services around the commander
    ("logger", "vehicle_files"),  # the flight log, the vehicle's files
    # AutopilotCore wires the rooms; beside it, what it is made from and the two steps it runs
    ("core", "setup", "estimator_switch", "flight_control"),
    ("app", "__main__", "bus_link", "log_files"),  # the process shell
)
# Imports that run back up, each with why it stands (a new one fails the suite): none.
KNOWN_UPWARD: set[tuple[str, str]] = set()


def autopilot_floor(module: str) -> tuple[int, str] | None:
    """(floor, the prefix that placed it) of an ``autopilot.`` module; None outside the autopilot."""
    parts = module.split(".")
    if parts[0] != "autopilot" or len(parts) < 2:
        return None
    rest, best = ".".join(parts[1:]), None
    for floor, prefixes in enumerate(AUTOPILOT_FLOORS):
        for prefix in prefixes:
            if (rest == prefix or rest.startswith(prefix + ".")) and (
                best is None or len(prefix) > len(best[1])
            ):
                best = (floor, prefix)
    return best


def _known_upward(name: str, module: str) -> bool:
    return any(
        name == file and (module == target or module.startswith(target + "."))
        for file, target in KNOWN_UPWARD
    )


def upward_imports() -> list[str]:
    """``file:line -> module`` for every autopilot import of a module on a higher floor."""
    bad = []
    for path in package_files("autopilot"):
        name = str(path.relative_to(ROOT))
        here = autopilot_floor(_module_name(path))
        if here is None:
            continue
        for line, module in imported_modules(path):
            there = autopilot_floor(module)
            if there and there[0] > here[0] and not _known_upward(name, module):
                bad.append(f"{name}:{line} -> {module}")
    return bad


def test_every_autopilot_module_has_a_floor():
    unplaced = [
        str(p.relative_to(ROOT))
        for p in package_files("autopilot")
        if autopilot_floor(_module_name(p)) is None
    ]
    assert unplaced == ["autopilot/__init__.py"]


def test_no_import_runs_back_up_inside_the_autopilot():
    assert upward_imports() == []


def test_the_floors_see_an_import_running_back_up():
    assert autopilot_floor("autopilot.control.cascade")[0] < autopilot_floor("autopilot.commander.modes")[0]
    assert (
        autopilot_floor("autopilot.mission.service")[0] > autopilot_floor("autopilot.commander.commander")[0]
    )
    assert autopilot_floor("autopilot.mavlink.codec")[0] == 0


# The core is wired by the process shell and composed by sitl/; no room reaches up to it.
CORE_IMPORTERS = frozenset(
    {"autopilot/app.py", "autopilot/__main__.py", "autopilot/bus_link.py", "autopilot/log_files.py"}
)


def core_importers() -> list[str]:
    """``file:line`` of every autopilot module that imports ``autopilot.core``, the shell's aside."""
    found = []
    for path in package_files("autopilot"):
        name = str(path.relative_to(ROOT))
        for line, module in imported_modules(path):
            core = module == "autopilot.core" or module.startswith("autopilot.core.")
            if core and name not in CORE_IMPORTERS and f"{name}:{line}" not in found:
                found.append(f"{name}:{line}")
    return found


def test_only_the_shell_imports_the_core():
    assert core_importers() == []


def test_the_rules_see_the_core_imported_behind_type_checking(tmp_path, monkeypatch):
    """A room naming the core's type only for the type checker still imports it: both checks fail."""
    room = tmp_path / "autopilot" / "mavlink"
    room.mkdir(parents=True)
    (tmp_path / "autopilot" / "__init__.py").write_text("")
    (room / "bad.py").write_text(
        "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from ..core import AutopilotCore\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert upward_imports()[0] == "autopilot/mavlink/bad.py:4 -> autopilot.core"
    assert core_importers() == ["autopilot/mavlink/bad.py:4"]


# -- file sizes ---------------------------------------------------------------------------------------
LINES_MAX = 600  # a source file longer than this says in its docstring why it is one file
ONE_FILE_REASON = ("(One module:", "(One script")


def long_files_without_a_reason(root: Path = ROOT) -> list[str]:
    """``path (lines)`` of every source file over :data:`LINES_MAX` lines whose module docstring does
    not say why it is one file (a paragraph opening with one of :data:`ONE_FILE_REASON`)."""
    found = []
    for package in PACKAGES:
        for path in sorted(p for p in (root / package).rglob("*.py") if "vendor" not in p.parts):
            text = path.read_text()
            lines = text.count("\n")
            if lines <= LINES_MAX:
                continue
            doc = ast.get_docstring(ast.parse(text)) or ""
            if not any(opening in doc for opening in ONE_FILE_REASON):
                found.append(f"{path.relative_to(root)} ({lines})")
    return found


def test_every_long_source_file_says_why_it_is_one_file():
    assert long_files_without_a_reason() == []


def test_the_size_rule_sees_a_long_file_without_a_reason(tmp_path):
    module = tmp_path / "autopilot" / "long.py"
    module.parent.mkdir()
    module.write_text('"""A module."""\n' + "x = 1\n" * LINES_MAX)
    (tmp_path / "autopilot" / "short.py").write_text('"""Short."""\n')
    for package in PACKAGES[1:]:
        (tmp_path / package).mkdir()
    assert long_files_without_a_reason(tmp_path) == [f"autopilot/long.py ({LINES_MAX + 1})"]
    module.write_text('"""A module.\n\n(One module: the reason.)\n"""\n' + "x = 1\n" * LINES_MAX)
    assert long_files_without_a_reason(tmp_path) == []
