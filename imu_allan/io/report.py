"""
Write an analysis to disk.

The result JSON, Kalibr file, Q/R, the Imu covariance fields, robot_localization
ekf.yaml fragments (IMUs with and without orientation), driver parameters, the VINS keys,
the OpenVINS kalibr_imu_chain.yaml, the fitted model as a params YAML, a human summary
and the ADEV plot (docs/outputs.md).

Used by the node (``~/save`` and shutdown) and by ``imu-allan analyze`` alike.  The
text of each consumer file is made in :mod:`imu_allan.core.outputs` (imu.yaml:
:func:`imu_allan.core.outputs.exports.kalibr_yaml`, given the result's covering pairs
by :meth:`imu_allan.pipeline.analysis.AnalysisResult.kalibr_yaml`).
"""

from concurrent.futures import Executor
import json
from pathlib import Path
import re

import yaml

from imu_allan.atomic import write_atomic
from imu_allan.core.noise.params import dump_params
from imu_allan.core.noise.values import NoiseSpec
from imu_allan.core.noise.words import speak
from imu_allan.io import FIGURE_FORMATS
from imu_allan.pipeline.analysis import AnalysisResult, B_CONVENTION
from imu_allan.pipeline.thermal_report import thermal_lines

#: File names inside the output directory (stable: other tools read them).
FILES = {
    'json': 'result.json',
    'kalibr': 'imu.yaml',
    'kalman': 'kalman_qr.yaml',
    'robot_localization': 'imu_covariance.yaml',
    'model': 'noise_model.yaml',
    'summary': 'summary.txt',
    'ekf': 'ekf_imu.yaml',
    'driver': 'imu_driver_noise.yaml',
    'vins': 'vins_imu.yaml',
    'openvins': 'kalibr_imu_chain.yaml',
    'ekf_no_orientation': 'ekf_imu_no_orientation.yaml',
}


def lacks_orientation(result: AnalysisResult) -> bool:
    """
    Tell whether every message read stated that it carries no orientation.

    ``orientation_covariance[0] = -1`` in each (REP 145; counted by the bag readers as
    ``hygiene.n_no_orientation``): robot_localization's ``ekf_imu.yaml`` would then
    take roll and pitch from nothing, so ``ekf_imu_no_orientation.yaml`` is the file
    to use.  False for CSV input and the node (not counted).
    """
    n_read = result.hygiene.get('n_read')
    return bool(n_read) and result.hygiene.get('n_no_orientation') == n_read


def ekf_advice(result: AnalysisResult) -> str:
    """Return which robot_localization fragment fits the messages (one line, or '')."""
    if lacks_orientation(result):
        return (f'robot_localization: use {FILES["ekf_no_orientation"]} (every message has '
                f'orientation_covariance[0] = -1: no orientation; {FILES["ekf"]} assumes '
                'one)')
    return ''


def _atomic_write(path: Path, text: str) -> Path:
    """Write text to path through a temporary file, so a crash never leaves half a file."""
    return write_atomic(path, lambda f: f.write(text), mode='w')


def result_json(result: AnalysisResult) -> str:
    """Return result.json's text (also the node's ``~/result`` topic)."""
    return json.dumps(result.to_json(), indent=1) + '\n'


def summary_text(result: AnalysisResult) -> str:
    """Return the human summary: one line per axis plus the input warnings."""
    lines = [f'imu_allan result for {result.source or "input"}: {result.n_samples} samples, '
             f'{result.duration_s / 3600:.3f} h at {result.rate_hz:.3f} Hz', '']
    lines += result.summary_lines()
    lines += ['', "[lo, hi]: the 95 % interval; '<' an upper bound (95 %), '>' a lower bound; "
              'n/a: not identified; ADEV floor: the lowest Allan deviation (what a '
              'datasheet calls in-run bias stability), shown where the curve measures it']
    notes = [f'  {axis}: {speak(n)}' for axis, fit in result.fits.items() if fit is not None
             for n in distinct_notes(fit.notes)]
    if notes:
        lines += ['', 'notes (why a value is a bound, what the model leaves open):'] + notes
    lines += thermal_lines(result.thermal)
    lines += [''] + result.covering_lines()
    if ekf_advice(result):
        lines += ['', ekf_advice(result)]
    if result.plans:
        lines += ['', 'precision (relative 95 % half-width) now, the record length to '
                  'reach each target, and at 1, 3, 10 h:']
        for axis, plan in result.plans.items():
            lines += [f'{axis}: {plan.progress_line()}'] + plan.table_lines()
    if result.warnings:
        lines += ['', 'warnings:'] + [f'  - {w}' for w in result.warnings]
    lines += ['', f'B convention: {B_CONVENTION}']
    return '\n'.join(lines) + '\n'


def distinct_notes(notes) -> list:
    """
    Return the notes without repeats: one per wording, whatever its numbers.

    The search may note the same finding twice with other figures (a sinusoid near
    10.1 Hz tried at two amplitudes); the first is kept.
    """
    seen, out = set(), []
    for note in notes:
        key = re.sub(r'[-+]?\d[\d.e+-]*', '#', note)
        if key not in seen:
            seen.add(key)
            out.append(note)
    return out


def kalman_yaml(result: AnalysisResult) -> str:
    """Return the Q/R matrices with their state order as YAML (discrete and continuous)."""
    k = result.kalman.to_json()
    header = ('# Bias-state Kalman model per axis (Maia et al. eqs. 16-17): states b_gm '
              '(Gauss-Markov) and b_rw (random walk).\n# Discrete forms for dt_s; '
              'Rd = S_N / dt. Units: rad, m, s.\n')
    return result.with_trust_comments(header + yaml.safe_dump(k, sort_keys=False, width=120))


def covariance_yaml(result: AnalysisResult) -> str:
    """Return the sensor_msgs/Imu covariance fields for robot_localization."""
    header = ('# Paste into the IMU driver (or imu_with_covariance): robot_localization '
              'reads noise from these message fields.\n# variance = N^2 * rate_hz '
              '(white noise at the sample rate), clamped to >= 1e-9.\n')
    text = header + yaml.safe_dump(result.imu_covariances(), sort_keys=False)
    return result.with_trust_comments(text)


def _draw(result: AnalysisResult, base: Path, ext: str) -> list:
    """Draw the ADEV figure as one file (in a worker: matplotlib is imported there)."""
    from imu_allan.io.plot import plot_result
    return plot_result(result, base, (ext,))


def write_outputs(result: AnalysisResult, out_dir, plot: bool = True,
                  imu_topic: str | None = None, pool: Executor | None = None) -> list:
    """
    Write every output file of one analysis into ``out_dir``.

    Parameters
    ----------
    result : AnalysisResult
        The analysis.
    out_dir : str or Path
        Directory (created when missing).
    plot : bool
        Also draw adev.png and adev.svg.
    imu_topic : str, optional
        The topic robot_localization should fuse (the node's republished topic);
        default the analysed one.
    pool : concurrent.futures.Executor, optional
        Worker processes (:func:`imu_allan.pipeline.workers.worker_pool`): the PNG and
        the SVG are then drawn in two of them while this process writes the rest.

    Returns
    -------
    list of Path
        The files written.

    """
    out = Path(out_dir).expanduser()
    out.mkdir(parents=True, exist_ok=True)
    figures = []
    if plot and pool is not None:
        figures = [pool.submit(_draw, result, out / 'adev', ext) for ext in FIGURE_FORMATS]
    spec = NoiseSpec(name=f'fitted from {result.source or "input"}', axes=result.models())
    written = [
        _atomic_write(out / FILES['json'], result_json(result)),
        _atomic_write(out / FILES['kalibr'], result.kalibr_yaml()),
        _atomic_write(out / FILES['kalman'], kalman_yaml(result)),
        _atomic_write(out / FILES['robot_localization'], covariance_yaml(result)),
        _atomic_write(out / FILES['model'], result.with_trust_comments(
            yaml.safe_dump(dump_params(spec), sort_keys=False))),
        _atomic_write(out / FILES['summary'], summary_text(result)),
        _atomic_write(out / FILES['ekf'], result.robot_localization_yaml(imu_topic)),
        _atomic_write(out / FILES['driver'], result.driver_yaml()),
        _atomic_write(out / FILES['vins'], result.vins_yaml()),
        _atomic_write(out / FILES['openvins'], result.openvins_yaml()),
        _atomic_write(out / FILES['ekf_no_orientation'],
                      result.robot_localization_yaml(imu_topic, orientation=False)),
    ]
    if lacks_orientation(result):
        # Listed first of the two: the one that fits messages without orientation.
        ekf = written.index(out / FILES['ekf'])
        written.insert(ekf, written.pop())
    if plot and pool is None:
        from imu_allan.io.plot import plot_result
        written += plot_result(result, out / 'adev')
    for job in figures:
        written += job.result()
    return written
