"""
The worker processes of one offline analysis: the axes' searches and the figures.

The search is pure Python and numpy on tiny matrices (GIL-bound), and so is drawing
with matplotlib: both run in processes, not threads.  The processes fork from one
server process that imported the package once (forking a process with threads, the
reader and the progress line, can deadlock the child).  This module imports nothing
heavy itself, so the server can be started before the input is read and its start-up
overlaps the reading.
"""

from concurrent.futures import ProcessPoolExecutor
import multiprocessing
import os
from typing import Iterable

#: Modules every server imports before it forks workers: the search and its scipy.
_PRELOAD = ('imu_allan.pipeline.analysis', 'imu_allan.core.search')


def one_blas_thread() -> None:
    """
    Hold OpenBLAS to one thread in this process and in the processes it starts.

    The fits, searches and plans work on matrices of a few tens of rows, and an offline
    analysis already runs its own threads and worker processes on every core:
    OpenBLAS's pool of one thread per core would only oversubscribe them.  OpenBLAS
    reads the variable when it is loaded, so the entry points (the CLI, the node) call
    this before numpy is imported; a user's own setting is kept.
    """
    os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')


def available() -> bool:
    """Tell whether worker processes can be had (POSIX fork server; not on Windows)."""
    return 'forkserver' in multiprocessing.get_all_start_methods()


def start_workers(preload: Iterable[str] = ()) -> None:
    """
    Start the fork server now, in the background, with its modules imported.

    Parameters
    ----------
    preload : iterable of str
        Further modules the server imports (the adapters' own, e.g. the plot warm-up);
        they count only when the server is not running yet.

    """
    if not available():
        return
    ctx = multiprocessing.get_context('forkserver')
    ctx.set_forkserver_preload(list(dict.fromkeys(_PRELOAD + tuple(preload))))
    from multiprocessing import forkserver
    forkserver.ensure_running()


def worker_pool(workers: int) -> ProcessPoolExecutor | None:
    """
    Return a pool of ``workers`` processes forked from the server, or None.

    None when ``workers`` < 2 or no fork server exists: the caller then does the work
    itself.  The caller shuts the pool down (use it in a ``with``).
    """
    if workers < 2 or not available():
        return None
    start_workers()
    return ProcessPoolExecutor(max_workers=workers,
                               mp_context=multiprocessing.get_context('forkserver'))
