"""Equations written once: plain Python functions that numba compiles from the same source.

A *kernel* is a function over floats, tuples and arrays (numpy arrays where numba runs it; numpy
arrays or lists where Python does), decorated with :func:`kernel`. Python calls it as it is.
Compiled code that calls it gets it compiled by numba **from the same function**: the decorator
registers the function as its own numba overload. There is no second copy to keep equal, and
without numba the very same source runs, slower.

What Python calls per step or per run is an *entry*, from :func:`compiled`: for a kernel, and
kernels bound to its first arguments (a cascade's two laws, say), a numba dispatcher compiled with
``cache=True`` (compiled once, then loaded from disk), or the kernel itself where nothing compiles
(:func:`compiling` false: numba missing, or ``QUADSITL_PURE_PYTHON=1``). Bound kernels are
compile-time constants of the entry: numba specialises the entry to them and inlines them, so a
law pair flies as one compiled loop.

Why the entries live in generated modules: numba keys a cached function on its own source file,
not on the files of the kernels it calls, so an edited equation elsewhere would be served stale
from the cache. An entry is therefore a three-line module in :func:`~.environment.kernel_cache_dir`
whose name carries a digest of every kernel module of the project (the files holding
``@kernel``) and of the bound kernels' own files: an edited equation gets a new module and a fresh
compilation; an unchanged one loads from the cache in a fraction of a second.

Writing a kernel (what numba's nopython mode takes): ``math`` functions, arithmetic, ``if``,
``for ... in range``, tuples (also nested), numpy arrays indexed or allocated with ``np.zeros`` /
``np.empty``, calls to other kernels, module-level constants (frozen when an entry compiles: keep
them in a kernel module). No dicts, no objects, no exceptions for control flow. Division by zero
gives inf/NaN in compiled code (``error_model="numpy"``) where Python raises.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import inspect
import os
import re
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from . import environment

F = TypeVar("F", bound=Callable[..., Any])

# The packages whose kernel modules an entry's digest covers (the whole project: any of them may
# hold an equation a kernel calls).
PROJECT_ROOT = Path(__file__).resolve().parents[1]
PROJECT_PACKAGES = ("quadcommon", "autopilot", "simulator", "sitl", "gcs_scripts")
JIT_OPTIONS = {"error_model": "numpy"}

_pending: list[Callable[..., Any]] = []  # kernels decorated before numba was loaded
_numba_loaded = False
_lock = threading.RLock()


def kernel(fn: F) -> F:
    """Mark ``fn`` as a kernel: Python calls it as it is; compiled code compiles the same function."""
    return _kernel(fn, inline=False)


def inlined_kernel(fn: F) -> F:
    """A :func:`kernel` whose body compiled code inlines into each caller before typing (numba's
    ``inline="always"``): for a kernel that calls a kernel it is handed (the integrator of
    :func:`simulator.dynamics.equations.rk4_of`), which LLVM leaves as a call costing ~15 % of a
    plant step."""
    return _kernel(fn, inline=True)


def _kernel(fn: F, inline: bool) -> F:
    fn.__quadsitl_inline__ = inline  # type: ignore[attr-defined]
    with _lock:
        if _numba_loaded:
            _register(fn)
        else:
            _pending.append(fn)
    fn.__quadsitl_kernel__ = True  # type: ignore[attr-defined]
    return fn


def is_kernel(fn: object) -> bool:
    """Whether ``fn`` was written as a kernel (:func:`kernel`)."""
    return bool(getattr(fn, "__quadsitl_kernel__", False))


@functools.cache
def compiling() -> bool:
    """True when entries are compiled: numba imports and ``QUADSITL_PURE_PYTHON`` is not ``1``.
    The one place that decides (read once per process)."""
    if environment.pure_python():
        return False
    try:
        _load_numba()
    except ImportError:
        return False
    return True


def compiled(fn: Callable[..., Any], *bound: Callable[..., Any], nogil: bool = False) -> Callable[..., Any]:
    """The entry Python calls: ``entry(*args) == fn(*bound, *args)``, compiled and cached when
    :func:`compiling`, else ``fn`` itself (bound with :func:`functools.partial`)."""
    for f in (fn, *bound):
        if not is_kernel(f):
            raise TypeError(f"{_qualified(f)} is not a kernel (decorate it with @kernel)")
    if not compiling():
        return functools.partial(fn, *bound) if bound else fn
    return _entry(fn, tuple(bound), nogil)


def warmed(fn: Callable[..., Any], *args: Any) -> Callable[..., Any]:
    """:func:`compiled` ``fn`` as a process calls it every frame: where kernels compile, run once
    on ``args`` (compiled now or loaded from numba's cache) and then :func:`frozen <freeze>`, so a
    flight never waits for a compilation; ``fn`` itself where nothing compiles."""
    entry = compiled(fn)
    if compiling():
        entry(*args)
        freeze(entry)
    return entry


def vector(values: Sequence[float] | int) -> Any:
    """A kernel's mutable float buffer: a float64 numpy array where kernels compile, a list of
    floats where Python runs them (list indexing is Python's fastest). An int gives zeros."""
    items = [0.0] * values if isinstance(values, int) else [float(v) for v in values]
    if compiling():
        import numpy as np

        return np.array(items, dtype=np.float64)
    return items


def borrowed(array: Any) -> Any:
    """``array`` itself where Python runs; in compiled code, a view of it that carries no reference
    count. Compiled code counts references to every array it passes to a kernel (an atomic
    increment and decrement per array per call, which numba cannot always prove redundant); a
    kernel stepping thousands of times per run passes its arrays borrowed. The view is valid while
    ``array`` is alive: borrow a function's arguments, or arrays it keeps in a variable it reads
    again after the loop (see :func:`~sitl.campaign.kernels.simulate`)."""
    return array


def matrix_view(buffer: Any, at: int, rows: int, cols: int) -> Any:
    """The ``rows`` x ``cols`` matrix (C order) that the flat ``buffer`` holds from offset ``at``: a
    view, no copy (``buffer[at : at + rows * cols].reshape((rows, cols))``). In compiled code the
    view is made in place: a reshape calls into numba's C helper (some 12 ns, and a fusion cuts
    several matrices from its work buffer), and, as :func:`borrowed`, the view carries no
    reference count: it is valid while ``buffer`` is alive. Outside the buffer: IndexError."""
    if at < 0 or rows < 0 or cols < 0 or at + rows * cols > len(buffer):
        raise IndexError(f"matrix_view: {rows}x{cols} from {at} is outside a buffer of {len(buffer)}")
    return buffer[at : at + rows * cols].reshape((rows, cols))


def freeze(entry: Callable[..., Any]) -> None:
    """No compiling from now on (after a warm-up call): a call whose argument types match no
    compiled signature, even after numba's safe conversions, raises TypeError instead of stalling
    the caller for seconds in the middle of a flight."""
    disable = getattr(entry, "disable_compile", None)
    if disable is not None:
        disable()


_COLOUR = re.compile(r"\x1b\[[0-9;]*m")
_LOCATION = re.compile(r'^\s*File "(?P<file>[^"]+)", line (?P<line>\d+):', re.M)
_PIPELINE = re.compile(r"Failed in \w+ mode pipeline \(step: [^)]*\)\s*$", re.M)


def typing_error_cause(error: BaseException) -> str | None:
    """The cause of a numba compilation error, as a kernel's author wants it: ``FILE, line N: what
    numba could not type`` and that line of source. numba nests the error of a kernel called by a
    kernel inside its caller's (an entry, the cascade, the law: each adds its own frames and
    candidate signatures), and prints the innermost location first: that location, and the message
    just before it, are the cause. None when ``error``'s text carries no source location."""
    text = _COLOUR.sub("", str(error))
    location = _LOCATION.search(text)
    if location is None:
        return None
    before = text[: location.start()]
    pipelines = list(_PIPELINE.finditer(before))
    start = pipelines[-1].end() if pipelines else 0
    message = " ".join(line.strip() for line in before[start:].splitlines() if line.strip())
    path = os.path.normpath(os.path.join(os.getcwd(), location["file"]))  # numba prints it relative
    line = int(location["line"])
    try:
        source = Path(path).read_text().splitlines()[line - 1].strip()
    except (OSError, IndexError, UnicodeDecodeError):
        source = ""
    hint = ""
    if "Untyped global name" in message and "<class 'function'>" in message:
        hint = " (a function a kernel calls must be a kernel too: decorate it with @kernel)"
    return f"{path}, line {line}: {message}{hint}" + (f"\n    {source}" if source else "")


# -------------------------------------------------------------------------------------------------
def _load_numba() -> None:
    global _numba_loaded
    with _lock:
        if _numba_loaded:
            return
        import numba  # noqa: F401 - ImportError: nothing compiles

        for fn in _pending:
            _register(fn)
        _pending.clear()
        _register_borrowed()
        _register_matrix_view()
        _numba_loaded = True


def _register(fn: Callable[..., Any]) -> None:
    """``fn`` becomes its own numba overload: compiled code calling it compiles ``fn``."""
    from numba.extending import overload

    def implementation(*args: Any) -> Callable[..., Any]:
        return fn

    implementation.__signature__ = inspect.signature(fn)  # type: ignore[attr-defined]
    inline = "always" if getattr(fn, "__quadsitl_inline__", False) else "never"
    overload(fn, jit_options=JIT_OPTIONS, inline=inline)(implementation)


def _register_borrowed() -> None:
    """:func:`borrowed` in compiled code: the array's struct with no meminfo (NRT's reference
    counting skips a null meminfo) and no parent object."""
    from numba.core import cgutils, types
    from numba.extending import intrinsic, overload

    @intrinsic
    def view_without_meminfo(typingctx: Any, array: Any) -> Any:
        if not isinstance(array, types.Array):
            return None

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            source = context.make_array(signature.args[0])(context, builder, value=args[0])
            view = context.make_array(signature.return_type)(context, builder)
            cgutils.copy_struct(view, source)
            view.meminfo = cgutils.get_null_value(view.meminfo.type)
            view.parent = cgutils.get_null_value(view.parent.type)
            return view._getvalue()

        return array(array), codegen

    def implementation(array):  # noqa: ANN001, ANN202 - numba matches its signature to the view's
        if isinstance(array, types.Array):
            return lambda array: view_without_meminfo(array)
        return None

    overload(borrowed, jit_options=JIT_OPTIONS)(implementation)


def _register_matrix_view() -> None:
    """:func:`matrix_view` in compiled code: the bounds checked, then the 2-D array struct built on
    the buffer's data pointer (strides ``(cols, 1)`` items, no meminfo, no parent)."""
    from numba.core import types
    from numba.extending import intrinsic, overload
    from numba.np.arrayobj import populate_array

    @intrinsic
    def view_2d(typingctx: Any, buffer: Any, at: Any, rows: Any, cols: Any) -> Any:
        result = types.Array(buffer.dtype, 2, "C")

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            source = context.make_array(signature.args[0])(context, builder, value=args[0])
            given = zip(args[1:], signature.args[1:], strict=True)
            start, n_rows, n_cols = (context.cast(builder, value, of, types.intp) for value, of in given)
            size = context.get_abi_sizeof(context.get_data_type(buffer.dtype))
            itemsize = context.get_constant(types.intp, size)
            view = context.make_array(result)(context, builder)
            populate_array(view, data=builder.gep(source.data, [start]), shape=[n_rows, n_cols],
                           strides=[builder.mul(n_cols, itemsize), itemsize], itemsize=itemsize,
                           meminfo=None)  # fmt: skip
            return view._getvalue()

        return result(buffer, at, rows, cols), codegen

    def implementation(buffer, at, rows, cols):  # noqa: ANN001, ANN202 - numba matches the signature
        if isinstance(buffer, types.Array) and buffer.ndim == 1 and buffer.layout == "C":

            def view(buffer, at, rows, cols):  # noqa: ANN001, ANN202
                if at < 0 or rows < 0 or cols < 0 or at + rows * cols > buffer.shape[0]:
                    raise IndexError("matrix_view: outside the buffer")
                return view_2d(buffer, at, rows, cols)

            return view
        return None

    overload(matrix_view, jit_options=JIT_OPTIONS)(implementation)


def _qualified(fn: Callable[..., Any]) -> str:
    return f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', repr(fn))}"


@functools.cache
def _project_digest() -> str:
    """Digest of every kernel module of the project (and of numba's version)."""
    from importlib.metadata import version

    digest = hashlib.sha256(version("numba").encode())
    for package in PROJECT_PACKAGES:
        for path in sorted((PROJECT_ROOT / package).rglob("*.py")):
            try:
                text = path.read_bytes()
            except OSError:
                continue
            if b"@kernel" in text:
                digest.update(str(path.relative_to(PROJECT_ROOT)).encode())
                digest.update(text)
    return digest.hexdigest()


def _outside_project(fn: Callable[..., Any]) -> Path | None:
    """The source file of a kernel defined outside the project's packages (a user's law)."""
    module = sys.modules.get(fn.__module__)
    path = getattr(module, "__file__", None)
    if path is None:
        return None
    path = Path(path).resolve()
    try:
        relative = path.relative_to(PROJECT_ROOT)
    except ValueError:
        return path
    return None if relative.parts[0] in PROJECT_PACKAGES else path


def _source_of_entry(fn: Callable[..., Any], bound: tuple[Callable[..., Any], ...], nogil: bool,
                     digest: str) -> str:  # fmt: skip
    params = list(inspect.signature(fn).parameters.values())[len(bound) :]
    for p in params:
        if p.kind is not inspect.Parameter.POSITIONAL_OR_KEYWORD or p.default is not inspect.Parameter.empty:
            raise TypeError(f"{_qualified(fn)}: an entry's parameters are plain positional ones ({p})")
    names = ", ".join(p.name for p in params)
    lines = [
        f'"""Generated by quadcommon.kernel; do not edit. The compiled entry of {_qualified(fn)}',
        *(f"with {_qualified(b)} bound to argument {i}" for i, b in enumerate(bound)),
        f'(sources digest {digest})."""',
        "from numba import njit",
        "",
        f"import {fn.__module__} as _m",
        *(f"import {b.__module__} as _m{i}" for i, b in enumerate(bound)),
        "",
        f"_kernel = _m.{fn.__qualname__}",
        *(f"_bound{i} = _m{i}.{b.__qualname__}" for i, b in enumerate(bound)),
        "",
        "",
        f'@njit(cache=True, error_model="numpy", nogil={nogil})',
        f"def entry({names}):",
        f"    return _kernel({''.join(f'_bound{i}, ' for i in range(len(bound)))}{names})",
        "",
    ]
    return "\n".join(lines)


_entries: dict[tuple[Any, ...], Callable[..., Any]] = {}


def cached(fn: Callable[..., Any], *bound: Callable[..., Any], nogil: bool = False) -> bool:
    """True when the entry ``compiled(fn, *bound, nogil=nogil)`` would load from numba's cache (no
    compilation); without importing numba."""
    name, _ = _entry_name(fn, tuple(bound), nogil)
    pattern = f"{name}.entry-*.nbi"
    numba_cache = environment.numba_cache_dir()
    if numba_cache is not None:
        return any(numba_cache.rglob(pattern))
    return any((environment.kernel_cache_dir() / "__pycache__").glob(pattern))


def _entry_name(
    fn: Callable[..., Any], bound: tuple[Callable[..., Any], ...], nogil: bool
) -> tuple[str, str]:
    """The generated module's name and the digest it carries."""
    digest = hashlib.sha256(_project_digest().encode())
    for f in (fn, *bound):
        digest.update(_qualified(f).encode())
        path = _outside_project(f)
        if path is not None:
            digest.update(path.read_bytes())
    digest.update(str(nogil).encode())
    hexdigest = digest.hexdigest()
    return f"quadsitl_entry_{fn.__name__}_{hexdigest[:20]}", hexdigest


def _entry(fn: Callable[..., Any], bound: tuple[Callable[..., Any], ...], nogil: bool) -> Callable[..., Any]:
    key = (fn, bound, nogil)
    with _lock:
        if key in _entries:
            return _entries[key]
        name, hexdigest = _entry_name(fn, bound, nogil)
        source = _source_of_entry(fn, bound, nogil, hexdigest)
        path = environment.kernel_cache_dir() / f"{name}.py"
        _write_once(path, source)
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        _entries[key] = module.entry
        return module.entry


def _write_once(path: Path, text: str) -> None:
    """Write ``path`` unless it exists (then it holds the same text: its name is its digest).
    Never rewritten: numba's cache of the module is keyed on the file's time stamp."""
    if path.exists():
        return
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}")
    temporary.write_text(text)
    try:
        os.link(temporary, path)  # fails if another process got there first: keep theirs
    except FileExistsError:
        pass
    finally:
        temporary.unlink(missing_ok=True)
