"""quadcommon.kernel: one source, run by Python and compiled by numba; entries cached on disk and
compiled again when an equation they use changes."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from quadcommon.kernel import borrowed, compiled, compiling, freeze, vector

pytestmark = pytest.mark.skipif(not compiling(), reason="numba is not installed or QUADSITL_PURE_PYTHON=1")

TOY = '''
import math
from quadcommon.kernel import borrowed, kernel, matrix_view

GAIN = {gain}


@kernel
def scaled(x):
    return GAIN * x


@kernel
def law(g, state, e, dt):
    state[0] += e * dt
    return scaled(g[0] * e) + state[0], math.sqrt(abs(e))


@kernel
def accumulate(f, g, state, e, dt, n):
    """n steps of the law on a borrowed view of its state (compiled: no reference counting)."""
    view = borrowed(state)
    total = 0.0
    for _ in range(n):
        a, _ = f(g, view, e, dt)
        total += a
    return total + 0.0 * len(state)  # (state read after the loop: alive while the view is used)


@kernel
def cut(buffer, at, rows, cols):
    """A matrix cut from a flat buffer, written through, and the sum of its rows' last entries."""
    M = matrix_view(buffer, at, rows, cols)
    M[0, 0] = -1.0
    total = 0.0
    for i in range(rows):
        total += M[i, cols - 1]
    return total


@kernel
def twice(f, g, state, e, dt):
    a, _ = f(g, state, e, dt)
    b, c = f(g, state, e, dt)
    return a + b + c
'''


def load(tmp_path, name: str, gain: float):
    """A module of kernels outside the project (as a user's law file is)."""
    path = tmp_path / f"{name}.py"
    path.write_text(TOY.format(gain=gain))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def cache(tmp_path, monkeypatch):
    directory = tmp_path / "kernels"
    monkeypatch.setenv("QUADSITL_KERNEL_CACHE", str(directory))
    return directory


def test_an_entry_runs_the_kernels_own_source_compiled(tmp_path, cache):
    toy = load(tmp_path, "toy_a", 2.0)
    entry = compiled(toy.twice, toy.law)
    g, state = np.array([3.0]), np.zeros(1)
    result = entry(g, state, 0.25, 0.1)
    expected = toy.twice(toy.law, [3.0], [0.0], 0.25, 0.1)  # the same function, run by Python
    assert result == pytest.approx(expected, rel=1e-15)
    assert state[0] == pytest.approx(0.05)  # the kernel's writes reach the caller's array
    assert type(entry).__name__ == "CPUDispatcher"
    assert [p.name for p in cache.glob("quadsitl_entry_twice_*.py")]  # its generated module


def test_a_borrowed_array_is_the_same_memory_in_python_and_compiled(tmp_path, cache):
    toy = load(tmp_path, "toy_borrowed", 2.0)
    state = np.zeros(1)
    assert borrowed(state) is state  # Python: the array itself
    total = compiled(toy.accumulate, toy.law)(np.array([3.0]), state, 0.5, 0.1, 4)
    expected_state = [0.0]
    expected = toy.accumulate(toy.law, [3.0], expected_state, 0.5, 0.1, 4)
    assert state[0] == pytest.approx(expected_state[0]) == pytest.approx(0.2)  # writes reach the caller
    assert total == pytest.approx(expected, rel=1e-15)


def test_a_matrix_view_is_the_same_memory_in_python_and_compiled_and_refuses_to_leave_its_buffer(
    tmp_path, cache
):
    toy = load(tmp_path, "toy_view", 1.0)
    entry = compiled(toy.cut)
    flat = np.arange(20.0)
    python_copy = flat.copy()
    assert entry(flat, 3, 4, 4) == toy.cut(python_copy, 3, 4, 4) == 6.0 + 10.0 + 14.0 + 18.0
    assert flat[3] == python_copy[3] == -1.0  # written through the view
    np.testing.assert_array_equal(flat, python_copy)
    for at, rows, cols in ((5, 4, 4), (-1, 2, 2), (0, 3, 7)):  # past the end, before the start
        with pytest.raises(IndexError):
            entry(np.arange(20.0), at, rows, cols)
        with pytest.raises(IndexError):
            toy.cut(np.arange(20.0), at, rows, cols)


def test_an_entry_is_loaded_from_the_cache_by_a_new_process_and_recompiled_when_a_source_changes(
    tmp_path, cache
):
    script = textwrap.dedent(f'''
        import importlib.util, sys, numpy as np
        from quadcommon.kernel import compiled
        spec = importlib.util.spec_from_file_location("toy_b", {str(tmp_path / "toy_b.py")!r})
        toy = importlib.util.module_from_spec(spec); sys.modules["toy_b"] = toy; spec.loader.exec_module(toy)
        entry = compiled(toy.twice, toy.law)
        value = entry(np.array([1.0]), np.zeros(1), 1.0, 0.0)
        print(value, sum(entry.stats.cache_hits.values()), sum(entry.stats.cache_misses.values()))
    ''')

    def run() -> tuple[float, int, int]:
        env = {**os.environ, "QUADSITL_KERNEL_CACHE": str(cache)}
        out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                             env=env)
        assert out.returncode == 0, out.stderr
        value, hits, misses = out.stdout.split()
        return float(value), int(hits), int(misses)

    (tmp_path / "toy_b.py").write_text(TOY.format(gain=2.0))
    assert run() == (2 * 2.0 + 1.0, 0, 1)  # compiled: GAIN * g * e twice, + sqrt(1)
    assert run() == (2 * 2.0 + 1.0, 1, 0)  # loaded from the cache
    (tmp_path / "toy_b.py").write_text(TOY.format(gain=5.0))  # an edited equation ...
    assert run() == (2 * 5.0 + 1.0, 0, 1)  # ... is compiled again, never served stale


def test_a_frozen_entry_converts_safely_or_refuses_instead_of_compiling(tmp_path, cache):
    toy = load(tmp_path, "toy_c", 1.0)
    entry = compiled(toy.twice, toy.law)
    entry(np.array([1.0]), np.zeros(1), 0.5, 0.1)
    freeze(entry)
    entry(np.array([1.0]), np.zeros(1), 1, 0.1)  # an int where a float was: numba converts it
    with pytest.raises(TypeError):
        entry(np.array([1], dtype=np.int64), np.zeros(1), 0.5, 0.1)  # an int array: no compiling now


def test_only_kernels_make_entries():
    def plain(x):
        return x

    with pytest.raises(TypeError, match="is not a kernel"):
        compiled(plain)


def test_vector_is_the_compiled_paths_buffer():
    zeros = vector(3)
    assert isinstance(zeros, np.ndarray) and zeros.dtype == np.float64 and list(zeros) == [0.0] * 3
    assert list(vector((1, 2))) == [1.0, 2.0]


def test_without_numba_the_same_source_runs_in_python(tmp_path):
    (tmp_path / "toy_d.py").write_text(TOY.format(gain=3.0))
    script = textwrap.dedent(f'''
        import sys; sys.path.insert(0, {str(tmp_path)!r})
        import toy_d
        from quadcommon.kernel import compiled, compiling, vector
        entry = compiled(toy_d.twice, toy_d.law)
        state = vector(1)
        value = entry([2.0], state, 1.0, 0.5)
        print(compiling(), type(state).__name__, value, state[0], "numba" in sys.modules)
    ''')
    env = {**os.environ, "QUADSITL_PURE_PYTHON": "1"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "list", str(3.0 * 2.0 * 2 + 0.5 + 1.0 + 1.0), "1.0", "False"]


INLINED = '''
from quadcommon.kernel import inlined_kernel, kernel


@kernel
def square(x):
    return x * x


def applied_twice(f):
    def twice_of(x):
        return f(f(x))

    twice_of.__name__ = twice_of.__qualname__ = f"twice_of_{f.__name__}"
    return inlined_kernel(twice_of)


twice_square = applied_twice(square)


@kernel
def plain_twice(x):
    return square(square(x))


@kernel
def through_inlined(x):
    return twice_square(x) + 1.0


@kernel
def through_plain(x):
    return plain_twice(x) + 1.0
'''


def test_an_inlined_kernel_leaves_no_call_of_its_own_in_its_callers_code(tmp_path, cache):
    """The one RK4 (simulator.dynamics.equations.rk4_of) is made this way: a kernel over a kernel
    it is handed, inlined where it is called; a plain kernel stays a call."""
    path = tmp_path / "toy_inlined.py"
    path.write_text(INLINED)
    spec = importlib.util.spec_from_file_location("toy_inlined", path)
    toy = importlib.util.module_from_spec(spec)
    sys.modules["toy_inlined"] = toy
    spec.loader.exec_module(toy)
    inlined, plain = compiled(toy.through_inlined), compiled(toy.through_plain)
    assert inlined(3.0) == plain(3.0) == toy.through_inlined(3.0) == 82.0  # Python runs it as it is
    code = inlined.inspect_llvm(inlined.signatures[0])
    assert "twice_of_square" not in code and "square" in code
    assert "plain_twice" in plain.inspect_llvm(plain.signatures[0])
