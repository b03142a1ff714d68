"""
The worker processes of one offline analysis: the axes' searches and the figures.

The search is pure Python and numpy on tiny matrices (GIL-bound), and so is drawing
with matplotlib: both run in processes, not threads.  The processes fork from one
server process that imported the package once (forking a process with threads, the
reader and the progress line, can deadlock the child).  This module imports nothing
heavy itself, so the server can be started before the input is read and its start-up
overlaps the reading.
"""

import atexit
from concurrent.futures import ProcessPoolExecutor
import ctypes
import multiprocessing
import os
import signal
from typing import Iterable

#: Modules every server imports before it forks workers: the search and its scipy.
_PRELOAD = ('imu_allan.pipeline.analysis', 'imu_allan.core.search')
#: glibc's heap settings for a long offline job (bytes): blocks below this stay on the
#: heap, and the heap keeps this much freed memory (mallopt M_MMAP_THRESHOLD = -3,
#: M_TRIM_THRESHOLD = -1; the environment variables set them in a new process).
HEAP_KEEP_BYTES = 1 << 28
HEAP_ENV = ('MALLOC_MMAP_THRESHOLD_', 'MALLOC_TRIM_THRESHOLD_')
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


def keep_large_blocks() -> None:
    """
    Let this process and the workers it starts reuse freed large blocks (glibc only).

    By default glibc serves every block above a threshold (128 KiB at first) with a
    fresh mmap and trims freed heap at once: each of the stream's many large numpy
    temporaries then page-faults anew.  Keeping up to 256 MiB saves about 0.3 s of the
    3 h bag's 6 s; a process that is not on glibc keeps its defaults.
    """
    for name in HEAP_ENV:       # the fork server and its workers, started later
        os.environ.setdefault(name, str(HEAP_KEEP_BYTES))
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt(_M_TRIM_THRESHOLD, HEAP_KEEP_BYTES)
    mallopt(_M_MMAP_THRESHOLD, HEAP_KEEP_BYTES)


def one_blas_thread() -> None:
    """
    Hold OpenBLAS to one thread in this process and in the workers it starts.

    An offline analysis runs its own threads (reader, accumulator) and worker processes
    on every core; OpenBLAS's pool of one thread per core only oversubscribes them
    (measured: the 3 h bag's analysis 0.2 s faster of 3.2 s, bench/bench_analyze.py).
    The environment reaches the libraries loaded later (the fork server's, the workers'
    and this process's own when numpy is not imported yet); a user's setting is kept.
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
    atexit.unregister(_end_server)      # registered once, however often it is started
    atexit.register(_end_server)


def _end_server() -> None:
    """
    End the fork server at once when this process exits (registered at its start).

    The server inherits this process's stdout and stderr, so a reader of them (a pipe
    into ``jq``, a test harness) sees their end only when the server is gone too.  Left
    to notice the exit itself, it would first tear down scipy, matplotlib and the rest
    (0.12-0.18 s after the command is done); it holds nothing that needs an orderly end
    (no files, no output, its workers already shut down with their pools).
    """
    from multiprocessing import forkserver
    pid = getattr(forkserver._forkserver, '_forkserver_pid', None)
    if pid:
        try:
            os.kill(pid, signal.SIGTERM)
        except OSError:     # already gone
            pass


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
