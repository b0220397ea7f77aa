"""A deep copy of a flight stack is a second vehicle: it shares no mutable state with the original.

The failure flights (test_failures_flown.py) fly deep copies of one hover. ``copy.deepcopy`` copies
a lambda as it is, closure and all: a lambda a room was handed (``lambda: self.sim_time``) goes on
reading, or steering, the original vehicle from inside the copy. So the rooms get bound methods,
which a deep copy rebinds to the copy; these tests find any closure that still reaches back.
"""

from __future__ import annotations

import copy
import copyreg
import gc
import struct
import types

import numpy as np
import pytest

from ..stack import make_stack

pytestmark = pytest.mark.timeout(120)

# pymavlink's codec keeps precompiled struct.Struct objects, which copy by their format string.
copyreg.pickle(struct.Struct, lambda s: (struct.Struct, (s.format,)))

ATOMIC = (type, types.ModuleType, types.CodeType, types.BuiltinFunctionType, str, bytes, int, float,
          complex, bool, type(None))  # fmt: skip
OURS = ("autopilot", "simulator", "quadcommon", "sitl", "gcs_scripts")


def reachable(root: object) -> dict[int, object]:
    """Every object reachable from ``root`` as a deep copy walks it, plus the contents of the
    closures of the functions on the way (what a deep copy does not copy). Compiled kernels and
    their globals are left out: they are shared code, not state."""
    seen: dict[int, object] = {}
    todo = [root]
    while todo:
        obj = todo.pop()
        if isinstance(obj, ATOMIC) or id(obj) in seen:
            continue
        seen[id(obj)] = obj
        if isinstance(obj, types.FunctionType):
            cells = obj.__closure__ or ()
            todo.extend(cell.cell_contents for cell in cells if cell.cell_contents is not None)
            continue
        if (type(obj).__module__ or "").startswith("numba"):
            continue
        todo.extend(gc.get_referents(obj))
    return seen


def _state(obj: object) -> bool:
    """Mutable state: a container, an array or an instance of this project's classes (its enums,
    tuples and frozen records aside)."""
    if isinstance(obj, (list, dict, set, bytearray, np.ndarray)):
        return True
    kind = type(obj)
    if (kind.__module__ or "").split(".")[0] not in OURS or isinstance(obj, tuple):
        return False
    params = getattr(kind, "__dataclass_params__", None)
    return not (params is not None and params.frozen) and not hasattr(kind, "_member_map_")


def closures_reaching_back(original: object, twin: object) -> list[str]:
    """The functions inside ``twin`` whose closures hold mutable state of ``original``."""
    theirs = reachable(original)
    found = []
    for obj in reachable(twin).values():
        if isinstance(obj, types.FunctionType) and obj.__closure__:
            for cell in obj.__closure__:
                value = cell.cell_contents
                if id(value) in theirs and _state(value):
                    code = obj.__code__
                    found.append(f"{obj.__qualname__} ({code.co_filename}:{code.co_firstlineno}) -> "
                                 f"{type(value).__qualname__}")  # fmt: skip
    return sorted(set(found))


@pytest.fixture(scope="module")
def stack_and_twin():
    stack = make_stack(sensors="gps", estimator="ekf")
    stack.run_for(0.3)
    return stack, copy.deepcopy(stack)


def test_no_closure_in_a_copied_stack_reaches_the_original(stack_and_twin):
    stack, twin = stack_and_twin
    assert closures_reaching_back(stack, twin) == []
    theirs = reachable(stack)
    shared = [obj for key, obj in reachable(twin).items() if key in theirs and _state(obj)]
    assert shared == []


def test_the_walk_finds_a_closure_that_reaches_back():
    """The check itself: a lambda over a mutable object, deep-copied, is found."""

    rows: list[int] = []
    holder = {"rows": rows, "count": lambda: len(rows)}
    found = closures_reaching_back(holder, copy.deepcopy(holder))
    assert len(found) == 1 and found[0].endswith("-> list"), found


def test_flying_the_copy_leaves_the_original_where_it_was(stack_and_twin):
    stack, twin = stack_and_twin
    before = (stack.t, stack.autopilot.sim_time, stack.autopilot.status.time_usec)
    twin = copy.deepcopy(twin)
    twin.run_for(0.3)
    assert twin.autopilot.sim_time > before[1]
    assert twin.autopilot.status.time_usec > before[2]
    assert (stack.t, stack.autopilot.sim_time, stack.autopilot.status.time_usec) == before
