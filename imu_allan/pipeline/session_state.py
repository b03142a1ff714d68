"""
A session's checkpoint: each part's own state in one atomic ``.npz`` file (no pickle).

The file holds ``session_meta`` (JSON: format, version, axes, config, the counters, the
warning log, the stamp clock, the sample gate and the warm-up hold) and arrays (the
accumulator's, and the rows the spike filter, the motion gate and the warm-up hold
keep).  Every part validates its own state when it is restored; anything missing,
foreign or inconsistent is one InputError line.
"""

from dataclasses import asdict, fields, replace
import json
from pathlib import Path

import numpy as np

from imu_allan import AXES
from imu_allan.atomic import write_atomic
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, SessionConfig

#: What a checkpoint calls itself, and the one layout this version reads.
FORMAT = 'imu_allan.session'
VERSION = 5


def save(session, path) -> None:
    """Write ``session`` (a :class:`~imu_allan.pipeline.session.Session`) to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if session.feed.acc is None:
        return
    gate_meta, gate_arrays = session.gate.state()
    warmup_meta, warmup_arrays = session.warmup.state()
    meta = {
        'format': FORMAT, 'version': VERSION, 'axes': list(AXES),
        'config': asdict(session.config), 'stats': asdict(session.stats),
        'log': session.log.state(), 'clock': session.clock.state(), 'gate': gate_meta,
        'warmup': warmup_meta,
        'ticks': session.ticks.state(),
    }
    arrays = {**session.feed.state(), **gate_arrays, **warmup_arrays,
              'session_meta': np.array(json.dumps(meta))}
    write_atomic(path, lambda f: np.savez(f, **arrays))


def load(path) -> tuple[dict, dict]:
    """Read a checkpoint's metadata and arrays; InputError when it is not one."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays.pop('session_meta')))
    except (OSError, ValueError, KeyError, EOFError, TypeError) as exc:
        raise InputError(f'cannot read checkpoint {path}: {exc}') from None
    except Exception as exc:  # noqa: B902 - zipfile and zlib raise their own kinds
        raise InputError(f'cannot read checkpoint {path}: {type(exc).__name__}: {exc}') \
            from None
    if not isinstance(meta, dict) or meta.get('format', FORMAT) != FORMAT:
        raise InputError(f'checkpoint {path} is damaged: not an imu_allan session')
    if meta.get('version') != VERSION:
        raise InputError(f'checkpoint {path} has format version {meta.get("version")!r}; '
                         f'this version reads {VERSION} only: not resuming')
    if meta.get('axes') != list(AXES):
        raise InputError(f'checkpoint {path} has axes {meta.get("axes")}, not {list(AXES)}')
    return meta, arrays


#: Settings that checkpoints of earlier versions hold and this one no longer has.
_RETIRED_SETTINGS = ('background_accumulator',)


def resume_config(path, saved: tuple[dict, dict], config: SessionConfig | None) \
        -> SessionConfig:
    """Return the resumed session's settings: the given (or saved) ones, saved rate."""
    meta = saved[0]
    try:
        saved_cfg = SessionConfig(**{k: v for k, v in meta['config'].items()
                                     if k not in _RETIRED_SETTINGS})
        rate = float(meta['clock']['rate_hz'])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f'checkpoint {path} is damaged: its settings: {exc}') from None
    if not rate > 0 or not np.isfinite(rate):
        raise InputError(f'checkpoint {path} is damaged: its rate is {rate!r}')
    config = config or saved_cfg
    if config.rate_hz > 0 and abs(config.rate_hz / rate - 1) > config.rate_tolerance:
        raise InputError(f'checkpoint {path} was taken at {rate:.3f} Hz but the rate is now '
                         f'{config.rate_hz:.3f} Hz: not resuming')
    return replace(config, rate_hz=rate)


def restore(path, saved: tuple[dict, dict], session) -> None:
    """Give each part of a new ``session`` its saved state; InputError when invalid."""
    meta, arrays = saved
    try:
        stats = HygieneStats.restore(meta['stats'])
        session.log.restore(meta['log'])
        session.clock.restore(meta['clock'])
        session.ticks.restore(meta.get('ticks'))
        session.gate.restore(meta['gate'], arrays)
        # A checkpoint from before the warm-up hold has none (its rows were passed on).
        session.warmup.restore(meta.get('warmup'), arrays)
        session.feed.restore(arrays, session.clock.rate_hz)
    except (InputError, KeyError, TypeError, ValueError, ArithmeticError, AttributeError,
            IndexError) as exc:
        raise InputError(f'checkpoint {path} is damaged: {exc}') from None
    for f in fields(stats):
        setattr(session.stats, f.name, getattr(stats, f.name))
