"""
The state the parts of a Session share, declared once for readers and type checkers.

:class:`~imu_allan.pipeline.session.Session` is assembled from three mixins, one per
concern: the stamp clock (clock.py), the sample checks (checks.py) and the state file
(session_state.py).  Each reads state the others write; :class:`_Parts` names that state
with its type, and ``Session.__init__`` sets it.  Nothing here runs: the class holds
annotations only.
"""

from __future__ import annotations

from typing import Callable, TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from imu_allan.core.allan.accumulator import AllanAccumulator
    from imu_allan.pipeline.feed import BackgroundAccumulator
    from imu_allan.pipeline.session import HygieneStats, SessionConfig


class _Parts:
    """Attributes and methods one part of a Session uses from another."""

    if TYPE_CHECKING:  # Session's
        def __init__(self, config: SessionConfig = ...,
                     on_warning: Callable[[str], None] | None = None) -> None: ...

    config: SessionConfig
    stats: HygieneStats
    acc: AllanAccumulator | BackgroundAccumulator | None
    rate_hz: float
    first_stamp_ns: int | None
    last_stamp_ns: int | None
    # Warnings (session.py)
    _warn_text: dict[str, str]
    _warn_count: dict[str, int]
    _warn: Callable[..., None]
    _start_accumulator: Callable[[], None]
    # Stamp clock (clock.py)
    _newest_ns: int | None
    _step_buf: list[np.ndarray]
    _clock_n: int
    _clock_ns: int
    _jitter_sq: float
    _jitter_n: int
    _off_period_ns: float | None
    # Sample checks and the motion gate (checks.py)
    _accumulate: Callable[[np.ndarray, np.ndarray], None]
    _flush_motion: Callable[..., None]
    _ref_mean: np.ndarray | None
    _ref_std: np.ndarray | None
    _win_t: list[np.ndarray]
    _win_y: list[np.ndarray]
    _pending: list[np.ndarray]
    _moving: bool
    _in_motion: bool
    _still_since_ns: int | None
    _last_value: np.ndarray
    _repeat: np.ndarray
