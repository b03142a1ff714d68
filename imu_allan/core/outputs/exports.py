"""
Outputs in the shapes their consumers read: robot_localization, IMU drivers, VIO configs.

Each function takes the six per-axis sources of :func:`imu_allan.core.outputs.kalman.kalman_model`
(AxisNoise or AxisFit) and returns YAML text whose keys are the consumer's own:

* :func:`kalibr_yaml`: Kalibr's imu.yaml (one noise density and random walk per sensor,
  :func:`sensor_value`);
* :func:`robot_localization_yaml`: an ``ekf.yaml`` fragment (robot_localization reads
  IMU noise from each message's covariance fields; the Allan result does not enter its
  ``process_noise_covariance``, which is a motion model without bias states);
* :func:`driver_yaml`: per-axis and worst-axis standard deviations and variances per
  sample, N sqrt(rate) and N^2 rate, for driver parameters (phidgets_spatial and mavros
  ``angular_velocity_stdev`` / ``linear_acceleration_stdev``, microstrain
  ``imu_angular_cov`` / ``imu_linear_cov``, realsense2_camera ``angular_velocity_cov``
  / ``linear_accel_cov``);
* the VINS-Mono / VINS-Fusion and OpenVINS files are in :mod:`imu_allan.core.outputs.vio`.

Only numpy and the package core are imported: the node and the CLI write these files.
"""

import math
from typing import NamedTuple, Sequence

import numpy as np

from imu_allan import ACCEL_AXES, AXES, GYRO_AXES
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.outputs.kalman import _param, _six, axis_densities, imu_covariance
from imu_allan.errors import InputError

#: robot_localization's imu0_config order (15 booleans): x y z, roll pitch yaw, vx vy vz,
#: vroll vpitch vyaw, ax ay az.  An IMU gives angular velocity and linear acceleration;
#: its orientation is the driver's own filter output, which an Allan analysis does not
#: characterise.
IMU0_CONFIG = (False, False, False, False, False, False, False, False, False,
               True, True, True, True, True, True)
#: Mahalanobis rejection threshold suggested for the IMU (in standard deviations):
#: a 3-D Gaussian innovation exceeds it with probability ~1e-6 (sqrt of the chi-square
#: 1 - 1e-6 quantile with 3 degrees of freedom).
REJECTION_SIGMAS = 5.7


def _reduce(values: Sequence[float], how: str) -> float:
    if how == 'max':
        return float(max(values))
    if how == 'mean':
        return float(np.mean(values))
    raise InputError(f"axis reduction must be 'max' or 'mean', got {how!r}")


def _kinded(source, symbol: str, use_upper_bounds: bool) -> tuple[float, str]:
    """
    Value of N or K for one axis with its kind ('estimate', 'upper_bound', 'absent').

    An AxisNoise carries estimates (0 means absent): N and K are the square roots of
    the white and random-walk densities its terms add up to by their registry roles
    (:func:`imu_allan.core.outputs.kalman.axis_densities`).  An AxisFit gives its
    optimised parameter, an upper bound only when ``use_upper_bounds`` (otherwise it
    counts as absent), plus what terms without a field of their own add by their roles.
    """
    if isinstance(source, AxisNoise):
        d = axis_densities(source)
        value = math.sqrt(d.S_N if symbol == 'N' else d.S_K)
        return value, ('estimate' if value > 0 else 'absent')
    value, kind = _param(source, symbol, use_upper_bounds)
    if value is None or kind not in ('estimate', 'upper_bound') or value <= 0:
        return 0.0, 'absent'
    model = getattr(source, 'model', None)
    if model is not None and model.extra:
        d = axis_densities(AxisNoise(extra=model.extra))
        value = math.sqrt(value ** 2 + (d.S_N if symbol == 'N' else d.S_K))
    return value, kind


def _curve_bound(source, symbol: str) -> float:
    """
    Bound of N or K that the measured curve itself sets, 0.0 without a curve.

    No term can exceed the whole measured AVAR at any tau: N^2 / tau <= AVAR(tau) and
    K^2 tau / 3 <= AVAR(tau) (IEEE Std 952 C.1 slopes), so N <= min sqrt(AVAR tau) and
    K <= min sqrt(3 AVAR / tau) over the fitted taus.  K's minimum falls on the longest
    taus, whose few degrees of freedom let a point lie far below the truth: with the
    curve's EDF the bound is the fit's own 95 % one
    (:func:`imu_allan.core.fit.trust.curve_k_bound`).
    """
    tau, avar = getattr(source, 'tau_s', None), getattr(source, 'avar_meas', None)
    if tau is None or avar is None or not np.size(tau):
        return 0.0
    tau, avar = np.asarray(tau, dtype=np.float64), np.asarray(avar, dtype=np.float64)
    edf = getattr(source, 'edf', None)
    if symbol == 'K' and edf is not None and np.size(edf) == tau.size:
        from imu_allan.core.fit.trust import curve_k_bound   # scipy: only on this path
        return curve_k_bound(tau, avar, np.asarray(edf, dtype=np.float64))
    level = avar * tau if symbol == 'N' else 3.0 * avar / tau
    return float(np.sqrt(np.min(level)))


class SensorValue(NamedTuple):
    """
    One value of N or K for a whole sensor (three axes), as Kalibr and VIO configs take.

    Attributes
    ----------
    value : float or None
        The value [unit of the symbol], None when no axis gives one.
    kind : str
        'estimate', 'upper_bound' (the axes' 95 % bounds), 'curve_bound' (the measured
        curve's own bound: the record cannot separate the term) or 'absent'.
    per_axis : dict of str to tuple
        (value, kind) of each axis ('absent' with 0.0).

    """

    value: float | None
    kind: str
    per_axis: dict


def sensor_value(sources, axes: Sequence[str], symbol: str, reduce: str = 'max',
                 use_upper_bounds: bool = True) -> SensorValue:
    """
    Reduce N or K of three axes to one positive value for the sensor.

    Only axes where the term was *estimated* enter the reduction: an upper bound (a term
    the record was too short to see on that axis) can lie far above the values the other
    axes measure (an accelerometer K bound of 1e-4 beside estimates of 8e-6), so it
    would dominate 'max' without being a measurement.  Without any estimate (and with
    ``use_upper_bounds``) the axes' 95 % bounds are used, then the bound the measured
    curve sets (:func:`_curve_bound`); never 0, which Kalibr's and the VIO packages'
    config readers reject.

    Parameters
    ----------
    sources : mapping of str to AxisNoise or AxisFit
        Per axis name.
    axes : sequence of str
        The sensor's three axes.
    symbol : str
        'N' or 'K'.
    reduce : str
        'max' (worst axis) or 'mean'.
    use_upper_bounds : bool
        Fall back to bounds when no axis has an estimate (True) or give None.

    Returns
    -------
    SensorValue

    """
    per = {a: _kinded(sources[a], symbol, use_upper_bounds) for a in axes}
    for kind in ('estimate', 'upper_bound'):
        got = [v for v, k in per.values() if k == kind]
        if got:
            return SensorValue(_reduce(got, reduce), kind, per)
    if use_upper_bounds:
        got = [b for b in (_curve_bound(sources[a], symbol) for a in axes) if b > 0]
        if got:
            return SensorValue(_reduce(got, reduce), 'curve_bound', per)
    return SensorValue(None, 'absent', per)


def kalibr_yaml(sources, rate_hz: float, reduce: str = 'max', rostopic: str = '/imu/data',
                use_upper_bounds: bool = True) -> str:
    """
    Write a Kalibr imu.yaml (continuous densities: noise density = N, random walk = K).

    Kalibr takes one value per sensor for all three axes (:func:`sensor_value`).
    Default ``reduce='max'``: the worst axis, because under-stating any axis' noise
    makes the calibration (and a filter tuned from it) over-confident on that axis,
    while over-stating only down-weights it; ``'mean'`` gives the typical axis.
    Per-axis values are written as comments.  Every value written is positive: a key
    no axis can give (``use_upper_bounds`` False, or a model without that term) is left
    out with a comment, so Kalibr stops on it instead of using 0.

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit, see :func:`kalman_model`.
    rate_hz : float
        IMU message rate [Hz] (Kalibr's update_rate).
    reduce : str
        'max' (worst axis) or 'mean'.
    rostopic : str
        Value of Kalibr's rostopic key (the analysed topic).
    use_upper_bounds : bool
        Fall back to bounds when no axis has an estimate, see :func:`sensor_value`.

    Returns
    -------
    str
        YAML text with keys accelerometer_noise_density [m/s^2/sqrt(Hz)],
        accelerometer_random_walk [m/s^3/sqrt(Hz)], gyroscope_noise_density
        [rad/s/sqrt(Hz)], gyroscope_random_walk [rad/s^2/sqrt(Hz)], rostopic,
        update_rate [Hz].

    """
    if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    how = {'max': 'worst (largest) axis', 'mean': 'mean of the three axes'}.get(reduce)
    _reduce([0.0], reduce)  # validates ``reduce``
    srcs = dict(zip(AXES, _six(sources)))
    lines = ['# IMU noise for Kalibr (imu_allan).  Continuous-time densities:',
             '# noise_density = N (white noise), random_walk = K (bias random walk).',
             f'# One value per sensor: the {how} of the per-axis estimates below',
             '# (axes where a term is only an upper bound are left out of it).',
             '# B and T_B (bias instability, Gauss-Markov) have no Kalibr key.']
    keys, remarks = [], []
    for sensor, axes, u_n, u_k in (('accelerometer', ACCEL_AXES, 'm/s^2/sqrt(Hz)',
                                    'm/s^3/sqrt(Hz)'),
                                   ('gyroscope', GYRO_AXES, 'rad/s/sqrt(Hz)',
                                    'rad/s^2/sqrt(Hz)')):
        got = {sym: sensor_value(srcs, axes, sym, reduce, use_upper_bounds)
               for sym in ('N', 'K')}
        lines.append(f'# {sensor} per axis:')
        for a in axes:
            text = []
            for sym, u in (('N', u_n), ('K', u_k)):
                value, kind = got[sym].per_axis[a]
                mark = {'estimate': '', 'upper_bound': ' (95 % upper bound)',
                        'absent': ' (not available)'}[kind]
                text.append(f'{sym} = {value:.6e} {u}{mark}')
            lines.append(f'#   {a}: ' + ', '.join(text))
        for sym, key, u in (('N', f'{sensor}_noise_density', u_n),
                            ('K', f'{sensor}_random_walk', u_k)):
            sv = got[sym]
            n_est = sum(k == 'estimate' for _, k in sv.per_axis.values())
            if sv.kind == 'estimate' and n_est < len(axes):
                remarks.append(f'# {key}: from the {n_est} axes with an estimate; '
                               'the others only bound it')
            elif sv.kind == 'upper_bound':
                remarks.append(f'# {key}: no axis has an estimate; this is the '
                               f'{reduce} of the 95 % upper bounds (the record is too '
                               'short to measure it)')
            elif sv.kind == 'curve_bound':
                remarks.append(f'# {key}: no axis has an estimate or a bound; this is '
                               'the bound the measured curve sets (conservative)')
            elif sv.kind == 'absent':
                remarks.append(f'# {key}: not available on any axis; left out (Kalibr '
                               'needs a positive value: measure a longer record)')
            keys.append((key, sv.value, u))
    lines += remarks
    lines += [f'{key}: {value:.6e}  # [{u}]' for key, value, u in keys if value is not None]
    lines.append(f'rostopic: {rostopic}')
    lines.append(f'update_rate: {float(rate_hz):g}  # [Hz]')
    return '\n'.join(lines) + '\n'


class DriverNoise(NamedTuple):
    """
    Per-sample noise for driver parameters.

    Attributes
    ----------
    rate_hz : float
        Sample rate the values hold for [Hz].
    stdev : dict of str to float or None
        Per axis, N sqrt(rate_hz) [rad/s or m/s^2]; None where N is unknown.
    variance : dict of str to float or None
        Per axis, N^2 rate_hz [rad^2/s^2 or m^2/s^4].
    worst : dict of str to float or None
        'angular_velocity_stdev', 'linear_acceleration_stdev' and the two variances:
        the largest known axis of each sensor.

    """

    rate_hz: float
    stdev: dict
    variance: dict
    worst: dict


def driver_noise(sources, rate_hz: float) -> DriverNoise:
    """
    Return the white-noise standard deviation and variance of one sample per axis.

    A sample at rate f of white noise with density N has variance N^2 f (the bias
    terms are not white and have no slot in these parameters).  Drivers take one value
    per sensor: the worst axis, since under-stating an axis makes a filter
    over-confident on it.

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit, see :func:`imu_allan.core.outputs.kalman.kalman_model`.
    rate_hz : float
        Sample rate [Hz].

    Returns
    -------
    DriverNoise

    """
    cov = imu_covariance(sources, rate_hz)
    variances = dict(zip(GYRO_AXES, cov.angular_velocity_variance))
    variances.update(zip(ACCEL_AXES, cov.linear_acceleration_variance))
    var = {a: (None if a in cov.unknown else float(variances[a])) for a in AXES}
    std = {a: (None if v is None else math.sqrt(v)) for a, v in var.items()}
    worst = {}
    for field, axes in (('angular_velocity', GYRO_AXES), ('linear_acceleration', ACCEL_AXES)):
        known = [v for v in (var[a] for a in axes) if v is not None]
        worst[f'{field}_variance'] = max(known) if known else None
        worst[f'{field}_stdev'] = math.sqrt(max(known)) if known else None
    return DriverNoise(float(rate_hz), std, var, worst)


def _num(value) -> str:
    return 'null' if value is None else f'{value:.6e}'


def driver_yaml(sources, rate_hz: float) -> str:
    """
    Return the driver scalars as YAML (per axis and worst axis, stdev and variance).

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit.
    rate_hz : float
        Sample rate [Hz]; the values hold for this rate only.

    Returns
    -------
    str
        YAML text: ``rate_hz``, ``worst`` (angular_velocity_stdev [rad/s],
        linear_acceleration_stdev [m/s^2] and the variances) and ``per_axis``.

    """
    d = driver_noise(sources, rate_hz)
    lines = ['# IMU driver noise parameters (imu_allan): white noise of one sample at',
             '# rate_hz, stdev = N * sqrt(rate_hz), variance = N^2 * rate_hz.  Valid only at',
             '# this output rate.  Paste the worst-axis value into the driver:',
             '#   phidgets_spatial, mavros (imu plugin): angular_velocity_stdev,',
             '#     linear_acceleration_stdev',
             '#   realsense2_camera: angular_velocity_cov, linear_accel_cov (variances)',
             '#   microstrain_inertial_driver: imu_angular_cov, imu_linear_cov (9 entries,',
             '#     variance on the diagonal)',
             '# null: not known on that axis (no white-noise value).',
             f'rate_hz: {d.rate_hz:g}',
             'worst:']
    units = {'angular_velocity_stdev': 'rad/s', 'linear_acceleration_stdev': 'm/s^2',
             'angular_velocity_variance': 'rad^2/s^2',
             'linear_acceleration_variance': 'm^2/s^4'}
    for key in ('angular_velocity_stdev', 'linear_acceleration_stdev',
                'angular_velocity_variance', 'linear_acceleration_variance'):
        lines.append(f'  {key}: {_num(d.worst[key])}  # [{units[key]}]')
    lines.append('per_axis:')
    for a in AXES:
        u = 'rad/s' if a in GYRO_AXES else 'm/s^2'
        lines.append(f'  {a}: {{stdev: {_num(d.stdev[a])}, variance: {_num(d.variance[a])}}}'
                     f'  # [{u}], [({u})^2]')
    return '\n'.join(lines) + '\n'


def robot_localization_yaml(sources, rate_hz: float, imu_topic: str,
                            node_name: str = 'ekf_filter_node',
                            orientation: bool = True) -> str:
    """
    Return an ekf.yaml fragment for ROS 2 robot_localization that fuses this IMU.

    robot_localization takes IMU noise from each message's covariance fields, not from
    its parameters, so ``imu_topic`` should be a topic that carries the Allan
    variances (the node's ``~/imu_with_covariance``, or the driver once its covariance
    parameters are set from :func:`driver_yaml`).  The parameter names are the ones ROS 2
    robot_localization declares for an IMU (src/ros_filter.cpp, branch ros2:
    ``imu0_twist_rejection_threshold`` gates the angular velocity, not the ROS 1
    ``imu0_angular_velocity_rejection_threshold``).

    Gravity removal needs roll and pitch.  robot_localization takes them from the
    message's orientation, or, when the message says it has none (orientation_covariance
    [0] = -1), from the filter state.  With ``orientation`` True (a driver that publishes
    an attitude) the fragment fuses angular velocity and linear acceleration
    (:data:`IMU0_CONFIG`) with gravity removal.  With ``orientation`` False (raw IMUs,
    RealSense) nothing in the fragment fuses roll and pitch, so gravity could not be
    removed correctly on a slope: that variant fuses angular velocity only.

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit.
    rate_hz : float
        Sample rate [Hz].
    imu_topic : str
        The Imu topic to fuse (a name, not empty).
    node_name : str
        The EKF node's name (the YAML's top-level key).
    orientation : bool
        Whether the messages carry an orientation (see above).

    Returns
    -------
    str
        YAML text: ``<node_name>: ros__parameters:`` with imu0, imu0_config (15
        booleans), imu0_differential, imu0_relative, imu0_queue_size (int),
        imu0_remove_gravitational_acceleration and the rejection thresholds (doubles).

    Raises
    ------
    InputError
        An empty topic or node name.

    """
    if not imu_topic or not node_name:
        raise InputError('the robot_localization fragment needs an IMU topic and a node name')
    d = driver_noise(sources, rate_hz)

    def sd(key):
        v = d.worst[key]
        return 'unknown' if v is None else f'{v:.3e}'

    config = IMU0_CONFIG if orientation else IMU0_CONFIG[:12] + (False,) * 3
    flags = ', '.join('true' if f else 'false' for f in config)
    # At least two messages per filter step of a 50 Hz filter, and never fewer than 10.
    queue = max(10, int(math.ceil(2.0 * rate_hz / 50.0)))
    if orientation:
        assumes = [
            '# Assumes the messages carry an orientation (orientation_covariance[0] != -1):',
            '# robot_localization removes gravity with that roll/pitch.  Without one (raw',
            "# IMUs, RealSense: covariance -1) it would use the filter's roll/pitch, which",
            '# nothing here fuses: use the no-orientation variant (ekf_imu_no_orientation',
            '# .yaml) or fuse roll/pitch from another source.']
    else:
        assumes = [
            '# Variant for IMUs without orientation (orientation_covariance[0] = -1): fuses',
            '# angular velocity only.  Gravity removal would need roll/pitch that nothing',
            '# here provides, so accelerations are off; turn ax, ay, az and gravity removal',
            '# back on only when another input fuses roll and pitch (or two_d_mode on level',
            '# ground).']
    lines = [
        '# robot_localization (ROS 2) fragment (imu_allan): merge into your ekf.yaml.',
        '# What the Allan analysis sets: the IMU noise robot_localization uses comes from',
        "# each message's covariance fields; fuse a topic that carries them (the node's",
        '# ~/imu_with_covariance, or the driver once its covariance parameters are set).',
        f'# Worst-axis stdev per sample at {rate_hz:g} Hz (fitted white noise): angular '
        f'velocity {sd("angular_velocity_stdev")} rad/s,',
        f'# linear acceleration {sd("linear_acceleration_stdev")} m/s^2.',
        *assumes,
        '# What it does not set: process_noise_covariance (a motion model of the robot',
        '# without IMU bias states: tune it for your vehicle), the biases themselves',
        '# (robot_localization has no bias states: B, T_B and K have no slot), and the',
        '# orientation (the driver filter output, not characterised here).  Allan values',
        '# come from a still sensor: in motion, vibration adds noise, so inflate them if',
        '# the filter rejects good data.',
        f'{node_name}:',
        '  ros__parameters:',
        f'    imu0: {imu_topic}',
        '    # x, y, z, roll, pitch, yaw, vx, vy, vz, vroll, vpitch, vyaw, ax, ay, az',
        f'    imu0_config: [{flags}]',
        '    imu0_differential: false',
        '    imu0_relative: false',
        f'    imu0_queue_size: {queue}',
        f'    imu0_remove_gravitational_acceleration: {"true" if orientation else "false"}',
        '    # Mahalanobis distance [standard deviations]: a 3-D innovation exceeds it with',
        '    # probability ~1e-6 when the covariances are right.  twist = angular velocity.',
        f'    imu0_twist_rejection_threshold: {REJECTION_SIGMAS!r}',
    ]
    if orientation:
        lines.append(f'    imu0_linear_acceleration_rejection_threshold: {REJECTION_SIGMAS!r}')
    return '\n'.join(lines) + '\n'
