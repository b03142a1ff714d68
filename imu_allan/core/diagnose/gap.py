"""
The gap between a measured and a simulated Allan curve, and where it lies.

z(tau) = (ln ADEV_meas - ln ADEV_model) / s(tau) with s(tau) = sqrt(psi_1(edf / 2)) / 2
(the standard deviation of ln ADEV); gap = sqrt(mean z^2); bands where |z| > 2.  Part
of :mod:`imu_allan.core.diagnose`.
"""

from typing import NamedTuple

import numpy as np
from scipy.special import polygamma


#: A gap at or below this (with an acceptable chi-square) is consistent: no search.
GAP_OK = 1.5

#: chi-square p-value below which the fit itself says the model misses something.
P_INCONSISTENT = 1e-3

#: |z| above this marks a tau as disagreeing (two-sided 95 %).
Z_BAND = 2.0


class Band(NamedTuple):
    """
    A range of averaging times where measurement and model disagree beyond 95 %.

    Attributes
    ----------
    tau_range_s : tuple of float
        (first, last) averaging time of the band [s].
    shape : str
        'level' (an offset of one sign), 'slope' (a tilt), 'bump' (a hump or dip inside
        the band) or 'oscillation' (the sign alternates).
    sign : str
        'above' when the measurement lies mostly above the model, else 'below'.
    peak_z : float
        Largest |z| in the band [-].

    """

    tau_range_s: tuple
    shape: str
    sign: str
    peak_z: float

    def to_json(self) -> dict:
        """Return the band as a JSON-ready dict."""
        return {'tau_range_s': [float(v) for v in self.tau_range_s], 'shape': self.shape,
                'sign': self.sign, 'peak_z': float(self.peak_z)}


def ln_adev_stderr(edf) -> np.ndarray:
    """
    Return the standard error s(tau) of ln ADEV for ``edf`` degrees of freedom.

    AVAR_hat ~ AVAR chi2_nu / nu, so Var ln AVAR_hat = psi_1(nu / 2) (trigamma) and
    ln ADEV = ln AVAR / 2 has s = sqrt(psi_1(nu / 2)) / 2 (about 1 / sqrt(2 nu) for
    large nu).

    Parameters
    ----------
    edf : array_like
        Equivalent degrees of freedom, > 0.

    Returns
    -------
    np.ndarray
        s, same shape [-].

    """
    nu = np.maximum(np.asarray(edf, dtype=np.float64), 1e-3)
    return 0.5 * np.sqrt(polygamma(1, 0.5 * nu))


def gap_z(adev_meas, adev_model, s_ln) -> np.ndarray:
    """
    Return the normalised log residuals z = (ln ADEV_meas - ln ADEV_model) / s.

    Parameters
    ----------
    adev_meas, adev_model : array_like
        Shape (k,), measured and model Allan deviation [unit], > 0.
    s_ln : array_like
        Shape (k,), standard error of ln ADEV (:func:`ln_adev_stderr`).

    Returns
    -------
    np.ndarray
        Shape (k,), z [-].

    """
    return (np.log(adev_meas) - np.log(adev_model)) / np.asarray(s_ln, dtype=np.float64)


def gap(adev_meas, adev_model, s_ln) -> float:
    """
    Return the gap: RMS over tau of :func:`gap_z` (about 1 when model and data agree).

    Parameters
    ----------
    adev_meas, adev_model : array_like
        Shape (k,), measured and model Allan deviation [unit].
    s_ln : array_like
        Shape (k,), standard error of ln ADEV.

    Returns
    -------
    float
        The gap [-].

    """
    z = gap_z(adev_meas, adev_model, s_ln)
    return float(np.sqrt(np.mean(z * z)))


def find_bands(tau_s, z, threshold: float = Z_BAND) -> tuple:
    """
    Find the contiguous tau ranges where |z| > threshold, and the disagreement's shape.

    A single agreeing tau between two disagreeing ones does not split a band.  Shape:
    'oscillation' when z changes sign at least twice over the band's extent, 'bump'
    when the interior peak exceeds both ends by more than 2 (in z), 'slope' when a
    straight line in log tau changes by more than 2 across the band, else 'level'.

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s], increasing.
    z : array_like
        Shape (k,), normalised residuals (:func:`gap_z`).
    threshold : float
        |z| that marks disagreement.

    Returns
    -------
    tuple of Band
        The bands, in tau order.

    """
    tau = np.asarray(tau_s, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    bad = np.abs(z) > threshold
    for i in range(1, bad.size - 1):  # bridge single agreeing taus
        if not bad[i] and bad[i - 1] and bad[i + 1]:
            bad[i] = True
    bands = []
    i = 0
    while i < bad.size:
        if not bad[i]:
            i += 1
            continue
        j = i
        while j + 1 < bad.size and bad[j + 1]:
            j += 1
        lo, hi = max(i - 1, 0), min(j + 1, z.size - 1)
        seg = z[lo:hi + 1]
        core = z[i:j + 1]
        signs = np.sign(seg[np.abs(seg) > 1.0])
        changes = int(np.count_nonzero(np.diff(signs) != 0)) if signs.size > 1 else 0
        sign = 'above' if core.sum() >= 0 else 'below'
        x = np.log(tau[i:j + 1])
        a = np.abs(core)
        if changes >= 2:
            shape = 'oscillation'
        elif core.size >= 3 and a[1:-1].max() > max(a[0], a[-1]) + 2.0:
            shape = 'bump'
        elif core.size >= 2 and abs(np.polyfit(x, core, 1)[0] * (x[-1] - x[0])) > 2.0:
            shape = 'slope'
        else:
            shape = 'level'
        bands.append(Band((float(tau[i]), float(tau[j])), shape, sign, float(a.max())))
        i = j + 1
    return tuple(bands)
