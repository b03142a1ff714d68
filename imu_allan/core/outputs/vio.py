"""
IMU noise files for visual-inertial estimators that read OpenCV FileStorage YAML.

* :func:`vins_yaml`: VINS-Mono / VINS-Fusion ``acc_n, gyr_n, acc_w, gyr_w``.  VINS reads
  them with ``cv::FileStorage`` (vins_estimator/src/estimator/parameters.cpp) and puts
  their squares straight into the pre-integration noise matrix
  (vins_estimator/src/factor/integration_base.h, HKUST-Aerial-Robotics/VINS-Fusion at
  be55a937): per IMU step of length dt the mid-point scheme adds
  (dt/2)^2 gyr_n^2 twice (the two samples of the step) to the attitude and dt^2 gyr_w^2
  to the gyro bias, where the continuous model adds N^2 dt and K^2 dt.  The same
  covariance growth therefore needs, at rate f = 1 / dt::

      gyr_n = N sqrt(2 f),   gyr_w = K sqrt(f)      (acc_n, acc_w alike)

  i.e. per-step standard deviations, not densities; at 100 Hz a density is 14x (noise)
  and 10x (walk) too small there.
* :func:`openvins_yaml`: an OpenVINS ``kalibr_imu_chain.yaml``: ``%YAML:1.0`` first,
  an ``imu0`` node holding the four Kalibr densities (OpenVINS builds sigma^2 / dt and
  sigma^2 dt from them itself), ``rostopic``, ``model`` and the intrinsic matrices Tw,
  R_IMUtoGYRO, Ta, R_IMUtoACC, Tg (ov_msckf/src/core/VioManagerOptions.h and
  state/StateOptions.h, rpng/open_vins at 69488123, read each of these under imu0).

Both write the *covering* pair of :mod:`imu_allan.core.outputs.covering`, as Kalibr's
imu.yaml does: these estimators model the bias as a pure random walk, and the covering
pair is the white + random-walk model whose Allan variance bounds the fitted one over
the stated horizon, never below the reported N and K.  The reported pair and the factor
are written as comments.
"""

import math
from typing import Sequence

from imu_allan import ACCEL_AXES, AXES, GYRO_AXES
from imu_allan.core.outputs.covering import cover_axes, default_horizon, sensor_cover
from imu_allan.core.outputs.exports import sensor_value
from imu_allan.core.outputs.kalman import _six
from imu_allan.core.outputs.reported import report_axes

#: Identity and zero 3x3 matrices in the block-sequence form OpenVINS' examples use.
_EYE = ('    - [1.0, 0.0, 0.0]', '    - [0.0, 1.0, 0.0]', '    - [0.0, 0.0, 1.0]')
_ZERO = ('    - [0.0, 0.0, 0.0]',) * 3
_T_I_B = ('    - [1.0, 0.0, 0.0, 0.0]', '    - [0.0, 1.0, 0.0, 0.0]',
          '    - [0.0, 0.0, 1.0, 0.0]', '    - [0.0, 0.0, 0.0, 1.0]')

_SENSORS = (('accelerometer', 'acc', ACCEL_AXES, 'm/s^2', 'm/s^3'),
            ('gyroscope', 'gyr', GYRO_AXES, 'rad/s', 'rad/s^2'))


def _covered(sources, rate_hz: float, covers, horizon_s) -> tuple:
    """Return the six reports, their covering pairs and the horizon (made when not given)."""
    reports = report_axes(dict(zip(AXES, _six(sources))))
    horizon_s = default_horizon(rate_hz) if horizon_s is None else tuple(horizon_s)
    return reports, (cover_axes(reports, horizon_s) if covers is None else covers), horizon_s


def _pairs(sources, covers, axes: Sequence[str]) -> dict:
    """
    Return the reported and covering N, K of one sensor and which pair is written.

    Returns {'N_fit', 'K_fit', 'N_cov', 'K_cov', 'N', 'K', 'pair'}; the written values are
    the covering ones, or the reported ones where no axis has a pair (None: absent).
    """
    n_fit = sensor_value(sources, axes, 'N').value
    k_fit = sensor_value(sources, axes, 'K').value
    n_cov, k_cov = sensor_cover(covers or {}, axes)
    if n_cov is not None and k_cov is not None and k_cov > 0:
        return {'N_fit': n_fit, 'K_fit': k_fit, 'N_cov': n_cov, 'K_cov': k_cov,
                'N': n_cov, 'K': k_cov, 'pair': 'covering'}
    return {'N_fit': n_fit, 'K_fit': k_fit, 'N_cov': None, 'K_cov': None,
            'N': n_fit, 'K': k_fit, 'pair': 'reported'}


def _g(value) -> str:
    return 'n/a' if value is None else f'{value:.4e}'


def _factor(cov, fit) -> str:
    return f'{cov / fit:.3g}' if cov and fit else 'n/a'


def pair_comments(sources, covers, horizon_s) -> list:
    """
    Comment lines naming the pair written, with fitted, covering and factor per sensor.

    Parameters
    ----------
    sources : mapping of str to AxisReport, AxisNoise or AxisFit
        Per axis.
    covers : dict of str to AxisCover or None, or None
        :func:`imu_allan.core.outputs.covering.cover_axes`.
    horizon_s : sequence of two floats or None
        The covering horizon [s].

    Returns
    -------
    list of str
        YAML comment lines (each starting with '#').

    """
    lines = []
    if covers and horizon_s is not None:
        lines.append('# Covering pair: white + random walk whose Allan variance bounds the '
                     'whole fitted model')
        lines.append(f'# (bias instability, Gauss-Markov terms, K at its bound) for tau in '
                     f'[{horizon_s[0]:.3g}, {horizon_s[1]:.3g}] s.')
    for sensor, _, axes, u, uw in _SENSORS:
        p = _pairs(sources, covers, axes)
        lines.append(f'# {sensor}: reported N {_g(p["N_fit"])} {u}/sqrt(Hz), K {_g(p["K_fit"])} '
                     f'{uw}/sqrt(Hz); covering N {_g(p["N_cov"])}, K {_g(p["K_cov"])} '
                     f'(factor N {_factor(p["N_cov"], p["N_fit"])}, '
                     f'K {_factor(p["K_cov"], p["K_fit"])})')
    return lines


def vins_values(sources, rate_hz: float, covers=None, horizon_s=None) -> dict:
    """
    VINS' four keys, per-step standard deviations at ``rate_hz`` (module docstring).

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit.
    rate_hz : float
        The IMU rate VINS will integrate at [Hz].
    covers : dict of str to AxisCover, optional
        Covering pairs per axis; made over ``horizon_s`` when not given.
    horizon_s : sequence of two floats, optional
        Their horizon [s]; default the sample period to 100 s.

    Returns
    -------
    dict of str to float or None
        acc_n, gyr_n [m/s^2, rad/s], acc_w, gyr_w [m/s^3, rad/s^2]: N sqrt(2 rate) and
        K sqrt(rate); None where the value is unknown.

    """
    srcs, covers, _ = _covered(sources, rate_hz, covers, horizon_s)
    out = {}
    for _, short, axes, _, _ in _SENSORS:
        p = _pairs(srcs, covers, axes)
        out[f'{short}_n'] = None if p['N'] is None else p['N'] * math.sqrt(2.0 * rate_hz)
        out[f'{short}_w'] = None if p['K'] is None else p['K'] * math.sqrt(rate_hz)
    return {k: out[k] for k in ('acc_n', 'gyr_n', 'acc_w', 'gyr_w')}


def vins_yaml(sources, rate_hz: float, covers=None, horizon_s=None) -> str:
    """
    Return the VINS-Mono / VINS-Fusion IMU noise keys as an OpenCV FileStorage fragment.

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit.
    rate_hz : float
        IMU rate VINS integrates at [Hz]; the values hold at this rate only.
    covers : dict of str to AxisCover, optional
        Covering pairs; made over ``horizon_s`` when not given.
    horizon_s : sequence of two floats, optional
        Their horizon [s]; default the sample period to 100 s.

    Returns
    -------
    str
        ``%YAML:1.0`` then acc_n [m/s^2], gyr_n [rad/s], acc_w [m/s^3], gyr_w
        [rad/s^2] (reals), each a per-step standard deviation at ``rate_hz``; a key
        without a value is left out with a comment.

    """
    srcs, covers, horizon_s = _covered(sources, rate_hz, covers, horizon_s)
    values = vins_values(srcs, rate_hz, covers)
    pair = _pairs(srcs, covers, GYRO_AXES)['pair']
    lines = ['%YAML:1.0',
             '# VINS-Mono / VINS-Fusion IMU noise (imu_allan): merge into your VINS config.',
             f'# Per-step standard deviations at {rate_hz:g} Hz, the form VINS uses '
             '(integration_base.h):',
             '#   acc_n, gyr_n = N sqrt(2 rate) [m/s^2, rad/s]; acc_w, gyr_w = K sqrt(rate) '
             '[m/s^3, rad/s^2]',
             '# with N, K the worst-axis densities below.  Valid at this IMU rate only.',
             f'# Written: the {pair} pair.']
    lines += pair_comments(srcs, covers, horizon_s)
    units = {'acc_n': 'm/s^2', 'gyr_n': 'rad/s', 'acc_w': 'm/s^3', 'gyr_w': 'rad/s^2'}
    for key in ('acc_n', 'gyr_n', 'acc_w', 'gyr_w'):
        if values[key] is None:
            lines.append(f'# {key}: not available on any axis (left out)')
        else:
            lines.append(f'{key}: {values[key]:.6e}  # [{units[key]}] per step')
    return '\n'.join(lines) + '\n'


def openvins_yaml(sources, rate_hz: float, rostopic: str = '/imu/data', covers=None,
                  horizon_s=None) -> str:
    """
    Return an OpenVINS ``kalibr_imu_chain.yaml`` (OpenCV FileStorage, node ``imu0``).

    Parameters
    ----------
    sources : mapping or sequence
        Six AxisNoise / AxisFit.
    rate_hz : float
        IMU rate [Hz] (update_rate).
    rostopic : str
        The IMU topic.
    covers : dict of str to AxisCover, optional
        Covering pairs; made over ``horizon_s`` when not given.
    horizon_s : sequence of two floats, optional
        Their horizon [s]; default the sample period to 100 s.

    Returns
    -------
    str
        ``%YAML:1.0`` then ``imu0:`` with T_i_b, the four densities
        (accelerometer_noise_density [m/s^2/sqrt(Hz)], accelerometer_random_walk
        [m/s^3/sqrt(Hz)], gyroscope_noise_density [rad/s/sqrt(Hz)],
        gyroscope_random_walk [rad/s^2/sqrt(Hz)]), rostopic, time_offset, update_rate,
        model "kalibr" and identity intrinsics (Tw, R_IMUtoGYRO, Ta, R_IMUtoACC; Tg 0).

    """
    srcs, covers, horizon_s = _covered(sources, rate_hz, covers, horizon_s)
    pair = _pairs(srcs, covers, GYRO_AXES)['pair']
    lines = ['%YAML:1.0',
             '# OpenVINS IMU file (imu_allan): config/<dataset>/kalibr_imu_chain.yaml, the',
             '# file relative_config_imu names.  Continuous densities (OpenVINS discretises',
             f'# them itself at each IMU interval).  Written: the {pair} pair, worst axis.']
    lines += pair_comments(srcs, covers, horizon_s)
    lines += ['# Intrinsics are identity (an Allan analysis does not calibrate them): keep',
              "# your Kalibr calibration's Tw, R_IMUtoGYRO, Ta, Tg when you have one.",
              '', 'imu0:', '  T_i_b:', *_T_I_B]
    for sensor, _, axes, u, uw in _SENSORS:
        p = _pairs(srcs, covers, axes)
        for key, value, unit in ((f'{sensor}_noise_density', p['N'], f'{u}/sqrt(Hz)'),
                                 (f'{sensor}_random_walk', p['K'], f'{uw}/sqrt(Hz)')):
            if value is None:
                lines.append(f'  # {key}: not available on any axis (left out)')
            else:
                lines.append(f'  {key}: {value:.6e}  # [{unit}]')
    lines += [f'  rostopic: "{rostopic}"', '  time_offset: 0.0',
              f'  update_rate: {float(rate_hz)!r}  # [Hz]', '  model: "kalibr"',
              '  Tw:', *_EYE, '  R_IMUtoGYRO:', *_EYE, '  Ta:', *_EYE,
              '  R_IMUtoACC:', *_EYE, '  Tg:', *_ZERO]
    return '\n'.join(lines) + '\n'
