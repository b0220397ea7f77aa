"""``make test``: the suite as five pytest sessions side by side.

* ``-m "not processes"``: in-process and in simulation time, the large majority (CPU-bound), in
  two sessions (tests/sitl, tests/gcs_scripts and tests/estimation in the second);
* ``-m "processes and not compat"``: the tests that start processes or bind the SITL's fixed
  ports, one after another (see ``tests/conftest.py``);
* ``-m "compat and not second_namespace"``: MAVProxy against real vehicles, several vehicles,
  signing with real clients, the view on a live SITL and the paper through the SITL
  (``tests/conftest.py``), one after another, in a network namespace of its own (``unshare -n``
  with only loopback up: its port block overlaps other instances' ports, e.g. 14640 is instance
  60's API link);
* ``-m "compat and second_namespace"``: MAVSDK 4, MAVSDK-Python 3 and the installed wheel, in a
  second namespace (the two compat sessions use the same ports; each namespace has its own
  loopback). Where no namespace can be made, the compat tests run in the processes session.

The lockstep processes the tests start do not busy-wait for their peer (``QUADSITL_LOCKSTEP_SPIN_S=0``,
docs/running.md, "Several vehicles"): the sessions share 2 cores here, and a spinning process takes
the core its peer or another session needs (the suite takes about a third more wall time spinning). The
benchmarks measure the SITL with its default spin.

Each session's output goes to ``out/tests/<session>.log`` and is printed when it ends; the exit code
is non-zero when any session fails (or is interrupted), and the wall time and CPU time (the session
with every process it waited for) of each are reported.
Extra arguments go to every session (``python -m tests.suite -x -k fuzz``); when they name test
paths (``python -m tests.suite tests/sitl``), every session collects those instead of its own.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from tests.conftest import COMPAT_MODULES, NOT_COMPAT, PROCESS_MODULES, SECOND_NAMESPACE, _listed

LOGS = Path("out/tests")
# In a new network namespace: bring its loopback up, then run the command given after it.
NAMESPACE = ["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$0" "$@"']


def namespace_available() -> bool:
    try:
        probe = subprocess.run([*NAMESPACE, "true"], capture_output=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


def sessions(own_paths: bool = True) -> list[tuple[str, str, list[str], list[str]]]:
    """(name, marker selection, command prefix, paths to collect) of each pytest session.

    The marker selects; the paths only spare the process and compat sessions importing test
    modules they would deselect whole (collecting the whole tree costs ~3.6 s of CPU a session:
    matplotlib, scipy.stats, ...), and split the in-process tests in two. They come from the same
    lists as the markers (tests/conftest.py). ``own_paths=False`` (the caller names test paths):
    one in-process session, and every session collects the caller's paths.
    """
    processes = _paths(PROCESS_MODULES)
    if own_paths:
        # The in-process tests, CPU-bound, in two sessions of about equal CPU (measured alone:
        # sitl, gcs_scripts and estimation 44 s; the rest 48 s): one was the suite's last by ~15 s.
        split = ["tests/sitl/", "tests/gcs_scripts/", "tests/estimation/"]
        in_process = [("in-process", "not processes", [], ["tests/", *(f"--ignore={d}" for d in split)]),
                      ("in-process-2", "not processes", [], split)]  # fmt: skip
    else:
        in_process = [("in-process", "not processes", [], [])]
    if namespace_available():
        # NOT_COMPAT entries sit inside compat folders: named again so the process session has them.
        not_compat = [p for p in processes if not _listed(p, COMPAT_MODULES)] + sorted(NOT_COMPAT)
        compat, second = _paths(COMPAT_MODULES), _paths(SECOND_NAMESPACE)
        sessions = [*in_process,
                    ("processes", "processes and not compat", [], not_compat),
                    ("compat", "compat and not second_namespace", NAMESPACE, compat),
                    ("compat-2", "compat and second_namespace", NAMESPACE, second)]  # fmt: skip
    else:
        sessions = [*in_process, ("processes", "processes", [], processes)]
    if not own_paths:
        sessions = [(name, selection, prefix, []) for name, selection, prefix, _ in sessions]
    return sessions


def _paths(entries: set[str]) -> list[str]:
    """The entries, without those inside another entry's folder (pytest would collect them twice)."""
    folders = [e for e in entries if e.endswith("/")]
    return sorted(e for e in entries if not any(e != f and e.startswith(f) for f in folders))


# pytest options whose value may come as the next argument (``-k sitl``: "sitl" is not a path).
_TAKES_VALUE = {
    "-k", "-m", "-p", "-c", "-o", "-W", "-r", "--deselect", "--ignore", "--ignore-glob", "--junitxml",
    "--junit-xml", "--rootdir", "--durations", "--durations-min", "--timeout", "--maxfail", "--basetemp",
    "--confcutdir", "--log-file", "--log-level", "--tb", "--color", "--import-mode", "--override-ini",
}  # fmt: skip


def _names_paths(argv: list[str]) -> bool:
    """True when the extra arguments name test files or folders (not as an option's value)."""
    skip = False
    for arg in argv:
        if skip:
            skip = False
        elif arg.startswith("-"):
            skip = arg in _TAKES_VALUE
        elif Path(arg.split("::", 1)[0]).exists():
            return True
    return False


def main(argv: list[str]) -> int:
    LOGS.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    # The flight's kernels compiled once, here, in parallel: else the sessions' first processes
    # would each compile the same entries at once (seconds each) while others wait on them.
    compile_kernels = subprocess.run([sys.executable, "-m", "sitl.compile"], timeout=1200)
    if compile_kernels.returncode != 0:
        return compile_kernels.returncode
    runs = []
    for name, selection, prefix, paths in sessions(own_paths=not _names_paths(argv)):
        log = (LOGS / f"{name}.log").open("w")
        pytest = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", selection]
        pytest += [*argv, *paths]
        cmd = [*prefix, *pytest]
        env = {**os.environ, "QUADSITL_LOCKSTEP_SPIN_S": "0"}
        # Bytecode cached (in __pycache__, ignored by git) even where the environment says not to:
        # every session and every process a test starts would compile the project's modules again
        # (measured: importing the two cores 0.40 -> 0.26 s of CPU, ~90 processes a run).
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        runs.append((name, log, subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env), cmd))
    codes = {}
    try:
        pending = list(runs)
        while pending:
            for run in list(pending):
                name, log, process, cmd = run
                pid, status, usage = os.wait4(process.pid, os.WNOHANG)
                if pid == 0:
                    continue
                process.returncode = os.waitstatus_to_exitcode(status)
                pending.remove(run)
                log.close()
                codes[name] = process.returncode
                elapsed = time.monotonic() - started
                args = " ".join(cmd[cmd.index("pytest") + 1 :])
                cpu = usage.ru_utime + usage.ru_stime  # the session and every process it started
                print(f"==== {name} tests ({args}): exit {process.returncode} after {elapsed:.0f} s, "
                      f"{cpu:.0f} CPU-s")  # fmt: skip
                print((LOGS / f"{name}.log").read_text(), flush=True)
            time.sleep(0.2)
    except KeyboardInterrupt:
        for _, _, process, _ in runs:
            process.terminate()
        return 130
    total = time.monotonic() - started
    # pytest exit 5 = nothing collected (a selection that matches nothing): not a failure
    failed = {name: code for name, code in codes.items() if code not in (0, 5)}
    print(f"==== suite: {'FAILED ' + ', '.join(failed) if failed else 'passed'} in {total:.0f} s (wall)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
