"""Suite-wide wiring: the kernels compiled once, a port block per pytest process, the heavy tests
scheduled first.

The test command is one pytest run, three workers over two cores (``pytest -n 3``, pytest-xdist;
CONTRIBUTING.md).
Test modules that start processes say so themselves (``pytestmark = pytest.mark.processes``; those
with third-party clients ``compat`` as well): ``-m "not processes"`` runs the in-process tests alone.

* Before any test, in the process that runs or dispatches them (xdist's controller), ``quadsitl
  compile --missing`` fills numba's cache: else the workers' first processes would compile the same
  kernels at once (seconds each) while their tests wait. With the cache full it loads nothing.
* Each process that runs tests claims a port block of its own (:mod:`tests.ports`) and points
  ``QUADSITL_CONFIG_DIR`` at a ``sitl.toml`` with those bases: every vehicle a test starts, and
  every port a test computes with ``load_sitl().ports(n)``, is on it. No test binds a fixed port.
* The lockstep processes the tests start do not busy-wait for their peer
  (``QUADSITL_LOCKSTEP_SPIN_S=0``, docs/running.md): three workers share two cores, and a spinning
  process takes the core its peer or the other workers need. The benchmarks measure the SITL with
  its default spin.
* The modules marked ``processes`` are collected first: they wait on real processes and the wall
  clock, so xdist hands them out before the short in-process ones that fill the gaps.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from quadcommon import environment


def _runs_tests(config: pytest.Config) -> bool:
    """False in xdist's controller (it only dispatches); True in a worker or a plain run."""
    if hasattr(config, "workerinput"):
        return True
    return not getattr(config.option, "numprocesses", None)


def pytest_configure(config: pytest.Config) -> None:
    os.environ.setdefault(environment.LOCKSTEP_SPIN, "0")
    # Bytecode cached (in __pycache__, ignored by git) even where the environment says not to: each
    # of the ~90 processes the tests start would compile the project's modules again.
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    if _runs_tests(config):
        from tests.ports import claim_block

        start, directory = claim_block()
        config.stash[_PORT_BLOCK] = (start, directory)


_PORT_BLOCK = pytest.StashKey[tuple]()


def pytest_report_header(config: pytest.Config) -> str | None:
    block = config.stash.get(_PORT_BLOCK, None)
    return None if block is None else f"quadsitl test ports: block {block[0]} ({block[1]}/sitl.toml)"


def pytest_sessionstart(session: pytest.Session) -> None:
    if hasattr(session.config, "workerinput") or environment.pure_python():
        return
    compiled = subprocess.run([sys.executable, "-m", "sitl.compile", "--missing"], capture_output=True,
                              text=True, timeout=1200)  # fmt: skip
    if compiled.returncode != 0:
        raise pytest.UsageError(f"quadsitl compile failed:\n{compiled.stdout}{compiled.stderr}")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # Stable: the order within each group stays pytest's.
    items.sort(key=lambda item: item.get_closest_marker("processes") is None)
