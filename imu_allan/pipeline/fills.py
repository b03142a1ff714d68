"""
Rows that stand in for lost samples: made by the stamp clock, found by the feed.

A short gap in the stamps (at most ``SessionConfig.max_fill_samples`` lost samples)
does not end the segment: the stamp clock fills it by linear interpolation between
its neighbours, so the sample gate sees an even stream, and the accumulator is told
which rows are filled (it leaves the terms over them out at short taus and takes the
fills' known white-noise excess off the others, :mod:`imu_allan.core.allan.accumulator`).
The gate passes rows on by value only, so a filled row carries its mark in its values:
the low 24 bits of each value's mantissa hold :data:`TAG` (a change below 4e-9 of the
value, far below any sensor's resolution).  A row is a fill when at least two of its
values carry the tag.  An axis whose two neighbours are equal keeps their value
untagged, so a held value stays one run for the frozen-axis check (a quantised
accelerometer repeats its neighbours often), unless that would leave fewer than two
tags; a row is missed only when all six axes repeat their neighbours.  Real samples
come from float32 (the low 29 bits zero: never tagged), from decimal text or from
float64 arithmetic, where one value ends in the tag by chance with a probability of
about 6e-8: one tag alone would mark about one row in 3 M as a fill (a 3 h, 400 Hz
record lost about two rows that way), two tags one row in about 1e13.
"""

import numpy as np

#: The low mantissa bits of a filled value.
TAG = 0xA5C3E1
_LOW = np.uint64(0xFFFFFF)
#: The tagged values that make a row a fill (see the module docstring).
MIN_TAGS = 2


def fill_rows(left: np.ndarray, right: np.ndarray, k: np.ndarray) -> np.ndarray:
    """
    Rows filling gaps by linear interpolation, tagged as fills.

    Parameters
    ----------
    left, right : numpy.ndarray
        Shape (g, n_axes), the rows before and after each gap [unit]; an axis whose
        two neighbours are equal keeps their value untagged (a held value stays one
        run for the frozen-axis check) unless the row would carry fewer than
        :data:`MIN_TAGS` tags.
    k : numpy.ndarray
        Shape (g,), int, samples lost in each gap (>= 1).

    Returns
    -------
    numpy.ndarray
        Shape (sum(k), n_axes), the fills of gap 0, then gap 1 ... [unit].

    """
    gap = np.repeat(np.arange(k.size), k)
    step = np.arange(gap.size) - np.repeat(np.cumsum(k) - k, k) + 1
    a, b = left[gap], right[gap]
    rows = np.ascontiguousarray(a + (b - a) * (step / (k[gap] + 1.0))[:, None])
    tagged = as_fills(rows)
    tag = a != b
    # A row that moved on one axis only takes its further tags on the held axes.
    few = np.flatnonzero(tag.any(axis=1) & (tag.sum(axis=1) < MIN_TAGS))
    if few.size:
        # One tag is there: the first MIN_TAGS - 1 held axes take the others.
        order = np.argsort(tag[few], axis=1, kind='stable')
        tag[few[:, None], order[:, :MIN_TAGS - 1]] = True
    return np.where(tag, tagged, rows)


def as_fills(rows: np.ndarray) -> np.ndarray:
    """
    Return rows with every value marked as a fill (the tag in its low mantissa bits).

    Parameters
    ----------
    rows : numpy.ndarray
        Shape (n, n_axes), float64 values that stand in for lost samples [unit].

    Returns
    -------
    numpy.ndarray
        Shape (n, n_axes), the values changed by less than 4e-9 of each [unit].

    """
    y = np.ascontiguousarray(rows, dtype=np.float64)
    return ((y.view(np.uint64) & ~_LOW) | np.uint64(TAG)).view(np.float64)


def fill_run(stamp_ns: np.ndarray, samples: np.ndarray, last_row: np.ndarray,
             at: np.ndarray, lost: np.ndarray, steps_at: np.ndarray) -> tuple:
    """
    Return a run of rows with its short gaps filled: (stamp_ns (m,), samples (m, 6)).

    Parameters
    ----------
    stamp_ns, samples : numpy.ndarray
        Shapes (n,) and (n, 6): the run's rows [ns], [unit].
    last_row : numpy.ndarray
        Shape (0 or 1, 6): the row passed on before the run (a gap before row 0 is
        filled from it).
    at : numpy.ndarray
        Shape (g,), the rows each short gap lies before.
    lost, steps_at : numpy.ndarray
        Shape (g,), samples lost in each, and its stamp step [ns].

    """
    if not at.size:
        return stamp_ns, samples
    h = last_row.shape[0]
    rows = np.concatenate((last_row, samples)) if h else samples
    fills = fill_rows(rows[at + h - 1], samples[at], lost)
    prev_t = stamp_ns[at] - steps_at
    gap = np.repeat(np.arange(at.size), lost)
    step = np.arange(gap.size) - np.repeat(np.cumsum(lost) - lost, lost) + 1
    t_fill = prev_t[gap] + np.round((stamp_ns[at[gap]] - prev_t[gap]) * step
                                    / (lost[gap] + 1.0)).astype(np.int64)
    where = np.repeat(at, lost)
    return np.insert(stamp_ns, where, t_fill), np.insert(samples, where, fills, axis=0)


def missing_line(stats, n_rows: int, max_fill: int) -> str:
    """
    Return the one warning line on missing samples, with the share so far.

    Parameters
    ----------
    stats : imu_allan.pipeline.hygiene.HygieneStats
        Its gap counts.
    n_rows : int
        Real rows that reached the gap search.
    max_fill : int
        ``SessionConfig.max_fill_samples``.

    """
    s = stats
    share = s.n_missing / max(n_rows + s.n_missing, 1)
    n_long = s.n_gaps - s.n_short_gaps
    return (f'{100 * share:.1f} % of samples missing ({s.n_missing:,} in {s.n_gaps:,} gaps): '
            f'{s.n_short_gaps:,} short gaps of up to {max_fill} samples filled (no Allan '
            f'term at short taus uses a filled sample), {n_long:,} long '
            f'gap{"s" if n_long != 1 else ""} split the record')


def filled(samples: np.ndarray) -> np.ndarray | None:
    """
    Tell which rows are fills (see the module docstring).

    Parameters
    ----------
    samples : numpy.ndarray
        Shape (n, n_axes), float64 rows.

    Returns
    -------
    numpy.ndarray or None
        Shape (n,), bool; None when no row is a fill.

    """
    y = np.ascontiguousarray(samples, dtype=np.float64)
    marks = (y.view(np.uint64) & _LOW) == np.uint64(TAG)
    fill = marks.sum(axis=1) >= min(MIN_TAGS, marks.shape[1])
    return fill if fill.any() else None
