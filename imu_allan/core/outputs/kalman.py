"""
Kalman-filter inputs from a noise fit: densities, Q and R, the Imu covariances.

The consumer files (Kalibr, robot_localization, VINS, driver scalars) are in
:mod:`imu_allan.core.outputs.exports`; how the VIO and SLAM packages read the numbers is
:data:`imu_allan.core.outputs.consumers.NOTES`.  Which terms enter Q and R is each
term's registry role (``Term.kalman``, :mod:`imu_allan.core.noise.terms`).

Model per axis (the paper's eqs. 14-23, after Farrell; Maia, Silva, De Lima, Meneses):
two bias states, a first-order Gauss-Markov b_GM (correlation time T_B, driving PSD
S_B, paper eq. 8) and a random walk b_RW (PSD S_K = K^2), and white measurement noise
of PSD S_N = N^2::

    d b_GM / dt = -b_GM / T_B + w_GM,   E w_GM w_GM' = S_B delta
    d b_RW / dt = w_RW,                 E w_RW w_RW' = S_K delta
    y = rate + b_GM + b_RW + v,         E v v' = S_N delta

Exact discretisation for a sample period dt (paper eqs. 18-23, exact forms):
Phi_GM = exp(-dt / T_B), Qd_GM = S_B T_B / 2 (1 - exp(-2 dt / T_B)), Qd_RW = S_K dt,
R = S_N / dt.  Six axes give 12 states (order: for each axis in AXES, b_GM then b_RW)
and 6 measurements; :func:`kalman_model` returns both the continuous (F, Qc, Rc) and
the discrete (Phi, Qd, Rd) forms with their labels.

Units: S_N [unit^2 s], S_B and S_K [unit^2/s], Qd [unit^2], R [unit^2], with unit
rad/s (gyro) or m/s^2 (accel).

An upper-bound parameter (a term the record was too short to see) is used at its bound
by default: a filter that under-states a bias's wander becomes over-confident, one that
over-states it only converges a little slower.  A B without T_B (flicker, or T_B not
identified) has no finite-dimensional state: from a fit it becomes a Gauss-Markov state
of the same peak ADEV centred on the fitted taus (:func:`flicker_time_s`); a bare model
without taus keeps its b_GM state frozen (Phi = 1, Qd = 0) and a note says so.
"""

from dataclasses import dataclass
import math
from typing import Mapping

import numpy as np

from imu_allan import ACCEL_AXES, AXES, GYRO_AXES
from imu_allan.core.noise.shapes import GM_PEAK_TAU
from imu_allan.core.noise.terms import TERMS, terms_of
from imu_allan.core.noise.values import AxisNoise
from imu_allan.errors import InputError

#: robot_localization ignores (clamps) variances below this [unit^2].
ROBOT_LOCALIZATION_MIN_VARIANCE = 1e-9
#: Variance of an axis whose noise is not known (no fit, no N) [unit^2]: large, so a
#: filter leans on its other inputs, where 0 or 1e-9 would be the most trust it allows
#: (sensor_msgs/Imu: all zeros mean "unknown", and a consumer must assume something).
UNKNOWN_VARIANCE = 1e4


@dataclass(frozen=True)
class AxisDensities:
    """
    Continuous-time noise densities of one axis.

    Attributes
    ----------
    axis : str
        Axis name (AXES) or '' when unnamed.
    S_N : float
        White measurement noise PSD N^2 [unit^2 s].
    S_B : float
        Gauss-Markov driving PSD (paper eq. 8) [unit^2/s]; 0 when absent.
    T_B : float or None
        Correlation time [s]; None when there is no Gauss-Markov state.
    S_K : float
        Random-walk PSD K^2 [unit^2/s].

    """

    axis: str
    S_N: float
    S_B: float
    T_B: float | None
    S_K: float


@dataclass(frozen=True)
class AxisDiscrete:
    """
    Exact discrete-time form of :class:`AxisDensities` for one sample period.

    Attributes
    ----------
    axis : str
        Axis name.
    dt : float
        Sample period [s].
    phi_gm : float
        exp(-dt / T_B) (1 when there is no Gauss-Markov state).
    qd_gm : float
        S_B T_B / 2 (1 - exp(-2 dt / T_B)) [unit^2].
    qd_rw : float
        S_K dt [unit^2].
    r : float
        S_N / dt [unit^2].

    """

    axis: str
    dt: float
    phi_gm: float
    qd_gm: float
    qd_rw: float
    r: float


@dataclass(frozen=True)
class KalmanModel:
    """
    Six-axis bias model: continuous and discrete matrices with their state order.

    Attributes
    ----------
    state_labels : tuple of str
        12 labels, '<axis>.b_gm' and '<axis>.b_rw' for each axis in AXES order.
    measurement_labels : tuple of str
        6 labels, the axis names.
    dt : float
        Sample period of the discrete forms [s].
    F : np.ndarray
        Shape (12, 12), continuous state matrix: -1/T_B on b_GM, 0 on b_RW [1/s].
    Qc : np.ndarray
        Shape (12, 12), continuous process-noise PSD diag(S_B, S_K, ...) [unit^2/s].
    Rc : np.ndarray
        Shape (6, 6), continuous measurement PSD diag(S_N) [unit^2 s].
    Phi : np.ndarray
        Shape (12, 12), discrete transition diag(exp(-dt/T_B), 1, ...) [-].
    Qd : np.ndarray
        Shape (12, 12), discrete process noise [unit^2].
    Rd : np.ndarray
        Shape (6, 6), discrete measurement noise S_N / dt [unit^2].
    H : np.ndarray
        Shape (6, 12), measurement matrix (each axis sees its b_GM + b_RW) [-].
    axes : tuple of AxisDensities
        The per-axis densities the matrices come from.
    notes : tuple of str
        Choices made (upper bounds used, frozen Gauss-Markov states).

    """

    state_labels: tuple
    measurement_labels: tuple
    dt: float
    F: np.ndarray
    Qc: np.ndarray
    Rc: np.ndarray
    Phi: np.ndarray
    Qd: np.ndarray
    Rd: np.ndarray
    H: np.ndarray
    axes: tuple
    notes: tuple

    def to_json(self) -> dict:
        """Return the matrices as nested lists with their labels (JSON-ready)."""
        return {'state_labels': list(self.state_labels),
                'measurement_labels': list(self.measurement_labels), 'dt_s': self.dt,
                'continuous': {'F': self.F.tolist(), 'Qc': self.Qc.tolist(),
                               'Rc': self.Rc.tolist()},
                'discrete': {'Phi': self.Phi.tolist(), 'Qd': self.Qd.tolist(),
                             'Rd': self.Rd.tolist()},
                'H': self.H.tolist(), 'notes': list(self.notes)}


def _param(fit, symbol: str, use_upper_bounds: bool):
    """Value and kind of a fitted parameter, or (None, None) when absent."""
    p = fit.optimised.get(symbol)
    if p is None or not math.isfinite(p.value):
        return None, None
    if p.kind == 'upper_bound' and not use_upper_bounds:
        return 0.0, p.kind
    return float(p.value), p.kind


def axis_noise_from(source, use_upper_bounds: bool = True) -> tuple[AxisNoise, tuple]:
    """
    Return the AxisNoise a Kalman filter should use, from an AxisNoise or an AxisFit.

    Parameters
    ----------
    source : AxisNoise or imu_allan.core.fit.AxisFit
        A model, or a fit (its optimised parameters are used).
    use_upper_bounds : bool
        With a fit: use a parameter reported as an upper bound at its bound (True,
        conservative) or drop it (False).

    Returns
    -------
    noise : AxisNoise
        N, B, T_B, K in SI.
    notes : tuple of str
        What was substituted.

    """
    if isinstance(source, AxisNoise):
        return source, ()
    if not hasattr(source, 'optimised'):
        raise InputError(f'expected an AxisNoise or an AxisFit, got {type(source).__name__}')
    notes = []
    values = {}
    for sym in ('N', 'B', 'T_B', 'K'):
        value, kind = _param(source, sym, use_upper_bounds)
        values[sym] = value
        if kind == 'upper_bound' and use_upper_bounds:
            notes.append(f'{sym} used at its 95 % upper bound')
    t_b = values['T_B'] if values['T_B'] else None
    if values['B'] and t_b is None and getattr(source, 'tau_s', None) is not None:
        t_b = flicker_time_s(source.tau_s)
        notes.append(f'B is flicker (no T_B): modelled as a Gauss-Markov state of the same '
                     f'peak ADEV with T_B = {t_b:.3g} s (peak at the middle of the fitted '
                     'taus)')
    # Terms without a field of their own (a newly registered term) enter through their
    # registry role at the fit's values (see :func:`axis_densities`).
    extra = getattr(source, 'model', AxisNoise()).extra
    noise = AxisNoise(N=values['N'] or 0.0, B=values['B'] or 0.0, T_B=t_b, K=values['K'] or 0.0,
                      extra=extra)
    return noise, tuple(notes)


def flicker_time_s(tau_s) -> float:
    """
    Correlation time of the Gauss-Markov state that stands in for flicker noise.

    Flicker noise (ADEV 0.664 B at every tau) has no finite-dimensional state.  A
    Gauss-Markov process with the same B (paper eq. 8: its ADEV peaks at 0.664 B, at
    tau = 1.89 T) matches it at the geometric middle of the fitted taus, and falls
    below it by 1.8 dB (ADEV) half a decade above, 5.9 dB a decade above
    (closed forms of IEEE Std 952 C.1): the filter's bias state then wanders like the
    sensor over the averaging times the record could see.

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), the fitted averaging times [s].

    Returns
    -------
    float
        T_B [s].

    """
    tau = np.asarray(tau_s, dtype=np.float64)
    return float(math.sqrt(tau.min() * tau.max()) / GM_PEAK_TAU)


def axis_densities(noise: AxisNoise, axis: str = '') -> AxisDensities:
    """
    Continuous densities of one axis: S_N = N^2, S_B (paper eq. 8), S_K = K^2.

    Each term of the model enters by its registry role (``Term.kalman``): 'white'
    terms add their coefficient (N^2) to S_N, 'b_rw' terms theirs (K^2) to S_K, the
    first 'b_gm' term is the Gauss-Markov state (S_B and T_B); further Gauss-Markov
    processes, flicker, quantization, ramp and sinusoids are not in Q or R.

    Parameters
    ----------
    noise : AxisNoise
        The axis model, SI units.
    axis : str
        Axis name for labels.

    Returns
    -------
    AxisDensities
        S_B = 0 and T_B None when B is 0 or has no T_B.

    """
    s_n = s_k = s_b = 0.0
    t_b = None
    for _, name, params in terms_of(noise):
        term = TERMS[name]
        nonlinear = [params[s] for s in term.nonlinear]
        coef = term.to_coef(params[term.symbols[0]], *nonlinear)
        if term.kalman == 'white':
            s_n += coef
        elif term.kalman == 'b_rw':
            s_k += coef
        elif term.kalman == 'b_gm' and t_b is None:
            s_b, t_b = coef, float(nonlinear[0])
    return AxisDensities(axis=axis, S_N=s_n, S_B=s_b, T_B=t_b, S_K=s_k)


def discretise(d: AxisDensities, dt: float) -> AxisDiscrete:
    """
    Exact discretisation of one axis (paper eqs. 18-23, exact forms).

    Parameters
    ----------
    d : AxisDensities
        Continuous densities.
    dt : float
        Sample period [s], > 0.

    Returns
    -------
    AxisDiscrete
        phi_gm = exp(-dt/T_B), qd_gm = S_B T_B / 2 (1 - exp(-2 dt/T_B)),
        qd_rw = S_K dt, r = S_N / dt.

    """
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise InputError(f'sample period must be a positive number of seconds, got {dt!r}')
    if d.T_B:
        phi = math.exp(-dt / d.T_B)
        # -expm1 keeps the digits of 1 - exp(-2 dt/T) when dt << T.
        qd_gm = d.S_B * d.T_B / 2.0 * -math.expm1(-2.0 * dt / d.T_B)
    else:
        phi, qd_gm = 1.0, 0.0
    return AxisDiscrete(axis=d.axis, dt=float(dt), phi_gm=phi, qd_gm=qd_gm,
                        qd_rw=d.S_K * dt, r=d.S_N / dt)


def _six(sources) -> list:
    """Normalise per-axis inputs to a list in AXES order."""
    if isinstance(sources, Mapping):
        missing = [a for a in AXES if a not in sources]
        if missing:
            raise InputError(f'noise models missing for axes: {", ".join(missing)}')
        return [sources[a] for a in AXES]
    sources = list(sources)
    if len(sources) != len(AXES):
        raise InputError(f'expected {len(AXES)} axis models in AXES order, got {len(sources)}')
    return sources


def kalman_model(sources, rate_hz: float, use_upper_bounds: bool = True) -> KalmanModel:
    """
    Q and R of the six-axis bias model (paper eqs. 16-17), continuous and discrete.

    Parameters
    ----------
    sources : mapping of axis name to AxisNoise or AxisFit, or a sequence of six
        One model (or fit) per axis of AXES.
    rate_hz : float
        Sample rate [Hz]; dt = 1 / rate_hz.
    use_upper_bounds : bool
        See :func:`axis_noise_from`.

    Returns
    -------
    KalmanModel
        12 states (b_GM, b_RW per axis), 6 measurements, labelled.

    """
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    dt = 1.0 / float(rate_hz)
    n = len(AXES)
    F = np.zeros((2 * n, 2 * n))
    Qc = np.zeros_like(F)
    Phi = np.eye(2 * n)
    Qd = np.zeros_like(F)
    Rc = np.zeros((n, n))
    Rd = np.zeros((n, n))
    H = np.zeros((n, 2 * n))
    labels, dens, notes = [], [], []
    for i, (axis, src) in enumerate(zip(AXES, _six(sources))):
        noise, sub = axis_noise_from(src, use_upper_bounds)
        notes += [f'{axis}: {s}' for s in sub]
        d = axis_densities(noise, axis)
        if noise.B > 0 and d.T_B is None:
            notes.append(f'{axis}: B without T_B has no Gauss-Markov state (b_gm frozen)')
        disc = discretise(d, dt)
        g, r = 2 * i, 2 * i + 1
        labels += [f'{axis}.b_gm', f'{axis}.b_rw']
        F[g, g] = -1.0 / d.T_B if d.T_B else 0.0
        Qc[g, g], Qc[r, r] = d.S_B, d.S_K
        Phi[g, g] = disc.phi_gm
        Qd[g, g], Qd[r, r] = disc.qd_gm, disc.qd_rw
        Rc[i, i], Rd[i, i] = d.S_N, disc.r
        H[i, g] = H[i, r] = 1.0
        dens.append(d)
    return KalmanModel(state_labels=tuple(labels), measurement_labels=tuple(AXES), dt=dt,
                       F=F, Qc=Qc, Rc=Rc, Phi=Phi, Qd=Qd, Rd=Rd, H=H, axes=tuple(dens),
                       notes=tuple(notes))


@dataclass(frozen=True)
class ImuCovariance:
    """
    Diagonal covariances for sensor_msgs/Imu (robot_localization reads these).

    Attributes
    ----------
    angular_velocity_variance : tuple of float
        (x, y, z) variances N^2 rate_hz [rad^2/s^2], clamped to >= 1e-9.
    linear_acceleration_variance : tuple of float
        (x, y, z) variances [m^2/s^4], clamped likewise.
    angular_velocity_covariance : tuple of float
        The 9 row-major entries of the message field (diagonal).
    linear_acceleration_covariance : tuple of float
        The 9 row-major entries of the message field (diagonal).
    clamped : tuple of str
        Axes whose variance was raised to the 1e-9 floor.
    unknown : tuple of str
        Axes without a white-noise value, given :data:`UNKNOWN_VARIANCE`.

    """

    angular_velocity_variance: tuple
    linear_acceleration_variance: tuple
    angular_velocity_covariance: tuple
    linear_acceleration_covariance: tuple
    clamped: tuple
    unknown: tuple = ()


def imu_covariance(sources, rate_hz: float) -> ImuCovariance:
    """
    Per-message covariance diagonals of sensor_msgs/Imu for robot_localization.

    robot_localization has no bias states and no noise parameters; it takes the
    variance of each sample from the message: for white noise of density N sampled at
    rate f, var = N^2 f (the bias terms are not white and are left out).
    robot_localization clamps variances below 1e-9; this function clamps them the same
    way and lists the clamped axes, so what is published is what gets used.  An axis
    without N gets :data:`UNKNOWN_VARIANCE`, not the floor.

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit, see :func:`kalman_model`.
    rate_hz : float
        Message rate [Hz].

    Returns
    -------
    ImuCovariance
        Variances and the 9-element covariance fields.

    """
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    noises = {a: axis_noise_from(s)[0] for a, s in zip(AXES, _six(sources))}
    var, clamped, unknown = {}, [], []
    for a in AXES:
        s_n = axis_densities(noises[a]).S_N
        v = s_n * float(rate_hz)
        if not s_n > 0:
            unknown.append(a)
            v = UNKNOWN_VARIANCE
        elif v < ROBOT_LOCALIZATION_MIN_VARIANCE:
            clamped.append(a)
            v = ROBOT_LOCALIZATION_MIN_VARIANCE
        var[a] = v

    def field(axes):
        m = np.zeros((3, 3))
        np.fill_diagonal(m, [var[a] for a in axes])
        return tuple(float(x) for x in m.ravel())

    return ImuCovariance(
        angular_velocity_variance=tuple(var[a] for a in GYRO_AXES),
        linear_acceleration_variance=tuple(var[a] for a in ACCEL_AXES),
        angular_velocity_covariance=field(GYRO_AXES),
        linear_acceleration_covariance=field(ACCEL_AXES), clamped=tuple(clamped),
        unknown=tuple(unknown))
