"""
Spinning the node: the executor it runs on, and a loop that Ctrl-C and shutdown stop.

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
