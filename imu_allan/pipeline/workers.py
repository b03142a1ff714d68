"""
The worker processes of one offline analysis: the axes' searches and the figures.

The search is pure Python and numpy on tiny matrices (GIL-bound), and so is drawing
with matplotlib: both run in processes, not threads.  The processes fork from one
server process that imported the package once (forking a process with threads, the
reader and the progress line, can deadlock the child).  This module imports nothing
heavy itself, so the server can be started before the input is read and its start-up
overlaps the reading.

Ctrl-C: the server and its workers block SIGINT (a terminal sends it to the whole
process group), so only this process is interrupted; a pool left by an exception
terminates its workers instead of waiting for their jobs, and :func:`stop_workers`
ends the server.
"""

from concurrent.futures import ProcessPoolExecutor
import multiprocessing
import os
import signal
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
    from multiprocessing import forkserver, resource_tracker
    # The server starts with SIGINT blocked (the mask survives its exec) and passes the
    # mask on to the workers it forks: a Ctrl-C, which a terminal sends to the whole
    # process group, then interrupts this process alone (one line, not a traceback per
    # process), and it ends the workers itself (WorkerPool).  Blocked here, not
    # ignored: a Ctrl-C meanwhile is delivered to this process afterwards.  The resource
    # tracker first: starting it unblocks SIGINT.
    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        forkserver.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def stop_workers() -> None:
    """
    End the fork server this process started, for a process that is being interrupted.

    The server may still be importing its modules (seconds), or owe a worker to a pool
    whose start a Ctrl-C cut short: that worker would find the pool's queues gone and
    print a traceback.  The workers of a pool end with their :class:`WorkerPool`.
    """
    from multiprocessing import forkserver
    # The standard library keeps the server's process id in a private attribute and
    # offers no way to stop the server.
    pid = getattr(getattr(forkserver, '_forkserver', None), '_forkserver_pid', None)
    if pid:
        try:
            os.kill(pid, signal.SIGTERM)
        except OSError:
            pass


class WorkerPool(ProcessPoolExecutor):
    """
    A process pool whose ``with`` block, left by an exception, terminates the workers.

    The standard pool waits for the running jobs (an axis search, seconds) before an
    exception, such as a Ctrl-C's KeyboardInterrupt, goes on; their results are not
    wanted then.
    """

    def __exit__(self, exc_type, exc_val, exc_tb):
        if exc_type is not None:
            self.terminate_workers()
        return super().__exit__(exc_type, exc_val, exc_tb)

    def terminate_workers(self) -> None:
        """Cancel the queued jobs and terminate the worker processes now."""
        processes = list((self._processes or {}).values())
        self.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.terminate()
        for process in processes:
            process.join()


def worker_pool(workers: int) -> WorkerPool | None:
    """
    Return a pool of ``workers`` processes forked from the server, or None.

    None when ``workers`` < 2 or no fork server exists: the caller then does the work
    itself.  The caller shuts the pool down (use it in a ``with``).
    """
    if workers < 2 or not available():
        return None
    start_workers()
    return WorkerPool(max_workers=workers, mp_context=multiprocessing.get_context('forkserver'))
