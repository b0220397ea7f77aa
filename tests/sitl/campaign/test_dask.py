"""Past one machine: a real Dask scheduler and two real workers, as processes on 127.0.0.1.

The campaign goes through ``Client.get_executor()`` (``--scheduler tcp://HOST:PORT``) and its
table must equal the local run's; a worker killed with SIGKILL while it flies a chunk loses no
result: the scheduler gives that chunk to the other worker.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("numba")
distributed = pytest.importorskip("distributed")

from sitl.campaign.results import tables_equal  # noqa: E402
from sitl.campaign.runner import run_campaign  # noqa: E402
from sitl.campaign.spec import load_campaign  # noqa: E402

from . import specs  # noqa: E402

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

DASK = str(Path(sys.executable).with_name("dask"))
START_TIMEOUT_S = 90.0


class Cluster:
    """``dask scheduler`` + ``dask worker`` x N, loopback only, no dashboard, no nanny."""

    def __init__(self, tmp_path: Path, workers: int = 2) -> None:
        self.dir = tmp_path
        self.file = tmp_path / "scheduler.json"
        self.procs: list[subprocess.Popen] = []
        self.workers: dict[str, subprocess.Popen] = {}
        self.count = workers

    def __enter__(self) -> "Cluster":
        log = open(self.dir / "scheduler.log", "w")  # noqa: SIM115 (closed with the process)
        self.procs.append(
            subprocess.Popen(
                [DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                 "--scheduler-file", str(self.file)],
                stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
            )
        )  # fmt: skip
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self.file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert self.file.exists(), (self.dir / "scheduler.log").read_text()
        self.address = json.loads(self.file.read_text())["address"]
        assert self.address.startswith("tcp://127.0.0.1:")
        for i in range(self.count):
            name = f"w{i}"
            log = open(self.dir / f"{name}.log", "w")  # noqa: SIM115
            proc = subprocess.Popen(
                [DASK, "worker", self.address, "--host", "127.0.0.1", "--no-dashboard", "--no-nanny",
                 "--nthreads", "1", "--name", name, "--death-timeout", "60",
                 "--local-directory", str(self.dir / name)],
                stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
            )  # fmt: skip
            self.procs.append(proc)
            self.workers[name] = proc
        with distributed.Client(self.address, timeout=30) as client:
            client.wait_for_workers(self.count, timeout=START_TIMEOUT_S)
        return self

    def __exit__(self, *exc) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.terminate()
        for proc in self.procs:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)


@pytest.mark.timeout(600)
def test_dask_cluster_gives_the_local_table_even_when_a_worker_dies(tmp_path):
    # 40 s flights, 8 runs per chunk: a chunk takes about a second, long enough to be killed in.
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box", chunk=8, duration=40.0))
    from dataclasses import replace

    spec = replace(spec, runs=32)
    # The reference in this process (a local pool gives the same table: test_runner.py).
    local = run_campaign(spec, tmp_path / "local", workers=1, progress=False)

    with Cluster(tmp_path) as cluster:
        # One campaign on the cluster, a worker killed in its first chunk: the table is the local one
        # all the same (the chunks the kill did not touch are the clean case).
        killed: list[str] = []

        def kill_a_busy_worker(done: int, total: int) -> None:
            if killed:
                return
            with distributed.Client(cluster.address, timeout=30) as client:
                info = client.scheduler_info()["workers"]
                busy = [addr for addr, keys in client.processing().items() if keys]
                for addr in busy:
                    name = info[addr]["name"]
                    proc = cluster.workers.get(name)
                    if proc is not None and proc.poll() is None:
                        os.kill(proc.pid, signal.SIGKILL)
                        proc.wait(timeout=10)
                        killed.append(name)
                        return

        survived = run_campaign(
            spec,
            tmp_path / "dask_kill",
            scheduler=cluster.address,
            progress=False,
            on_chunk=kill_a_busy_worker,
        )
        assert survived.executor == "ClientExecutor"
        assert killed, "no worker was busy when the first chunk came back"
        assert cluster.workers[killed[0]].returncode == -signal.SIGKILL
        assert survived.table.num_rows == spec.runs * len(spec.controllers)
        assert tables_equal(survived.table, local.table)
