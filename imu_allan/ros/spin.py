"""
Spinning the node: its executor, a loop Ctrl-C and shutdown stop, work they cut short.

rclpy's EventsExecutor is several times cheaper per message (bench/bench_node.py), but
its spin() never returns to Python; short spin_once calls let Ctrl-C and shutdown in.
"""

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor


def create_executor(kind: str = 'events', context=None):
    """
    Return the executor the node spins with.

    Parameters
    ----------
    kind : str
        'events' (rclpy.experimental.EventsExecutor, the default: the cheapest per
        message), 'single' (SingleThreadedExecutor) or 'multi' (MultiThreadedExecutor
        with two threads; kept for benchmarks).
    context : rclpy.context.Context, optional
        Context of the executor.

    Returns
    -------
    Executor
        The executor; 'events' falls back to 'single' where it is unavailable.

    """
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            kind = 'single'
        else:
            return EventsExecutor(context=context)
    if kind == 'multi':
        from rclpy.executors import MultiThreadedExecutor
        return MultiThreadedExecutor(num_threads=2, context=context)
    return SingleThreadedExecutor(context=context)


def spin_until_shutdown(executor, context=None) -> None:
    """
    Spin until the context shuts down (Ctrl-C, SIGTERM or rclpy.shutdown).

    rclpy's EventsExecutor.spin() runs in C++ and never returns to Python, so neither
    a Ctrl-C nor a shutdown stops it; short spin_once calls let Python see both.

    Parameters
    ----------
    executor : Executor
        The executor with the node added.
    context : rclpy.context.Context, optional
        The context to watch (the default context when None).

    """
    context = context or rclpy.get_default_context()
    try:
        while context.ok():
            executor.spin_once(timeout_sec=0.25)
    except ExternalShutdownException:
        pass


def until_shutdown(context, work, *args) -> None:
    """
    Run work (a fit on its own thread); a shutdown while it runs ends it without a traceback.

    SIGTERM or Ctrl-C shuts the context down while a fit runs; its publishers are gone
    then (rcl raises "publisher's context is invalid"), and the node's save() writes the
    files from the result the fit kept.

    Parameters
    ----------
    context : rclpy.context.Context
        The node's context.
    work : callable
        Called with ``args``; its errors are raised while the context is up.

    """
    try:
        work(*args)
    except Exception:  # noqa: B902 - rcl's error types are private to rclpy
        if context.ok():
            raise
