"""
The covariances ``~/imu_with_covariance`` writes into each republished Imu message.

No rclpy here: the node calls :meth:`CovarianceRelay.patch` from its subscription
callback, so every message goes out as it arrives, from the first one on.  Until the
first fit the fields hold the covariances of an earlier result (the node's
``initial_covariance_file``) or, without one, :data:`~imu_allan.core.outputs.kalman.
UNKNOWN_VARIANCE` on the diagonal: a large variance, so a filter leans on its other
inputs, where zeros (sensor_msgs/Imu: "covariance unknown") make robot_localization
fall back to its most confident floor.
"""

import math
from pathlib import Path

import numpy as np
import yaml

from imu_allan.core.outputs.kalman import UNKNOWN_VARIANCE
from imu_allan.errors import InputError
from imu_allan.io.imu_patch import CovariancePatch

_FIELDS = ('angular_velocity_covariance', 'linear_acceleration_covariance')


def load_covariance_file(path) -> tuple:
    """
    Read the two Imu covariance fields of an earlier result.

    Parameters
    ----------
    path : str or Path
        result.json (key ``imu_covariance``) or imu_covariance.yaml of an analysis.

    Returns
    -------
    tuple of np.ndarray
        (angular velocity, linear acceleration) covariances, (9,) each [SI^2].

    Raises
    ------
    InputError
        A missing or unreadable file, or fields that are not 9 finite numbers with a
        non-negative diagonal.

    """
    path = Path(path).expanduser()
    try:
        doc = yaml.safe_load(path.read_text())   # YAML reads the JSON result too
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise InputError(f'initial_covariance_file {path}: cannot read it ({exc})') from None
    if isinstance(doc, dict) and isinstance(doc.get('imu_covariance'), dict):
        doc = doc['imu_covariance']
    if not isinstance(doc, dict) or not all(k in doc for k in _FIELDS):
        raise InputError(f'initial_covariance_file {path}: no {" and ".join(_FIELDS)} '
                         '(give result.json or imu_covariance.yaml of an analysis)')
    out = []
    for key in _FIELDS:
        try:
            cov = np.asarray(doc[key], dtype=np.float64)
        except (TypeError, ValueError):
            cov = np.zeros(0)
        if cov.shape != (9,) or not np.isfinite(cov).all() or (cov[[0, 4, 8]] < 0).any():
            raise InputError(f'initial_covariance_file {path}: {key} must be 9 finite numbers '
                             'with a non-negative diagonal')
        out.append(cov)
    return tuple(out)


class CovarianceRelay:
    """
    The covariance fields of ``~/imu_with_covariance`` and where they come from.

    Parameters
    ----------
    initial : tuple of array_like, optional
        (angular velocity, linear acceleration) covariances, (9,) each, to start from.

    Attributes
    ----------
    source : str
        'unknown' (no values yet), 'file' (the initial covariances) or 'fit'.

    """

    def __init__(self, initial: tuple | None = None):
        if initial is None:
            unknown = np.diag([UNKNOWN_VARIANCE] * 3).ravel()
            self._set(unknown, unknown, 'unknown')
        else:
            gyro, accel = initial
            self._set(gyro, accel, 'file')

    def _set(self, gyro, accel, source: str = 'fit') -> None:
        self.fields = (tuple(float(x) for x in gyro), tuple(float(x) for x in accel))
        self._patch = CovariancePatch(*self.fields)
        self.source = source

    def update(self, imu_covariances: dict) -> None:
        """Take the fields of a new result (``AnalysisResult.imu_covariances()``)."""
        gyro = imu_covariances['angular_velocity_covariance']
        accel = imu_covariances['linear_acceleration_covariance']
        if all(math.isfinite(x) for x in list(gyro) + list(accel)):
            self._set(gyro, accel, 'fit')

    def patch(self, raw: bytes) -> bytes | None:
        """Return ``raw`` with the current covariances, or None for an unusual layout."""
        return self._patch(raw)
