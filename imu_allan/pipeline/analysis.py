"""
From a pipeline session to the result every output is made of.

:func:`analyze` fits each axis of the session's Allan curve and bundles the fits, the
Kalman matrices, the Kalibr file and the Imu covariances in one frozen
:class:`AnalysisResult`; its :meth:`AnalysisResult.to_json` is the result JSON of
docs/contracts.md.  B follows the paper's convention (Maia et al. eq. 8, see noise_params).
"""

from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
import math
from typing import Any, Callable

import numpy as np

from imu_allan import AXES, AXIS_UNITS
from imu_allan.core.allan.curve import AllanCurve
from imu_allan.core.allan.edf import confidence_bounds
from imu_allan.core.allan.hold import held_fit_curve
from imu_allan.core.allan.raw import raw_evidence
from imu_allan.core.fit.result import AxisFit, json_floats
from imu_allan.core.noise.unit_check import unit_warnings
from imu_allan.core.noise.units import format_quoted, sensor_of
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.outputs.covering import cover_axes, default_horizon, DEFAULT_HORIZON_S
from imu_allan.core.outputs.exports import driver_yaml, kalibr_yaml, robot_localization_yaml
from imu_allan.core.outputs.kalman import imu_covariance, kalman_model, KalmanModel
from imu_allan.core.outputs.lines import axis_line
from imu_allan.core.outputs.reported import report_axes, unsettled
from imu_allan.core.outputs.short_record import SHORT_RECORD, short_record_warnings
from imu_allan.core.outputs.vio import openvins_yaml, vins_yaml
from imu_allan.errors import InputError
from imu_allan.pipeline.clipping import CLIPPED, KEEP_SHARE, left_out
from imu_allan.pipeline.drift_report import drift_axes, SLOW_DRIFT
from imu_allan.pipeline.level_report import level_axes, NOISE_CHANGED
from imu_allan.pipeline.resolution import COARSE_GRID, resolution_warnings
from imu_allan.pipeline.session import Session
from imu_allan.pipeline.thermal_report import thermal_axes, THERMAL_DRIFT
from imu_allan.pipeline.workers import worker_pool

#: Confidence of the reported Allan bands and parameter intervals.
CONFIDENCE = 0.95
B_CONVENTION = ('B is the level of the fitted bias-instability term: a Gauss-Markov '
                'process whose ADEV peaks at 0.664 B at tau = 1.89 T_B, driving PSD '
                'S_B = 2 B^2 ln2 / (pi 0.4365^2 T_B) (Maia et al. eq. 8), or flicker noise '
                'of ADEV 0.664 B; the measured floor also holds the other terms, so '
                'B_floor = ADEV_min / 0.664 (IEEE Std 952 read-off) is reported beside '
                'it and is >= B up to its interval')
_CORE = ('N', 'B', 'K', 'T_B')


# Long by design: the one result every output is made of; each method is one view of
# it (JSON, Q/R, Kalibr, covariances, statuses), so they cannot drift apart.
@dataclass(frozen=True)
class AnalysisResult:
    """
    Everything one analysis produced, for every output (JSON, topics, files, plots).

    Attributes
    ----------
    rate_hz : float
        Sample rate [Hz].
    duration_s : float
        Duration of the samples used [s].
    n_samples : int
        Samples used.
    warnings : tuple of str
        One line per kind of input problem.
    hygiene : dict
        Counters of the input checks (pipeline.HygieneStats as a dict), plus ``n_read``
        and ``n_lost``: messages the input delivered and lost (None: unknown).
    curve : AllanCurve
        Measured curve of the six axes at 95 % confidence.
    fits : dict of str to AxisFit or None
        Fit per axis; None where the axis cannot be fitted (frozen, no noise).
    source : str
        What was analysed (file name, topic).
    topic : str
        The Imu topic the samples came from ('' for a CSV file): Kalibr's ``rostopic``.
    start_ns : int or None
        First header stamp of the recording [ns since the epoch] (offline inputs).
    frame_id : str
        header.frame_id of the messages ('' for CSV and the node).
    covering_tau_max_s : float
        Upper end of the covering pair's horizon [s] (the lower end is the sample period),
        :mod:`imu_allan.core.outputs.covering`.
    plans : dict of str to imu_allan.core.plan.AxisPlan
        Per axis, the precision now and the record length to each target (empty
        unless :func:`analyze` was asked to plan).
    thermal : dict of str to AxisThermal
        Thermal coefficient and compensated fit per axis (pipeline/thermal_report.py).

    """

    rate_hz: float
    duration_s: float
    n_samples: int
    warnings: tuple
    hygiene: dict
    curve: AllanCurve
    fits: dict
    source: str = ''
    topic: str = ''
    start_ns: int | None = None
    frame_id: str = ''
    covering_tau_max_s: float = DEFAULT_HORIZON_S
    plans: dict = field(default_factory=dict)
    thermal: dict = field(default_factory=dict)

    def models(self) -> dict:
        """Fitted AxisNoise per axis (an empty model where the axis has no fit)."""
        return {a: (f.model if f is not None else AxisNoise()) for a, f in self.fits.items()}

    @cached_property
    def reports(self) -> dict:
        """
        Return what every output reports per axis (AxisReport): the one decision.

        :func:`imu_allan.core.outputs.reported.report_axes` of :attr:`fits`, made once;
        every file, topic and summary line of this class only formats it.
        """
        return report_axes(self.fits)

    @cached_property
    def kalman(self) -> KalmanModel:
        """Six-axis bias model (paper eqs. 16-17), continuous and discrete, of the reports."""
        return kalman_model(self.reports, self.rate_hz)

    def _sources(self) -> dict:
        return self.reports

    @property
    def covering_horizon_s(self) -> tuple:
        """(sample period, covering_tau_max_s) [s]: the covering pair's horizon."""
        return default_horizon(self.rate_hz, self.covering_tau_max_s)

    @cached_property
    def covers(self) -> dict:
        """Covering white + random-walk pair per axis (AxisCover or None)."""
        return cover_axes(self._sources(), self.covering_horizon_s)

    def kalibr_yaml(self, rostopic: str | None = None) -> str:
        """Kalibr imu.yaml (covering pair); ``rostopic`` is the analysed topic unless given."""
        return self.with_trust_comments(kalibr_yaml(
            self._sources(), self.rate_hz, rostopic=rostopic or self.topic or '/imu/data',
            covers=self.covers, horizon_s=self.covering_horizon_s))

    def robot_localization_yaml(self, imu_topic: str | None = None,
                                orientation: bool = True) -> str:
        """robot_localization ekf.yaml fragment fusing ``imu_topic`` (default: analysed)."""
        return self.with_trust_comments(robot_localization_yaml(
            self._sources(), self.rate_hz, imu_topic or self.topic or '/imu/data',
            orientation=orientation))

    def driver_yaml(self) -> str:
        """Per-sample stdev and variance per axis and worst axis, for driver parameters."""
        return self.with_trust_comments(driver_yaml(self._sources(), self.rate_hz))

    def vins_yaml(self) -> str:
        """VINS-Mono / VINS-Fusion acc_n, gyr_n, acc_w, gyr_w (covering pair, per step)."""
        return self.with_trust_comments(vins_yaml(self._sources(), self.rate_hz, self.covers,
                                                  self.covering_horizon_s))

    def openvins_yaml(self, rostopic: str | None = None) -> str:
        """Return the OpenVINS kalibr_imu_chain.yaml (covering pair, densities)."""
        return self.with_trust_comments(openvins_yaml(
            self._sources(), self.rate_hz, rostopic or self.topic or '/imu/data', self.covers,
            self.covering_horizon_s))

    def covering_lines(self) -> list:
        """Summary lines: fitted and covering N, K per axis with the factors."""
        lo, hi = self.covering_horizon_s
        lines = [f'covering white + random-walk pair (bounds the whole model for tau in '
                 f'[{lo:.3g}, {hi:.3g}] s, never below the reported N and K; written to the '
                 'Kalibr, VINS and OpenVINS files):']
        for axis in AXES:
            c = self.covers.get(axis)
            if c is None:
                lines.append(f'  {axis}: n/a')
                continue
            fn = 'n/a' if c.factor_N is None else f'{c.factor_N:.3g}'
            fk = 'n/a' if c.factor_K is None else f'{c.factor_K:.3g}'
            # The units the files carry them in (Kalibr's: unit/sqrt(Hz) for both).
            unit = AXIS_UNITS[axis]
            lines.append(f'  {axis}: N {c.N_fit:.3e} -> {c.N_cover:.3e} {unit}/sqrt(Hz) '
                         f'(x{fn}), K {c.K_fit:.3e} -> {c.K_cover:.3e} {unit}/s/sqrt(Hz) '
                         f'(x{fk})')
        return lines

    def process_noise(self) -> tuple[np.ndarray, list]:
        """Discrete process noise Qd (12, 12) [unit^2] and its state order."""
        return self.kalman.Qd, list(self.kalman.state_labels)

    def measurement_noise(self) -> tuple[np.ndarray, list]:
        """Discrete measurement noise Rd (6, 6) [unit^2] and its order."""
        return self.kalman.Rd, list(self.kalman.measurement_labels)

    def imu_covariances(self) -> dict:
        """Return the sensor_msgs/Imu covariance fields for robot_localization."""
        cov = imu_covariance(self._sources(), self.rate_hz)
        return {'angular_velocity_covariance': list(cov.angular_velocity_covariance),
                'linear_acceleration_covariance': list(cov.linear_acceleration_covariance),
                'clamped_to_1e-9': list(cov.clamped), 'unknown': list(cov.unknown)}

    def axis_status(self, axis: str) -> tuple[str, str, list]:
        """
        Level, message and key/values of one axis for a diagnostic status.

        Returns
        -------
        level : str
            'ok' when N and B are estimates with reasonably tight intervals and the
            input was clean, 'warn' when the numbers are not to be trusted yet,
            'error' when the axis cannot be characterised.
        message : str
            One line with the values in customary units.
        values : list of (str, str)
            Every parameter with its interval and unit, samples, duration, rate.

        """
        fit = self.fits.get(axis)
        base = [('samples', str(self.n_samples)), ('duration_s', f'{self.duration_s:.1f}'),
                ('rate_hz', f'{self.rate_hz:.4f}')]
        if fit is None:
            return 'error', f'{axis}: {self.no_fit(axis)}', base
        values = []
        for sym, p in self.reports[axis].params.items():
            values += [(sym, _g(p.value)), (f'{sym}_ci95_lo', _g(p.ci95[0])),
                       (f'{sym}_ci95_hi', _g(p.ci95[1])), (f'{sym}_unit', p.unit),
                       (f'{sym}_kind', p.kind)]
        problems = unsettled(fit)
        if fit.trust:
            problems.append('fit not trusted, conservative values used: ' + '; '.join(fit.trust))
        elif fit.model_consistent is False:
            problems.append('no listed effect explains the curve (see the notes)')
        if any(k in self.hygiene and self.hygiene[k] for k in ('n_motion_events',)):
            problems.append('motion was detected')
        level = 'warn' if problems else 'ok'
        message = self.summary_line(axis)
        if problems:
            message += ' | not trusted yet: ' + '; '.join(problems)
        return level, message, values + base

    def no_fit(self, axis: str) -> str:
        """Say why an axis has no fit: clipped (left out), or no usable noise."""
        if self.hygiene.get('clipped', {}).get(axis, 0.0) > KEEP_SHARE:
            return 'left out: clipped at the ends of its range (see the warning)'
        return 'no usable noise (frozen or constant axis)'

    def summary_line(self, axis: str) -> str:
        """One human line of an axis (:func:`imu_allan.core.outputs.lines.axis_line`)."""
        fit = self.fits.get(axis)
        if fit is None:
            return f'{axis}: {self.no_fit(axis)}'
        return axis_line(axis, fit, self.reports[axis])

    def trust_warnings(self) -> list:
        """One top-level warning per axis whose fit is not trusted (conservative values)."""
        out = []
        for axis in [a for a in AXES if self.fits.get(a) is not None and self.fits[a].trust]:
            fit = self.fits[axis]
            used = ', '.join(f'{s} {"<= " if p.kind == "upper_bound" else ""}{p.value:.3g}'
                             + (f' [{p.ci95[0]:.3g}, {p.ci95[1]:.3g}]'
                                if p.kind == 'estimate' else '')
                             for s, p in self.reports[axis].params.items()
                             if s in ('N', 'B', 'K') and math.isfinite(p.value))
            fitted = ', '.join(f'{s} {p.value:.3g} ({p.kind})'
                               for s, p in fit.fit_values.items() if s in ('N', 'B'))
            out.append(f'{axis}: the fitted model is not trusted ({"; ".join(fit.trust)}); '
                       f'every output uses conservative values from the curve: {used} [SI] '
                       f'(N from the white region, B from the ADEV floor); the fit gave '
                       f'{fitted}; imu-allan diagnose names an effect the model lacks, a '
                       'longer record settles a time at the end of its range')
        return out

    def with_trust_comments(self, text: str) -> str:
        """Consumer-file text with a comment per untrusted axis and undetermined value."""
        lines = [f'# WARNING {c}' for a in AXES
                 for c in [self.fits[a].trust_comment(a) if self.fits.get(a) else ''] if c]
        lines += [f'# WARNING {w}' for w in self.warnings if CLIPPED in w
                  or w.startswith((SHORT_RECORD, THERMAL_DRIFT, SLOW_DRIFT, COARSE_GRID,
                                   NOISE_CHANGED))]
        if not lines:
            return text
        head, sep, rest = text.partition('\n')
        if head.startswith('%YAML'):
            return head + sep + '\n'.join(lines) + '\n' + rest
        return '\n'.join(lines) + '\n' + text

    def summary_lines(self) -> list:
        """One summary line per axis."""
        return [self.summary_line(a) for a in AXES]

    def to_json(self) -> dict:
        """Return the result JSON of docs/contracts.md (SI units; None for NaN/inf)."""
        axes = {}
        for j, axis in enumerate(AXES):
            fit = self.fits.get(axis)
            entry: dict[str, object] = {
                'unit': AXIS_UNITS[axis],
                'tau_s': json_floats(self.curve.tau_s),
                'adev': json_floats(self.curve.adev[:, j]),
                'adev_lo': json_floats(self.curve.adev_lo[:, j]),
                'adev_hi': json_floats(self.curve.adev_hi[:, j]),
                'edf': json_floats(self.curve.edf[:, j]),
                'n_terms': [int(n) for n in self.curve.n_terms]}
            if fit is None:
                entry.update({'params': {}, 'nominal': {}, 'terms': [],
                              'notes': [self.no_fit(axis)]})
            else:
                entry.update(fit.to_json())
                entry['reported'] = self.reports[axis].to_json()
                # The final model at every tau, and the range it was fitted on (beyond
                # it, a plot of adev_model is an extrapolation).
                entry['adev_model'] = json_floats(np.sqrt(fit.avar_at(self.curve.tau_s)))
                entry['model_tau_range_s'] = json_floats([fit.tau_s.min(), fit.tau_s.max()])
                entry['quoted'] = {
                    sym: format_quoted(sym, sensor_of(axis), p.value, digits=4)
                    for sym, p in self.reports[axis].params.items()
                    if sym in _CORE and p.kind in ('estimate', 'upper_bound')}
            cover = self.covers.get(axis)
            entry['covering'] = None if cover is None else cover.to_json()
            if axis in self.plans:
                entry['plan'] = self.plans[axis].to_json()
            if axis in self.thermal:
                entry['thermal'] = self.thermal[axis].to_json(axis)
            axes[axis] = entry
        return {
            'source': self.source,
            'sample_rate_hz': self.rate_hz,
            'duration_s': self.duration_s,
            'n_samples': int(self.n_samples),
            'confidence': CONFIDENCE,
            'warnings': list(self.warnings),
            'hygiene': self.hygiene,
            'b_convention': B_CONVENTION,
            'covering_horizon_s': list(self.covering_horizon_s),
            'axes': axes,
            'kalman': self.kalman.to_json(),
            'imu_covariance': self.imu_covariances(),
        }


def _search_job(job: tuple) -> AxisFit | None:
    """Search one axis: (tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit)."""
    from imu_allan.core.search import search_axis   # scipy: in the workers only

    tau_s, avar, edf, rate_hz, n_samples, raw, raw_rate_hz, unit = job
    try:
        return search_axis(tau_s, avar, edf, rate_hz, n_samples, raw=raw,
                           raw_rate_hz=raw_rate_hz, unit=unit).fit
    except InputError:
        return None


def _map_axes(jobs: list, workers: int, meanwhile: Callable[[], Any]) -> tuple[list, Any]:
    """
    Run :func:`_search_job` over the axes, in worker processes when workers > 1.

    Returns the fits and what ``meanwhile()`` returned: it runs in this process while
    the workers search (first, without them).
    """
    pool = worker_pool(min(workers, len(jobs)))
    if pool is None:
        done = meanwhile()
        return [_search_job(job) for job in jobs], done
    with pool:
        fits = pool.map(_search_job, jobs)      # submitted now, collected below
        done = meanwhile()
        return list(fits), done


def analyze(session, source: str = '', raw=None, topic: str = '', workers: int = 1,
            covering_tau_max_s: float = DEFAULT_HORIZON_S, plan: bool = False,
            plan_targets: dict | None = None) -> AnalysisResult | None:
    """
    Fit every axis of a session's current Allan curve, effect search included.

    The node, ``imu-allan analyze`` and ``imu-allan diagnose`` all come here (or to
    :func:`imu_allan.core.search.search_axis` alike): one model for the same data.

    Parameters
    ----------
    session : imu_allan.pipeline.Session
        The session (node or offline) after its samples were added.
    source : str
        What was analysed, for the report.
    raw : imu_allan.core.search.evidence.RawKeeper, optional
        Block-averaged copy of the samples: the effect search's periodogram and ramp
        evidence (without it, sinusoids and ramps are named from the curve alone).
    topic : str
        The Imu topic of the samples (Kalibr's ``rostopic``); '' when unknown.
    workers : int
        Processes that search the axes (1: in this process, as the node does; same fits).
    covering_tau_max_s : float
        Upper end of the covering pair's horizon [s] (:attr:`AnalysisResult.covers`).
    plan : bool
        Also plan the record length (:mod:`imu_allan.core.plan`, a few seconds).
    plan_targets : dict of str to float, optional
        Target relative 95 % half-widths by parameter (default the planner's).

    Returns
    -------
    AnalysisResult or None
        None while no Allan deviation can be computed yet.

    """
    # The bounds (chi-square quantiles) are computed while the workers search.
    if isinstance(session, Session):    # a fit is due: rows held for the warm-up judged
        session.judge_settling()
    curve = session.curve(confidence=CONFIDENCE, bounds=False)
    if curve is None or curve.tau_s.size < 3:
        return None
    samples, raw_rate = raw_evidence(raw, session.rate_hz)
    fits = dict.fromkeys(AXES)
    jobs = {}
    clipped = left_out(session.stats)     # clipped too much: no honest number (warned)
    for j, axis in enumerate(AXES):
        avar = curve.avar[:, j]
        if (np.all(np.isfinite(avar)) and np.count_nonzero(avar > 0) >= 3
                and axis not in clipped):
            # Held values bias the shortest taus low (core.allan.hold): fit above them.
            first, fitted = held_fit_curve(curve.tau_s, avar, curve.rate_hz,
                                           session.stats.held.get(axis, 0.0))
            jobs[axis] = (curve.tau_s[first:], fitted, curve.edf[first:, j], curve.rate_hz,
                          int(session.stats.n_used),
                          None if samples is None else samples[:, j], raw_rate, AXIS_UNITS[axis])
    found, (lo, hi) = _map_axes(list(jobs.values()), workers, lambda: confidence_bounds(
        curve.avar, curve.edf, CONFIDENCE))
    fits.update(zip(jobs, found))
    thermal, hot = thermal_axes(session, curve, fits, (samples, raw_rate), _map_axes, workers)
    fits, drifts = drift_axes(fits, samples, raw_rate, thermal)     # K that is a slow drift
    fits, changed = level_axes(fits, session.stretches())
    curve = curve._replace(adev_lo=lo, adev_hi=hi)
    plans = _plans(fits, float(session.rate_hz), float(session.duration_s), plan_targets,
                   workers) if plan else {}
    units = unit_warnings(session.rate_hz, None if samples is None else samples.mean(axis=0),
                          _gyro_white(curve, fits), session.config.declared_quantities)
    result = AnalysisResult(
        rate_hz=float(session.rate_hz), duration_s=float(session.duration_s),
        n_samples=int(session.stats.n_used), warnings=tuple(session.warnings) + tuple(units),
        # n_read / n_lost: what the input delivered and lost (a reader overrides them).
        hygiene={**asdict(session.stats), 'n_read': int(session.stats.n_received),
                 'n_lost': 0}, curve=curve, fits=fits,
        source=source, topic=topic,
        covering_tau_max_s=float(covering_tau_max_s), plans=plans, thermal=thermal)
    # No confident wrong number: an axis whose fit is not trusted is a top-level warning,
    # and so is a consumer value the record cannot determine.
    return replace(result, warnings=result.warnings + tuple(result.trust_warnings())
                   + tuple(short_record_warnings(fits, plans, float(session.duration_s)))
                   + hot + drifts + changed
                   + resolution_warnings(session.stats.value_grid, fits, session.rate_hz))


def _gyro_white(curve: AllanCurve, fits: dict) -> np.ndarray:
    """(3,) white noise N of the gyro axes [rad/s/sqrt(Hz)]: the fit's, else ADEV(tau0)."""
    out = np.full(3, np.nan)
    for j, axis in enumerate(AXES[:3]):
        p = fits[axis].optimised.get('N') if fits.get(axis) is not None else None
        if p is not None and p.kind == 'estimate':
            out[j] = p.value
        elif curve.tau_s.size:    # white noise: ADEV(tau) = N / sqrt(tau)
            out[j] = curve.adev[0, j] * math.sqrt(curve.tau_s[0])
    return out


def _plan_job(job: tuple) -> dict:
    """Plan some axes: (fits, rate_hz, duration_s, targets) -> {axis: AxisPlan}."""
    from imu_allan.core.plan.planner import plan_fits  # scipy: in the workers only

    return plan_fits(*job)


def _plans(fits: dict, rate_hz: float, duration_s: float, targets, workers: int) -> dict:
    """Plan the fitted axes, split over the worker processes when workers > 1."""
    fitted = [a for a, f in fits.items() if f is not None]
    pool = worker_pool(min(workers, len(fitted)))
    if pool is None:
        return _plan_job((fits, rate_hz, duration_s, targets))
    jobs = [({a: fits[a] for a in fitted[i::workers]}, rate_hz, duration_s, targets)
            for i in range(workers)]
    with pool:
        done: dict = {}
        for part in pool.map(_plan_job, [j for j in jobs if j[0]]):
            done.update(part)
    return {a: done[a] for a in fitted if a in done}


def _g(x: float) -> str:
    return f'{x:.6g}' if math.isfinite(x) else 'nan'
