"""
The work of one fleet input, as it runs on a Dask worker: today's pipeline, unchanged.

:func:`analyze_job` streams the input through :func:`imu_allan.io.inputs.analyze_input`
(the same call as ``imu-allan analyze``) and turns the result into store rows (one per
axis).  Every failure comes back as one row with a one-line reason, so a bad input never
stops the run; a robot that moved during the recording is a failure too, since its
numbers do not describe a still IMU.  Nothing here imports Dask.
"""

import math
import time
from typing import NamedTuple

from imu_allan import __version__, AXES, AXIS_UNITS
from imu_allan.errors import InputError
from imu_allan.fleet.store import PARAMS
from imu_allan.pipeline.hygiene import SessionConfig

#: Share of the samples dropped as motion above which an input is rejected.
MAX_MOTION_SHARE = 0.2


class FleetJob(NamedTuple):
    """
    One input to analyse.

    Attributes
    ----------
    path : str
        The input.
    key : str
        Its content key.
    imu_id : str
        The IMU ('' to take the bag's topic@frame_id).
    model : str
        IMU model.
    topic : str or None
        Imu topic of a bag (None: its only one).
    config : SessionConfig
        Input checks and accumulator settings.

    """

    path: str
    key: str
    imu_id: str
    model: str
    topic: str | None
    config: SessionConfig


def _base(job: FleetJob) -> dict:
    return {'key': job.key, 'path': job.path, 'imu_id': job.imu_id, 'model': job.model,
            'version': __version__}


def failed_rows(job: FleetJob, reason: str, cpu_s: float = math.nan) -> list[dict]:
    """Return the one row of an input that could not be analysed."""
    return [dict(_base(job), status='failed', reason=reason.splitlines()[0] if reason
                 else 'failed', cpu_s=cpu_s)]


def _param_columns(fit) -> dict:
    out: dict = {}
    for sym in PARAMS:
        p = fit.optimised.get(sym) if fit is not None else None
        if p is None:
            continue
        out[sym], (out[f'{sym}_lo'], out[f'{sym}_hi']) = float(p.value), map(float, p.ci95)
        out[f'{sym}_kind'] = p.kind
    if fit is not None:
        out['effects'] = ','.join(e['effect'] for e in fit.effects)
        out['model_consistent'] = -1 if fit.model_consistent is None \
            else int(fit.model_consistent)
    return out


def result_rows(job: FleetJob, result, cpu_s: float) -> list[dict]:
    """Return the six rows (one per axis) of an analysed input."""
    topic = result.topic or ''
    imu_id = job.imu_id or (f'{topic}@{result.frame_id}' if result.frame_id else topic) \
        or job.path
    base = dict(_base(job), imu_id=imu_id, topic=topic, frame_id=result.frame_id,
                start_ns=-1 if result.start_ns is None else int(result.start_ns),
                duration_s=float(result.duration_s), rate_hz=float(result.rate_hz),
                n_samples=int(result.n_samples), status='ok', cpu_s=cpu_s,
                warnings=' | '.join(result.warnings))
    return [dict(base, axis=axis, unit=AXIS_UNITS[axis], **_param_columns(result.fits.get(axis)))
            for axis in AXES]


def analyze_job(job: FleetJob) -> tuple[str, str, list[dict]]:
    """
    Analyse one input; never raises for a bad input.

    Parameters
    ----------
    job : FleetJob
        The input.

    Returns
    -------
    tuple
        (content key, 'ok' or 'failed', store rows).

    """
    from imu_allan.io.inputs import analyze_input  # the pipeline: numpy, scipy, readers

    start = time.process_time()
    try:
        # One input per core: a read-ahead thread would only compete with the other workers.
        result, _ = analyze_input(job.path, job.topic, job.config, quiet=True, progress=False,
                                  prefetch=False)
    except InputError as exc:
        return job.key, 'failed', failed_rows(job, str(exc), time.process_time() - start)
    except MemoryError:
        return job.key, 'failed', failed_rows(job, f'{job.path}: out of memory')
    except Exception as exc:  # noqa: B902 - one line per failed input, the others go on
        return job.key, 'failed', failed_rows(
            job, f'{job.path}: unexpected {type(exc).__name__}: {exc}')
    cpu_s = time.process_time() - start
    stats = result.hygiene
    share = stats.get('n_motion_dropped', 0) / max(stats.get('n_received', 0), 1)
    if share >= MAX_MOTION_SHARE:
        return job.key, 'failed', failed_rows(
            job, f'{job.path}: the IMU moved ({100 * share:.0f} % of the samples dropped as '
            'motion): not a static recording', cpu_s)
    return job.key, 'ok', result_rows(job, result, cpu_s)
