"""
The stamp clock's checkpoint, checked: every field of a saved state validated.

Part of :mod:`imu_allan.pipeline.clock`: :meth:`StampClock.restore` takes the values
:func:`check_clock_state` returns, so a damaged checkpoint is one InputError line and
never a clock in an impossible state.
"""

import numpy as np

from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import N_AXES
from imu_allan.pipeline.steps import is_int, number


def check_clock_state(state, keys: set, window: int) -> dict:
    """
    Return a saved stamp clock's state validated and converted.

    Parameters
    ----------
    state : object
        What the checkpoint holds (a dict of :meth:`StampClock.state`).
    keys : set of str
        The fields a state has.
    window : int
        Stamp steps per judged window (the steps in progress are fewer).

    Returns
    -------
    dict
        The fields of ``state``: ``rate_hz`` [Hz], ``jitter_sq`` and ``off_period_ns``
        as floats, ``far`` as None or (stamp_ns, row (6,)), ``last_row`` as an array of
        shape (0 or 1, 6), ``break_next`` as bool, the others as saved.

    Raises
    ------
    InputError
        One line naming the first invalid field.

    """
    if isinstance(state, dict) and 'last_row' not in state:
        # Written before short gaps were filled: no rows to fill from yet.
        state = {**state, 'last_row': [], 'n_rows': 0}
    if not isinstance(state, dict) or set(state) != keys:
        raise InputError('the stamp clock state is incomplete')
    last_row = np.asarray(state['last_row'], dtype=np.float64).reshape(-1, N_AXES)
    if (last_row.shape[0] > 1 or not np.isfinite(last_row).all()
            or not is_int(state['n_rows']) or state['n_rows'] < 0):
        raise InputError('the rows before a short gap are invalid')
    rate = number(state['rate_hz'], 'rate_hz')
    if rate <= 0:
        raise InputError(f'the stamp clock has no rate ({rate!r})')
    for key in ('first_stamp_ns', 'last_stamp_ns', 'newest_stamp_ns'):
        if state[key] is not None and not is_int(state[key]):
            raise InputError(f'the stamp clock field {key} is invalid')
    far = state['far']
    if far is not None:
        if (not isinstance(far, list) or len(far) != 2 or not is_int(far[0])
                or np.asarray(far[1], dtype=np.float64).shape != (N_AXES,)):
            raise InputError('the held far stamp is invalid')
        far = (int(far[0]), np.asarray(far[1], dtype=np.float64))
    steps = state['step_buf']
    if not isinstance(steps, list) or not all(is_int(s) and s > 0 for s in steps):
        raise InputError('the stamp steps in progress are invalid')
    if len(steps) >= window:
        raise InputError('the stamp steps in progress are too many')
    if not all(is_int(state[k]) and state[k] >= 0 for k in ('clock_n', 'clock_ns', 'jitter_n')):
        raise InputError('the stamp step counts are invalid')
    off = state['off_period_ns']
    return {**state, 'rate_hz': rate, 'far': far, 'last_row': last_row,
            'break_next': bool(state['break_next']), 'n_rows': int(state['n_rows']),
            'jitter_sq': number(state['jitter_sq'], 'jitter_sq'),
            'off_period_ns': None if off is None else number(off, 'off_period_ns')}
