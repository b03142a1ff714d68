"""
The state of an :class:`~imu_allan.core.allan.accumulator.AllanAccumulator` in memory and on disk.

:meth:`_Persistence.to_state` / :meth:`_Persistence.from_state` give the state as JSON-able
metadata plus named arrays (what the pipeline's checkpoints embed); :meth:`~_Persistence.save`
and :meth:`~_Persistence.load` write and read it as one .npz file.  Loading checks every
shape, counter and value, so a corrupt or foreign file is an InputError, not a wrong curve.
"""

import json
import math
from pathlib import Path
from typing import Self, TYPE_CHECKING

import numpy as np

from imu_allan.atomic import write_atomic
from imu_allan.core.allan.stretches import StretchSums
from imu_allan.errors import InputError

STATE_FORMAT = 'imu_allan.core.accumulator'
STATE_VERSION = 1
#: Arrays of the missing samples (absent from states written before they were known).
_MISSING_KEYS = ('miss', 'dirty_sums', 'dirty_counts')
#: Arrays of the stretches (absent from states written before they were kept).
_STRETCH_KEYS = ('stretch_sums', 'stretch_counts', 'stretch_rows')


# Long because from_state checks every field of a state it did not write: a corrupt
# checkpoint must be an InputError, never a wrong curve.
class _Persistence:
    """Save, load and in-memory state of the accumulator (mixed into AllanAccumulator)."""

    if TYPE_CHECKING:  # provided by AllanAccumulator
        def __init__(self, n_axes: int, rate_hz: float, exact_max_m: int = 8192,
                     per_decade: int = 10) -> None: ...

        def _flush(self) -> None: ...

        stretch_sums: StretchSums

    def _copy(self) -> Self:
        new = type(self)(self.n_axes, self.rate_hz, self.exact_max_m, self.per_decade)
        new._set_state(*self.to_state())
        return new

    def to_state(self) -> tuple[dict, dict]:
        """
        Return the whole state in memory: JSON-able metadata and named arrays.

        Returns
        -------
        meta : dict
            Settings, counters and the format version (JSON-able).
        arrays : dict of str to np.ndarray
            Copies of the sums, counts, history and reference values.

        """
        meta = {
            'format': STATE_FORMAT, 'version': STATE_VERSION, 'n_axes': self.n_axes,
            'rate_hz': self.rate_hz, 'exact_max_m': self.exact_max_m,
            'per_decade': self.per_decade, 'n_samples': self._n_samples,
            'n_segments': self._n_segments, 'seg_n': self._seg_n, 'h0': self._h0,
            'pending': self._pending, 'ref_set': self._ref_set,
            'level_h': [lv.h for lv in self._levels],
            'level_n': [lv.n for lv in self._levels],
            'n_missing': self._n_missing, 'fill_excess': self._fill_excess,
            'miss_run': self._miss_run,
        }
        stretch_meta, stretch_arrays = self.stretch_sums.state()
        meta.update(stretch_meta)
        arrays = {
            'buf': self._buf[:, :self._h0 + self._pending].copy(),
            'ref': self._ref.copy(),
            'level_hist': np.stack([lv.hist for lv in self._levels]),
            'sums': self._sums.copy(), 'counts': self._counts.copy(), 'm': self._m.copy(),
            'miss': self._miss[:self._h0 + self._pending].copy(),
            'dirty_sums': self._dirty_sums.copy(), 'dirty_counts': self._dirty_counts.copy(),
            **stretch_arrays,
        }
        return meta, arrays

    def _set_state(self, meta: dict, arrays: dict) -> None:
        w = meta['h0'] + meta['pending']
        self._buf[:, :w] = arrays['buf']
        self._ref = arrays['ref'].astype(float)
        self._sums = arrays['sums'].astype(float)
        self._counts = arrays['counts'].astype(np.int64)
        # States written before missing samples were known have none.
        if 'miss' in arrays:
            self._miss[:w] = arrays['miss']
            self._dirty_sums = arrays['dirty_sums'].astype(float)
            self._dirty_counts = arrays['dirty_counts'].astype(np.int64)
        self._n_missing = int(meta.get('n_missing', 0))
        self._fill_excess = float(meta.get('fill_excess', 0.0))
        self._miss_run = int(meta.get('miss_run', 0))
        for lv, hist, h, n in zip(self._levels, arrays['level_hist'], meta['level_h'],
                                  meta['level_n']):
            lv.hist[...] = hist
            lv.h, lv.n = int(h), int(n)
        self._n_samples, self._n_segments = int(meta['n_samples']), int(meta['n_segments'])
        self._seg_n, self._h0 = int(meta['seg_n']), int(meta['h0'])
        self._pending, self._ref_set = int(meta['pending']), bool(meta['ref_set'])
        self.stretch_sums.restore(meta, arrays)

    def save(self, path) -> None:
        """
        Write the whole state to an .npz file atomically (temporary file, then rename).

        Parameters
        ----------
        path : str or Path
            Target file, written exactly at this name; no pickled objects inside
            (metadata is a JSON string).

        """
        path = Path(path)
        meta, arrays = self.to_state()
        write_atomic(path, lambda f: np.savez(f, meta=np.array(json.dumps(meta)), **arrays))

    @classmethod
    def load(cls, path) -> Self:
        """
        Restore an accumulator written by :meth:`save`.

        Parameters
        ----------
        path : str or Path
            State file.

        Returns
        -------
        AllanAccumulator
            Ready for more samples; continuing gives the same sums as never stopping.

        Raises
        ------
        InputError
            The file is missing, corrupt, or not a state of this format and version.

        """
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z['meta']))
                arrays = {k: z[k] for k in ('buf', 'ref', 'level_hist', 'sums', 'counts',
                                            'm', *_MISSING_KEYS, *_STRETCH_KEYS) if k in z}
        except FileNotFoundError:
            raise InputError(f'accumulator state {path} does not exist') from None
        except Exception as exc:  # zip, JSON, missing keys: all mean a bad file
            raise InputError(f'accumulator state {path} is unreadable or corrupt '
                             f'({type(exc).__name__})') from None
        try:
            acc = cls.from_state(meta, arrays)
        except InputError as exc:
            raise InputError(f'accumulator state {path}: {exc}') from None
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f'accumulator state {path} is inconsistent '
                             f'({type(exc).__name__}: {exc})') from None
        return acc

    @classmethod
    def from_state(cls, meta, arrays: dict) -> Self:
        """
        Rebuild an accumulator from :meth:`to_state`, checking every field.

        Parameters
        ----------
        meta : dict
            The metadata.
        arrays : dict of str to np.ndarray
            The arrays.

        Returns
        -------
        AllanAccumulator
            Ready for more samples.

        Raises
        ------
        InputError
            Wrong format or version, or fields that do not fit together.
        KeyError, TypeError, ValueError
            Missing or mistyped fields (:meth:`load` turns them into InputError).

        """
        if not isinstance(meta, dict) or meta.get('format') != STATE_FORMAT:
            raise InputError('not an imu_allan accumulator state')
        if meta.get('version') != STATE_VERSION:
            raise InputError(f'state version {meta.get("version")} is not supported '
                             f'(expected {STATE_VERSION})')
        if arrays['ref'].shape != (int(meta['n_axes']),):
            raise InputError(f'{meta["n_axes"]} axes in its settings but '
                             f'{arrays["ref"].shape} reference values')
        acc = cls(meta['n_axes'], meta['rate_hz'], meta['exact_max_m'], meta['per_decade'])
        a, n_lv = acc.n_axes, len(acc._levels)
        cap = acc._levels[0].capacity if acc._levels else 0
        h0, pending = int(meta['h0']), int(meta['pending'])
        seg_n = int(meta['seg_n'])
        expect = {
            'buf': (a, h0 + pending), 'ref': (a,),
            'level_hist': (n_lv, a, cap),
            'sums': (acc._m.size, a), 'counts': (acc._m.size,), 'm': (acc._m.size,),
        }
        for key, shape in expect.items():
            arr = arrays[key]
            if arr.shape != shape or arr.dtype.kind not in 'fi':
                raise InputError(f'array {key!r} has shape {arr.shape} and type {arr.dtype}, '
                                 f'expected {shape}')
            if not np.isfinite(arr).all():
                raise InputError(f'array {key!r} holds non-finite values')
        _check_missing(meta, arrays, acc, h0 + pending)
        if not np.array_equal(arrays['m'], acc._m):
            raise InputError('its tau grid does not match its settings')
        if (arrays['counts'] < 0).any() or (arrays['sums'] < 0).any():
            raise InputError('negative sums or term counts')
        level_h, level_n = list(meta['level_h']), list(meta['level_n'])
        if len(level_h) != n_lv or len(level_n) != n_lv:
            raise InputError('wrong number of decimated levels')
        ok = (0 <= pending < acc._chunk and 0 <= h0 == min(acc._hist_cap, seg_n)
              and int(meta['n_samples']) >= seg_n + pending
              and int(meta['n_segments']) >= 0
              and all(0 <= h == min(cap, n) for h, n in zip(level_h, level_n)))
        if not ok:
            raise InputError('inconsistent buffer counters')
        acc._set_state(meta, arrays)
        return acc


def _check_missing(meta: dict, arrays: dict, acc, w: int) -> None:
    """Check the missing-sample fields of a state (all present, or all absent)."""
    present = [k in arrays for k in _MISSING_KEYS]
    if not any(present) and 'n_missing' not in meta:
        return
    if not all(present):
        raise InputError('the missing-sample arrays are incomplete')
    k0 = acc._m0.size
    expect = {'miss': (w,), 'dirty_sums': (k0, acc.n_axes), 'dirty_counts': (k0,)}
    for key, shape in expect.items():
        arr = arrays[key]
        if arr.shape != shape or arr.dtype.kind not in ('b' if key == 'miss' else 'fi'):
            raise InputError(f'array {key!r} has shape {arr.shape} and type {arr.dtype}, '
                             f'expected {shape}')
    n_missing, excess, run = (meta.get(k) for k in ('n_missing', 'fill_excess', 'miss_run'))
    if not (isinstance(n_missing, int) and isinstance(run, int)) or isinstance(run, bool):
        raise InputError('the missing-sample counts are invalid')
    dirty_sums, dirty_counts = arrays['dirty_sums'], arrays['dirty_counts']
    if (not isinstance(excess, (int, float)) or not 0 <= excess < math.inf
            or not 0 <= run <= n_missing <= int(meta['n_samples'])
            or not np.isfinite(dirty_sums).all()
            or (dirty_sums < 0).any() or (dirty_counts < 0).any()
            or (dirty_counts > arrays['counts'][:k0]).any()):
        raise InputError('the missing-sample counts are invalid')
