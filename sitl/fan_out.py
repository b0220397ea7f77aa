"""One ground-station script for several vehicles: ``quadsitl fly ... --instance 0-9`` and
``quadsitl mission ... --instance 0-9`` run the script once per instance, side by side.

``--instance`` takes one instance (``3``, the script's own flag), a range (``0-9`` or ``0..9``), a
list (``3,5,8``) or both (``0-4,10-14``). With more than one, each instance gets its own process
of the same command with ``--instance N`` (they fly at the same time, each on its own vehicle's
API port, as one script per vehicle would); every line they print comes out prefixed with
``[N]``, and the exit status is the first non-zero one in instance order (0 when all succeeded),
after a one-line summary. A ``{instance}`` in any argument becomes the instance's number, and an
option that names one output file (``--save``, ``--out``) must hold it, so that no two scripts
write the same file; ``--url`` names one vehicle's link and is refused with several.

Each script is a process of its own (a pymavlink script: about 50 MB and one CPU-second to
start), so a range suits a handful to a few dozen vehicles; Ctrl-C stops them all.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import threading
from collections.abc import Sequence

from quadcommon import wire

OWN_FILE_OPTIONS = ("--save", "--out")  # options that name one file: {instance} needed with several
STOP_WAIT_S = 10.0  # after Ctrl-C, how long a script has to land its vehicle and exit


class InstanceError(ValueError):
    """A bad ``--instance`` value or a flag that cannot go with several instances."""


def parse_instances(text: str) -> list[int]:
    """:func:`quadcommon.wire.parse_instances`, its ValueError as an InstanceError."""
    try:
        return wire.parse_instances(text)
    except ValueError as exc:
        raise InstanceError(str(exc)) from None


def instance_argument(argv: Sequence[str]) -> tuple[int, int] | None:
    """Where ``--instance``'s value is in ``argv`` (index of the flag, of the value; the same for
    ``--instance=V``), or None without one."""
    for i, arg in enumerate(argv):
        if arg == "--":
            return None
        if arg == "--instance" and i + 1 < len(argv):
            return i, i + 1
        if arg.startswith("--instance="):
            return i, i
    return None


def several_instances(argv: Sequence[str]) -> list[int] | None:
    """The instances ``argv``'s ``--instance`` names when it names more than one, else None (the
    script takes its own flag). InstanceError for a malformed range."""
    where = instance_argument(argv)
    if where is None:
        return None
    value = argv[where[1]]
    value = value.split("=", 1)[1] if where[0] == where[1] else value
    if re.fullmatch(r"\s*\d+\s*", value):
        return None  # one instance (or not a number at all): the script's own parser says
    instances = parse_instances(value)
    return instances if len(instances) > 1 else None


def script_argv(argv: Sequence[str], instance: int) -> list[str]:
    """``argv`` for one instance: ``--instance N``, and ``{instance}`` replaced in every argument."""
    flag, value = instance_argument(argv)
    out = [arg.replace("{instance}", str(instance)) for arg in argv]
    out[flag : value + 1] = ["--instance", str(instance)]
    return out


def check_several(argv: Sequence[str]) -> None:
    """InstanceError for what cannot go with several instances: ``--url`` (one vehicle's link), an
    output file without ``{instance}`` (every script would write it)."""
    for i, arg in enumerate(argv):
        name, _, inline = arg.partition("=")
        if name == "--url":
            raise InstanceError("--url names one vehicle's link: leave it out with several instances "
                                "(each script finds its vehicle's API port)")  # fmt: skip
        if name in OWN_FILE_OPTIONS:
            path = inline if inline else (argv[i + 1] if i + 1 < len(argv) else "")
            if "{instance}" not in path:
                raise InstanceError(f"{name} {path}: with several instances the path must contain "
                                    f"{{instance}} (each script writes its own), e.g. {name} "
                                    f"run_{{instance}}")  # fmt: skip


def run_each(command: Sequence[str], argv: Sequence[str], instances: Sequence[int], prog: str) -> int:
    """``command`` + :func:`script_argv` for every instance, all at once; their lines prefixed
    ``[N]`` on stdout; the first non-zero exit status in instance order, or 0."""
    lock = threading.Lock()
    children: list[tuple[int, subprocess.Popen]] = []
    readers = []

    def relay(instance: int, stream) -> None:
        for line in stream:
            with lock:
                sys.stdout.write(f"[{instance}] {line}")
                sys.stdout.flush()

    try:
        for n in instances:
            # errors="replace": a byte that is not UTF-8 must not stop the relay (the child would
            # then block on a full pipe).
            child = subprocess.Popen([*command, *script_argv(argv, n)], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, errors="replace",
                                     bufsize=1)  # fmt: skip
            children.append((n, child))
            reader = threading.Thread(target=relay, args=(n, child.stdout), daemon=True)
            reader.start()
            readers.append(reader)
        codes = [(n, child.wait()) for n, child in children]
    except KeyboardInterrupt:
        for _, child in children:
            child.send_signal(signal.SIGINT)
        for _, child in children:
            try:
                child.wait(STOP_WAIT_S)
            except subprocess.TimeoutExpired:
                child.kill()
        raise
    for reader in readers:
        reader.join()
    failed = [(n, code) for n, code in codes if code != 0]
    if not failed:
        print(f"{prog}: instances {wire.instance_ranges(instances)}: all {len(instances)} succeeded")
        return 0
    print(f"{prog}: {len(failed)} of {len(instances)} failed: "
          + ", ".join(f"instance {n} (exit {code})" for n, code in failed), file=sys.stderr)  # fmt: skip
    return failed[0][1] if failed[0][1] > 0 else 1

