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
* The order xdist hands the tests out in (:func:`pytest_collection_modifyitems`): the longest
  first, so none is left to run alone at the end, and the live view's wall-clock tests beside them
  (:data:`FIRST`); then the modules that start
  processes (marked ``processes``: they wait on real processes and the wall clock) one for one with
  the in-process ones, so that while a worker waits on a vehicle the others keep the cores busy.
  A module's tests run on one worker (``--dist loadfile``), in order, except those of
  :data:`PER_TEST`, whose tests each start a vehicle of their own and are handed out one by one.
"""

from __future__ import annotations

import os
import subprocess
import sys
from itertools import zip_longest

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


# Handed out first, in this order (node id prefixes): the longest tests and modules (30 s to a minute
# or more of wall time with three workers on two cores), and the live view's browser tests, which
# watch a vehicle at the wall clock's pace (a page's update rate, a gust sent while it flies): they
# start beside the MAVSDK-Python 3 tests, which mostly wait, rather than beside two workers computing.
FIRST = (
    "tests/compat/test_mavsdk3.py::test_mavsdk_python3_examples_fly",
    "tests/gcs_scripts/view/test_browser_sitl.py",
    "tests/compat/test_mavsdk3.py",
    "tests/gcs_scripts/view/test_live_sitl.py",
    "tests/sitl/test_inprocess.py",
    "tests/sitl/test_failures_flown.py",
    "tests/sitl/test_fuzz.py",
    "tests/compat/test_mavsdk.py::test_the_geofence_and_manual_control_examples",
    "tests/sitl/test_manual_modes_sitl.py",
    "tests/sitl/campaign/test_cli.py",
    "tests/sitl/campaign/test_dask.py",
)
# Modules whose tests share no costly fixture (each flies a vehicle of its own): with -n, each test is
# a unit of work of its own, so a module's minutes spread over the workers.
PER_TEST = ("tests/compat/test_mavsdk3.py", "tests/compat/test_mavsdk.py")


def _unit(nodeid: str) -> str:
    """The unit of work a test is handed out in: its module, or itself in a :data:`PER_TEST` module."""
    path = nodeid.split("::", 1)[0]
    return nodeid if path in PER_TEST else path


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    units: dict[str, list[pytest.Item]] = {}
    for item in items:
        units.setdefault(_unit(item.nodeid), []).append(item)

    def rank(unit: str) -> int:
        return next((i for i, prefix in enumerate(FIRST) if unit.startswith(prefix)), len(FIRST))

    first = sorted((u for u in units if rank(u) < len(FIRST)), key=rank)  # stable: pytest's order within
    rest = [u for u in units if rank(u) == len(FIRST)]
    waiting = [u for u in rest if units[u][0].get_closest_marker("processes") is not None]
    computing = [u for u in rest if units[u][0].get_closest_marker("processes") is None]
    mixed = [u for pair in zip_longest(waiting, computing) for u in pair if u is not None]
    items[:] = [item for unit in first + mixed for item in units[unit]]


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadfile`` with the tests of :data:`PER_TEST` modules handed out one by one."""
    if config.getoption("dist", None) != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class Scheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _unit(nodeid)

    return Scheduling(config, log)
