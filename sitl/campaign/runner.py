"""Running a campaign: chunks of runs through a ``concurrent.futures.Executor``, rows to disk.

The extension point is the Executor (ARCHITECTURE.md, "Past one vehicle and one machine"):

* ``workers = 1``: in this process (no executor; handy for debugging);
* ``workers = K``: a local :class:`~concurrent.futures.ProcessPoolExecutor` of K processes
  (default: one per core). The kernels are compiled (or loaded from numba's cache) here first,
  so forked workers start with them;
* ``scheduler = "tcp://HOST:PORT"``: a Dask distributed cluster through
  ``Client.get_executor()`` (``quadsitl[cluster]``): ``dask scheduler`` on one machine,
  ``dask worker tcp://HOST:8786`` on the others. A worker that dies mid-task loses nothing: the
  scheduler hands its tasks to another worker and the rows arrive once.

Only this process writes results (workers return rows), so no shared file system is needed.
The table is the same whatever the number of workers or machines: rows depend on (spec, run)
only, and they are sorted by (run, controller) at the end.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from .batch import run_chunk, warm_up
from .results import ResultStore
from .spec import CampaignSpec

DASK_CONNECT_TIMEOUT_S = 30.0


@dataclass(frozen=True)
class CampaignRun:
    """What :func:`run_campaign` did."""

    table: pa.Table
    results_path: Path
    flown_runs: int  # runs flown by this invocation (the others were on disk already)
    skipped_runs: int
    wall_s: float
    warm_up_s: float  # kernel compilation or cache load in this process
    executor: str


def chunks(runs: Sequence[int], size: int) -> list[list[int]]:
    """Consecutive groups of at most ``size`` runs (the tasks)."""
    ordered = sorted(runs)
    return [ordered[i : i + size] for i in range(0, len(ordered), size)]


@contextlib.contextmanager
def make_executor(workers: int | None = None, scheduler: str | None = None) -> Iterator[Executor | None]:
    """The campaign's Executor: local processes, a Dask cluster, or None (in this process)."""
    if scheduler:
        try:
            from distributed import Client
        except ImportError:
            raise RuntimeError(
                "--scheduler needs Dask distributed: pip install 'quadsitl[cluster]' (dask[distributed])"
            ) from None
        client = Client(scheduler, timeout=DASK_CONNECT_TIMEOUT_S)
        try:
            # pure=False: every chunk is its own task, never deduplicated by argument hashing.
            executor = client.get_executor(pure=False)
            yield executor
            executor.shutdown(wait=False)
        finally:
            client.close()
        return
    count = workers if workers is not None else (os.cpu_count() or 1)
    if count <= 1:
        yield None
        return
    pool = ProcessPoolExecutor(max_workers=count)
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _progress(total: int, initial: int, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, initial=initial, unit="run", desc="campaign", file=sys.stderr, smoothing=0.1)


def run_campaign(
    spec: CampaignSpec,
    out_dir: str | Path,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    on_chunk: Callable[[int, int], None] | None = None,
    executor: Executor | None = None,
) -> CampaignRun:
    """Fly every run of ``spec`` not yet in ``out_dir`` and write ``results.parquet``.

    ``on_chunk(done, total)`` is called after each chunk is on disk (runs done so far). An
    ``executor`` given here is used as is (and not shut down); otherwise one is made from
    ``workers`` / ``scheduler``.
    """
    store = ResultStore(out_dir, spec)
    done = {r for r in store.done_runs() if r < spec.runs}
    missing = [r for r in range(spec.runs) if r not in done]
    tasks = chunks(missing, spec.chunk_runs)
    started = time.perf_counter()
    # Compile (or load) the kernels here for local work: forked workers inherit them, and a
    # compile error shows up once, before any task is sent. Dask workers compile their own.
    local = executor is None and not scheduler
    warm = warm_up(spec) if missing and local else 0.0
    bar = _progress(spec.runs, len(done), progress)
    finished = len(done)
    kind = "in-process"

    def persist(rows, count: int) -> None:
        nonlocal finished
        store.append(rows)
        finished += count
        if bar is not None:
            bar.update(count)
        if on_chunk is not None:
            on_chunk(finished, spec.runs)

    try:
        if tasks:
            context = (
                contextlib.nullcontext(executor)
                if executor is not None
                else make_executor(workers, scheduler)
            )
            with context as ex:
                if ex is None:
                    for task in tasks:
                        persist(run_chunk(spec, task), len(task))
                else:
                    kind = type(ex).__name__
                    futures: dict[Future, list[int]] = {
                        ex.submit(run_chunk, spec, task): task for task in tasks
                    }
                    try:
                        for future in as_completed(futures):
                            persist(future.result(), len(futures[future]))
                    except BaseException:
                        for future in futures:
                            future.cancel()
                        raise
    finally:
        if bar is not None:
            bar.close()
    path = store.write_results()
    return CampaignRun(
        table=store.table(),
        results_path=path,
        flown_runs=len(missing),
        skipped_runs=len(done),
        wall_s=time.perf_counter() - started,
        warm_up_s=warm,
        executor=kind,
    )
