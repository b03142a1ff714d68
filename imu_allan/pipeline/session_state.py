"""
A session's state on disk: the atomic checkpoint and its restore.

A mixin of :class:`imu_allan.pipeline.session.Session`.
"""

from __future__ import annotations

from dataclasses import asdict, replace
import json
from pathlib import Path
from typing import Callable, Self, TYPE_CHECKING

import numpy as np

from imu_allan import AXES
from imu_allan.atomic import write_atomic
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.errors import InputError
from imu_allan.pipeline.clock import _NS
from imu_allan.pipeline.parts import _Parts

if TYPE_CHECKING:  # the session module imports this one
    from imu_allan.pipeline.session import SessionConfig


N_AXES = len(AXES)


# Slightly long: a checkpoint's format, and a check of every field when it is read
# back (a foreign or corrupt file is set aside, never trusted).
class _StateFile(_Parts):
    """Checkpoint (save_state) and resume (load_state) of the whole session."""

    # ------------------------------------------------------------- checkpoint
    def _restore_clock(self, meta: dict, rate_hz: float) -> None:
        """Restore the stamp-clock state; older checkpoints get a neutral equivalent."""
        self._newest_ns = meta.get('newest_stamp_ns', meta.get('last_stamp_ns'))
        self._nan_break = bool(meta.get('nan_break', False))
        if 'clock_n' in meta:
            self._clock_n = int(meta['clock_n'])
            self._clock_ns = int(meta['clock_ns'])
            self._jitter_sq = float(meta['jitter_sq'])
            self._jitter_n = int(meta['jitter_n'])
            buf = np.array(meta['step_buf'], dtype=np.int64)
            self._step_buf = [buf] if buf.size else []
            off = meta['off_period_ns']
            self._off_period_ns = None if off is None else float(off)
            return
        # Version 1 kept no step counts: weigh the saved rate as if every used sample
        # had been one step at it, so a later mean-rate refinement stays anchored.
        self._clock_n = int(self.stats.n_used)
        self._clock_ns = int(round(self._clock_n * _NS / rate_hz))
        self._jitter_n = self._clock_n
        self._jitter_sq = self.stats.jitter_rel ** 2 * self._clock_n

    def save_state(self, path) -> None:
        """
        Save the whole session atomically (accumulator state plus counters; no pickle).

        Parameters
        ----------
        path : str or Path
            Target file; written to a temporary file first, then renamed.

        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if self.acc is None:
            return
        meta = {
            'version': 3, 'rate_hz': self.rate_hz, 'axes': list(AXES),
            'config': asdict(self.config), 'stats': asdict(self.stats),
            'warn_text': self._warn_text, 'warn_count': self._warn_count,
            'first_stamp_ns': self.first_stamp_ns,
            'last_stamp_ns': self.last_stamp_ns,
            # Everything the stamp checks and the rate estimate carry over (version 2).
            'newest_stamp_ns': self._newest_ns,
            'clock_n': self._clock_n, 'clock_ns': self._clock_ns,
            'step_buf': [int(s) for b in self._step_buf for s in b],
            'jitter_sq': self._jitter_sq, 'jitter_n': self._jitter_n,
            'off_period_ns': self._off_period_ns, 'nan_break': self._nan_break,
            'ref_mean': None if self._ref_mean is None else self._ref_mean.tolist(),
            'ref_std': None if self._ref_std is None else self._ref_std.tolist(),
            # The motion and frozen-axis checks in progress (version 3).
            'moving': self._moving, 'in_motion': self._in_motion,
            'still_since_ns': self._still_since_ns, 'repeat': self._repeat.tolist(),
        }
        # The accumulator's state in memory, under the keys its own file uses.
        acc_meta, acc_arrays = self.acc.to_state()
        arrays = {f'acc__{k}': v for k, v in acc_arrays.items()}
        arrays['acc__meta'] = np.array(json.dumps(acc_meta))
        arrays['session_meta'] = np.array(json.dumps(meta))
        # Samples held for the motion check of a window not yet complete (version 3).
        arrays['held_stamp_ns'] = np.concatenate(self._win_t or [np.empty(0, np.int64)])
        arrays['held_samples'] = np.concatenate(self._win_y or [np.empty((0, N_AXES))])
        arrays['last_value'] = self._last_value
        write_atomic(path, lambda f: np.savez(f, **arrays))

    @classmethod
    def load_state(cls, path, config: SessionConfig | None = None,
                   on_warning: Callable[[str], None] | None = None) -> Self:
        """
        Restore a session saved by :meth:`save_state`.

        Parameters
        ----------
        path : str or Path
            Checkpoint file.
        config : SessionConfig, optional
            Settings for the resumed session; a rate that differs from the saved one
            by more than ``rate_tolerance`` refuses the resume with an InputError.
        on_warning : callable, optional
            Warning sink of the new session.

        Returns
        -------
        Session
            The restored session, ready for more samples.

        """
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z['session_meta']))
                acc_arrays = {k[5:]: z[k] for k in z.files if k.startswith('acc__')}
                held = {k: z[k] for k in ('held_stamp_ns', 'held_samples', 'last_value')
                        if k in z.files}
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f'cannot read checkpoint {path}: {exc}') from None
        try:
            return cls._restore(path, meta, acc_arrays, held, config, on_warning)
        except InputError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f'checkpoint {path} is damaged: {exc!r}') from None

    @classmethod
    def _restore(cls, path, meta: dict, acc_arrays: dict, held: dict,
                 config: SessionConfig | None,
                 on_warning: Callable[[str], None] | None) -> Self:
        if not isinstance(meta, dict):
            raise TypeError('its metadata is not a JSON object')
        if meta.get('axes') != list(AXES):
            raise InputError(f'checkpoint {path} has axes {meta.get("axes")}, not {list(AXES)}')
        from imu_allan.pipeline.session import HygieneStats, SessionConfig

        saved_cfg = SessionConfig(**meta['config'])
        config = config or saved_cfg
        rate = float(meta['rate_hz'])
        if config.rate_hz > 0 and abs(config.rate_hz / rate - 1) > config.rate_tolerance:
            raise InputError(f'checkpoint {path} was taken at {rate:.3f} Hz but the rate is now '
                             f'{config.rate_hz:.3f} Hz: not resuming')
        try:
            acc = AllanAccumulator.from_state(
                json.loads(str(acc_arrays['meta'])),
                {k: v for k, v in acc_arrays.items() if k != 'meta'})
        except InputError as exc:
            raise InputError(f'checkpoint {path}: accumulator state: {exc}') from None
        session = cls(replace(config, rate_hz=rate), on_warning=on_warning)
        session.acc = acc
        session.stats = HygieneStats(**meta['stats'])
        session._warn_text = dict(meta['warn_text'])
        session._warn_count = {k: int(v) for k, v in meta['warn_count'].items()}
        session.first_stamp_ns = meta['first_stamp_ns']
        session.last_stamp_ns = meta['last_stamp_ns']
        session._restore_clock(meta, rate)
        if meta['ref_mean'] is not None:
            # float64 arrays of their own: the motion scan updates the mean in place.
            session._ref_mean = np.array(meta['ref_mean'], dtype=np.float64)
            session._ref_std = np.array(meta['ref_std'], dtype=np.float64)
            if session._ref_mean.shape != (N_AXES,) or session._ref_std.shape != (N_AXES,):
                raise ValueError('the motion reference has the wrong shape')
        if 'held_samples' in held:  # version 3; older checkpoints lost these
            rows = held['held_stamp_ns'].shape
            if (held['held_samples'].shape != rows + (N_AXES,)
                    or held['last_value'].shape != (N_AXES,) or len(meta['repeat']) != N_AXES):
                raise ValueError('the held samples or axis counters have the wrong shape')
            if rows[0]:
                session._win_t = [held['held_stamp_ns'].astype(np.int64)]
                session._win_y = [held['held_samples'].astype(np.float64)]
            session._last_value = held['last_value'].astype(np.float64)
            session._repeat = np.array(meta['repeat'], dtype=np.int64)
            session._moving = bool(meta['moving'])
            session._in_motion = bool(meta['in_motion'])
            session._still_since_ns = meta['still_since_ns']
        return session
