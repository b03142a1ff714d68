"""
A fleet run on Dask: key the inputs, skip those done, analyse the rest, store each result.

The scheduling is Dask's (dask.distributed), not ours: a ``LocalCluster`` of single-
threaded worker processes by default, or any running cluster given by its scheduler
address.  Per input:

1. its content key (SHA-256 of the file), computed on the workers, remembered in the
   store by size and mtime so a re-run does not hash again;
2. skipped when the store already holds that key (failures too, unless
   ``retry_failed``); two inputs with the same content are analysed once;
3. :func:`imu_allan.fleet.task.analyze_job` on a worker, submitted under a key derived
   from the content key, so Dask never runs the same input twice at once;
4. the rows written to the store by this process as each result arrives.

A worker that dies mid-run (out of memory, a killed node) has its inputs rescheduled by
Dask; an input that has killed ``distributed.scheduler.allowed-failures`` workers is
stored as failed with that reason.
"""

import hashlib
import os
from pathlib import Path
import time
from typing import Callable, NamedTuple

from imu_allan.errors import InputError
from imu_allan.fleet.inputs import content_key, FleetInput, stat_key
from imu_allan.fleet.store import FleetStore
from imu_allan.fleet.task import analyze_job, failed_rows, FleetJob
from imu_allan.pipeline.hygiene import SessionConfig

#: glibc's heap settings (bytes): blocks below this stay on the heap, and the heap keeps
#: this much freed memory (the environment's names for mallopt M_MMAP_THRESHOLD and
#: M_TRIM_THRESHOLD).
HEAP_KEEP_BYTES = 1 << 28
HEAP_ENV = ('MALLOC_MMAP_THRESHOLD_', 'MALLOC_TRIM_THRESHOLD_')
#: Set in every local worker before it starts.  Dask sets MALLOC_TRIM_THRESHOLD_, and any
#: malloc variable freezes glibc's mmap threshold at 128 KiB: every large numpy temporary
#: is then a fresh mmap and page-faults anew, which made each analysis slower in a worker
#: than in a plain process (bench/bench_fleet.py, docs/benchmarks.md).  Large blocks stay
#: on the heap, and the heap is trimmed only above 256 MiB: Dask's 64 KiB handed the freed
#: top of the heap back after every large temporary, so the next one page-faulted again
#: (a worker's peak stays about 0.3 GB).
#: The statistical profiler (its periodic stack samples) is off, and the event loop's
#: watchdog tick and monitors run rarely: each wake-up takes the GIL from the analysis.
WORKER_CONFIG = {**{f'distributed.nanny.pre-spawn-environ.{name}': HEAP_KEEP_BYTES
                    for name in HEAP_ENV},
                 'distributed.worker.profile.enabled': False,
                 'distributed.admin.tick.interval': '1s',
                 'distributed.admin.system-monitor.interval': '2s',
                 'distributed.worker.memory.monitor-interval': '1s'}


class FleetSummary(NamedTuple):
    """What a run did: counts of inputs analysed, failed, skipped and duplicated."""

    n_inputs: int
    n_ok: int
    n_failed: int
    n_skipped: int
    n_duplicates: int
    wall_s: float
    keys_s: float
    cpu_s: float
    n_messages: int


def _dask():
    try:
        from dask.distributed import as_completed, Client, LocalCluster
    except ImportError:
        raise InputError('fleet runs need Dask: pip install imu_allan[fleet]') from None
    return as_completed, Client, LocalCluster


def _warm_up() -> None:
    """Import the pipeline and the search in a worker before its first input (a second)."""
    import imu_allan.core.search  # noqa: F401
    import imu_allan.io.inputs  # noqa: F401
    import imu_allan.pipeline.analysis  # noqa: F401


def connect(scheduler: str | None = None, n_workers: int | None = None,
            memory_limit: str = 'auto'):
    """
    Return (client, cluster or None): to ``scheduler``, else to a new LocalCluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``).
    n_workers : int, optional
        Worker processes of the local cluster (default: the number of cores).
    memory_limit : str
        Memory per local worker (Dask's format, e.g. '2GiB').

    """
    _, client_cls, cluster_cls = _dask()
    import dask

    try:
        if scheduler:
            return client_cls(scheduler, timeout='30s'), None
        with dask.config.set(WORKER_CONFIG):
            cluster = cluster_cls(n_workers=n_workers or os.cpu_count() or 1,
                                  threads_per_worker=1, processes=True,
                                  memory_limit=memory_limit, dashboard_address=':0')
        client = client_cls(cluster)
        client.run(_warm_up)
        return client, cluster
    except (OSError, TimeoutError) as exc:
        raise InputError(f'cannot reach the Dask scheduler {scheduler or "(local)"}: '
                         f'{exc}') from None


def _keys(client, inputs: list[FleetInput], store: FleetStore) -> dict[str, str | Exception]:
    """Content key of every input (cached ones from the store, the others on workers)."""
    keys: dict[str, str | Exception] = {}
    signatures: dict[str, str] = {}
    for inp in inputs:
        try:
            signatures[inp.path] = stat_key(inp.path)
        except OSError as exc:
            keys[inp.path] = InputError(f'{inp.path}: cannot read it ({exc.strerror})')
            continue
        cached = store.cached_key(signatures[inp.path])
        if cached:
            keys[inp.path] = cached
    todo = [inp.path for inp in inputs if inp.path not in keys]
    futures = client.map(content_key, todo, pure=False)
    new = {}
    for path, fut in zip(todo, futures):
        try:
            keys[path] = new[signatures[path]] = fut.result()
        except InputError as exc:
            keys[path] = exc
        except Exception as exc:  # noqa: B902 - a worker lost while hashing: one line
            keys[path] = InputError(f'{path}: not hashed ({type(exc).__name__}: {exc})'
                                    .splitlines()[0])
    if new:
        store.remember_keys(new)
    return keys


def run_fleet(inputs: list[FleetInput], store: FleetStore, client,
              config: SessionConfig = SessionConfig(), topic: str | None = None,
              retry_failed: bool = False,
              on_record: Callable[[str, str, list], None] | None = None) -> FleetSummary:
    """
    Analyse every input not yet in the store on a Dask cluster; store each result.

    Parameters
    ----------
    inputs : list of FleetInput
        The inputs (:func:`imu_allan.fleet.inputs.fleet_inputs`).
    store : FleetStore
        Where results go.
    client : dask.distributed.Client
        A connected client (:func:`connect`).
    config : SessionConfig
        Input checks and accumulator settings, as for ``imu-allan analyze``.
    topic : str, optional
        Imu topic of the bags (default: each bag's only one).
    retry_failed : bool
        Analyse inputs stored as failed again.
    on_record : callable, optional
        Called with (key, status, rows) after each stored result.

    Returns
    -------
    FleetSummary

    """
    as_completed, _, _ = _dask()
    start = time.monotonic()
    keys = _keys(client, inputs, store)
    keys_s = time.monotonic() - start
    done = store.done()
    jobs: dict[str, FleetJob] = {}
    n_skipped = n_dup = n_failed = n_ok = 0
    for inp in inputs:
        key = keys[inp.path]
        if isinstance(key, Exception):   # unreadable: stored under a key of its path
            path_key = hashlib.sha256(inp.path.encode()).hexdigest()[:32]
            job = FleetJob(inp.path, f'path-{path_key}', inp.imu_id, inp.model, topic, config)
            store.write(job.key, 'failed', failed_rows(job, str(key)))
            n_failed += 1
            continue
        status = done.get(key)
        if status == 'ok' or (status == 'failed' and not retry_failed):
            n_skipped += 1
        elif key in jobs:
            n_dup += 1
        else:
            jobs[key] = FleetJob(inp.path, key, inp.imu_id, inp.model, topic, config)
    # Largest first: the last inputs to finish are then short ones, and no worker idles
    # long at the end (longest-processing-time-first).
    order = sorted(jobs, key=lambda k: -_size(jobs[k].path))
    futures = {client.submit(analyze_job, jobs[key], key=f'imu-allan-fleet-{key}', pure=False,
                             retries=1): key for key in order}
    cpu_s, n_messages = 0.0, 0
    for fut in as_completed(list(futures)):
        key = futures[fut]
        try:
            _, status, rows = fut.result()
        except Exception as exc:  # noqa: B902 - KilledWorker, lost scheduler: one line each
            status, rows = 'failed', failed_rows(
                jobs[key], f'{jobs[key].path}: {type(exc).__name__}: {exc}'.splitlines()[0])
        store.write(key, status, rows)
        n_ok += status == 'ok'
        n_failed += status == 'failed'
        if status == 'ok':
            cpu_s += rows[0]['cpu_s']
            n_messages += rows[0]['n_samples']
        if on_record is not None:
            on_record(key, status, rows)
        fut.release()
    return FleetSummary(len(inputs), n_ok, n_failed, n_skipped, n_dup,
                        time.monotonic() - start, keys_s, cpu_s, n_messages)


def _size(path: str) -> int:
    p = Path(path)
    try:
        return sum(f.stat().st_size for f in p.rglob('*') if f.is_file()) if p.is_dir() \
            else p.stat().st_size
    except OSError:
        return 0
