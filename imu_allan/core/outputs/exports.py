"""
Outputs in the shapes their consumers read: robot_localization, IMU drivers, VIO configs.

Each function takes the six per-axis sources of :func:`imu_allan.core.outputs.kalman.kalman_model`
(AxisReport, AxisNoise or AxisFit; every value is the axis' report,
:mod:`imu_allan.core.outputs.reported`) and returns YAML text whose keys are the
consumer's own:

* :func:`kalibr_yaml`: Kalibr's imu.yaml (one noise density and random walk per sensor:
  the covering pair);
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
from imu_allan.core.outputs.covering import cover_axes, default_horizon
from imu_allan.core.outputs.kalman import _six, imu_covariance
from imu_allan.core.outputs.reported import CONSUMER_KINDS, report_axes, report_axis
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


class SensorValue(NamedTuple):
    """
    One value of N or K for a whole sensor (three axes), as Kalibr and VIO configs take.

    Attributes
    ----------
    value : float or None
        The value [unit of the symbol], None when no axis gives one.
    kind : str
        The weakest kind among the axes that gave it (:data:`CONSUMER_KINDS`: 'estimate',
        'upper_bound', 'curve_bound'), or 'absent'.
    per_axis : dict of str to tuple
        (value, kind) of each axis ('absent' with 0.0).

    """

    value: float | None
    kind: str
    per_axis: dict


def sensor_value(sources, axes: Sequence[str], symbol: str,
                 reduce: str = 'max') -> SensorValue:
    """
    Reduce the reported N or K of three axes to one value for the sensor.

    Each axis gives its report's value (:mod:`imu_allan.core.outputs.reported`: an
    estimate, a 95 % bound at its bound, or the curve's own bound); every axis with a
    value enters the reduction, so a larger bound on one axis is never ignored.

    Parameters
    ----------
    sources : mapping of str to AxisReport, AxisNoise or AxisFit
        Per axis name.
    axes : sequence of str
        The sensor's three axes.
    symbol : str
        'N' or 'K'.
    reduce : str
        'max' (worst axis) or 'mean'.

    Returns
    -------
    SensorValue

    """
    per = {}
    for a in axes:
        report = report_axis(sources[a], a)
        v = report.white if symbol == 'N' else report.random_walk
        per[a] = (v.value, v.kind)
    got = [(v, k) for v, k in per.values() if k != 'absent']
    if not got:
        return SensorValue(None, 'absent', per)
    kind = max((k for _, k in got), key=CONSUMER_KINDS.index)
    return SensorValue(_reduce([v for v, _ in got], reduce), kind, per)


def _kalibr_pair(reports: dict, covers: dict, axes: Sequence[str], reduce: str) -> dict:
    """Return the written N and K of one sensor: the covering pair, else the reported."""
    got = [covers[a] for a in axes if covers.get(a) is not None]
    if got:
        return {'N': _reduce([c.N_cover for c in got], reduce),
                'K': _reduce([c.K_cover for c in got], reduce), 'pair': 'covering'}
    return {'N': sensor_value(reports, axes, 'N', reduce).value,
            'K': sensor_value(reports, axes, 'K', reduce).value, 'pair': 'reported'}


def kalibr_yaml(sources, rate_hz: float, reduce: str = 'max', rostopic: str = '/imu/data',
                covers: dict | None = None, horizon_s: Sequence[float] | None = None) -> str:
    """
    Write a Kalibr imu.yaml: the covering pair (continuous densities), one per sensor.

    Kalibr models each axis as white noise plus a bias random walk, as the VIO packages
    do, so it gets the one pair every random-walk-only consumer gets: the covering pair
    (:mod:`imu_allan.core.outputs.covering`), which bounds the whole fitted model over
    the horizon and is never below the reported N and K.  One value per sensor: default
    ``reduce='max'``, the worst axis (under-stating any axis' noise makes the
    calibration over-confident on it, over-stating only down-weights it); ``'mean'``
    gives the typical axis.  The reported and covering values per axis are comments.
    A key no axis can give is left out with a comment (Kalibr stops on it; 0 it would
    take).  The values come from :func:`report_axes` (the fit's reported N and K,
    :mod:`imu_allan.core.outputs.reported`) and :func:`cover_axes`; the text is written
    as imu.yaml by :func:`imu_allan.io.report.write_outputs` (``analyze``, the node's
    ``~/save``).

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisReport / AxisNoise / AxisFit, see :func:`kalman_model`.
    rate_hz : float
        IMU message rate [Hz] (Kalibr's update_rate).
    reduce : str
        'max' (worst axis) or 'mean'.
    rostopic : str
        Value of Kalibr's rostopic key (the analysed topic).
    covers : dict of str to AxisCover, optional
        The covering pairs (:func:`cover_axes`); made over ``horizon_s`` when not given.
    horizon_s : sequence of two floats, optional
        Their horizon [s]; default the sample period to 100 s.

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
    reports = report_axes(dict(zip(AXES, _six(sources))))
    horizon_s = default_horizon(rate_hz) if horizon_s is None else horizon_s
    covers = cover_axes(reports, horizon_s) if covers is None else covers
    lines = ['# IMU noise for Kalibr (imu_allan).  Continuous-time densities of the covering',
             '# pair: white noise + bias random walk whose Allan variance bounds the whole',
             f'# fitted model for tau in [{horizon_s[0]:.3g}, {horizon_s[1]:.3g}] s, never '
             'below the',
             f'# reported N and K.  One value per sensor: the {how}.',
             '# B and T_B (bias instability) have no Kalibr key; the pair covers them.']
    keys = []
    mark = {'estimate': '', 'upper_bound': ' (95 % upper bound)',
            'curve_bound': " (the curve's bound)", 'absent': ' (not available)'}
    for sensor, axes, u_n, u_k in (('accelerometer', ACCEL_AXES, 'm/s^2/sqrt(Hz)',
                                    'm/s^3/sqrt(Hz)'),
                                   ('gyroscope', GYRO_AXES, 'rad/s/sqrt(Hz)',
                                    'rad/s^2/sqrt(Hz)')):
        lines.append(f'# {sensor} per axis, reported -> covering:')
        for a in axes:
            r, c = reports[a], covers.get(a)
            text = []
            for sym, v, cov, u in (('N', r.white, c and c.N_cover, u_n),
                                   ('K', r.random_walk, c and c.K_cover, u_k)):
                to = 'n/a' if cov is None else f'{cov:.6e}'
                text.append(f'{sym} = {v.value:.6e}{mark[v.kind]} -> {to} {u}')
            lines.append(f'#   {a}: ' + ', '.join(text))
        pair = _kalibr_pair(reports, covers, axes, reduce)
        for sym, key, u in (('N', f'{sensor}_noise_density', u_n),
                            ('K', f'{sensor}_random_walk', u_k)):
            value = pair[sym]
            if value is None or not value > 0:
                lines.append(f'# {key}: not available on any axis; left out (Kalibr '
                             'needs a positive value: measure a longer record)')
            else:
                keys.append((key, value, u))
    lines += [f'{key}: {value:.6e}  # [{u}]' for key, value, u in keys]
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
