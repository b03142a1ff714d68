"""
Expected interval widths of the fitted parameters for a record of any length.

A fitted model (its terms, coefficients and nonlinear parameters) says what the Allan
curve of a longer record of the same sensor would look like, and the exact covariance
Sigma of that curve under the model (:mod:`imu_allan.core.fit.covariance`).  The GLS fit
weights the curve with Sigma^-1, so the covariance of its parameters theta (here the
logarithms of the reported parameters N, B, T_B, K ...) is the inverse of the Fisher
information F = J^T Sigma^-1 J, J = d avar / d theta at the taus the fit would use
(Cramer-Rao; the GLS estimate attains it to first order: Bates & Watts, nonlinear
regression, ch. 2).  The expected 95 % interval of log p is +-z sd, so its relative
half-width (hi - lo) / (2 p) is sinh(z sd), the width the profile intervals of the fit
report; z^2 is the fit's own profile threshold, chi2(0.95; 1) = 3.84 scaled by the
dispersion the fit sees on average (:func:`interval_threshold`).
"""

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np

from imu_allan.core.allan.quantiles import chi2_ppf, chi2_sf, f_ppf
from imu_allan.core.allan.taus import tau_grid
from imu_allan.core.fit.axis import thin
from imu_allan.core.fit.covariance import CurveCovariance
from imu_allan.core.noise.terms import base_name, Term, TERMS

#: Two-sided 95 % normal quantile.
Z95 = 1.959963984540054
#: Relative step of the log-parameter derivatives.
_STEP = 1e-4
#: A log-sd above this is "not identified" (the interval spans many decades).
_MAX_SD = 3.0


@dataclass(frozen=True)
class Component:
    """
    One term of a model as the planner sees it.

    Attributes
    ----------
    label : str
        Term label, possibly numbered ('white', 'gauss_markov_2').
    coef : float
        Linear coefficient c of AVAR = c shape(tau, *phi) [SI].
    phi : tuple of float
        Nonlinear parameters of the term (T_B, T, f0_hz ...).

    """

    label: str
    coef: float
    phi: tuple

    @property
    def term(self) -> Term:
        """Return the registry term."""
        return TERMS[base_name(self.label)]

    def names(self) -> list:
        """Return the reported names of the term's symbols (N, B, T_B, gauss_markov.T ...)."""
        base = base_name(self.label)
        return [sym if self.label == base and self.term.plain else
                f'{self.label}.{sym}' for sym in self.term.symbols]

    def values(self) -> list:
        """Values of the term's symbols [SI], in the order of :meth:`names`."""
        params = self.term.to_params(self.coef, *self.phi)
        return [float(params[s]) for s in self.term.symbols]


def components_of(raw: Sequence) -> list:
    """Return Components from (label, coef, phi) tuples (``AxisFit.components``)."""
    return [Component(str(lb), float(c), tuple(float(v) for v in p)) for lb, c, p in raw
            if c > 0]


def _log_params(comps: Sequence[Component]) -> np.ndarray:
    return np.log(np.concatenate([c.values() for c in comps]))


def _avar(comps: Sequence[Component], theta: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """AVAR of the model whose log-parameters are ``theta`` (same layout as comps)."""
    out = np.zeros(tau.size)
    i = 0
    for c in comps:
        k = len(c.term.symbols)
        vals = np.exp(theta[i:i + k])
        nl = tuple(vals[1:])
        out += c.term.to_coef(vals[0], *nl) * c.term.shape(tau, *nl)
        i += k
    return out


def _jacobian(comps: Sequence[Component], theta: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Return d avar / d theta, shape (k, p), central differences in the log-parameters."""
    jac = np.empty((tau.size, theta.size))
    for j in range(theta.size):
        up, down = theta.copy(), theta.copy()
        up[j] += _STEP
        down[j] -= _STEP
        jac[:, j] = (_avar(comps, up, tau) - _avar(comps, down, tau)) / (2.0 * _STEP)
    return jac


def fit_taus(rate_hz: float, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Cluster sizes and taus the fit uses for a record of ``n_samples``.

    The accumulator's dense grid up to M // 2 samples, thinned to two per octave as
    :func:`imu_allan.core.fit.fit_axis` does.

    Returns
    -------
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    tau_s : np.ndarray
        Shape (k,), averaging times [s].

    """
    m = tau_grid(int(n_samples), 'dense')
    m = m[thin(m / rate_hz)]
    return m, m / rate_hz


class CurveModel:
    """The model of one axis evaluated on the curve of a record of any length."""

    def __init__(self, comps: Sequence[Component], rate_hz: float):
        self.comps = list(comps)
        self.rate_hz = float(rate_hz)
        self.theta = _log_params(self.comps)
        self.names = [n for c in self.comps for n in c.names()]

    def geometry(self, duration_s: float) -> tuple:
        """Taus, term counts, Sigma [unit^4] and scale of a record of ``duration_s``."""
        n = max(int(round(duration_s * self.rate_hz)), 8)
        m, tau = fit_taus(self.rate_hz, n)
        n_terms = np.maximum(n + 1 - 2 * m, 1)
        cov = CurveCovariance(m, n_terms, 1.0 / self.rate_hz, n)
        avar = _avar(self.comps, self.theta, tau)
        scale = float(np.max(avar))
        sigma = cov.sigma([c.term for c in self.comps],
                          np.array([c.coef / scale for c in self.comps]),
                          [c.phi for c in self.comps])
        return tau, sigma, scale

    def widths(self, duration_s: float) -> np.ndarray:
        """Return the expected relative 95 % half-width of every parameter (``names`` order)."""
        tau, sigma, scale = self.geometry(duration_s)
        return expected_widths(_jacobian(self.comps, self.theta, tau) / scale, sigma)


def interval_threshold(dof: int) -> float:
    """
    Return the expected rise of the chi-square that bounds the fit's 95 % profile intervals.

    The fit (:func:`imu_allan.core.fit.axis.profile_threshold`) uses chi2(0.95; 1) when
    its J_min <= dof and F(0.95; 1, dof) J_min / dof otherwise.  Under the model J_min
    ~ chi2_dof, so the threshold averages to F(0.95; 1, dof) E[max(1, X)], X =
    chi2_dof / dof, with E[max(1, X)] = P(chi2_dof <= dof) + P(chi2_{dof+2} > dof)
    (E[chi2_nu; chi2_nu > c] = nu P(chi2_{nu+2} > c)); the first case is rounded up to
    the F quantile too (they differ by under 4 % beyond 20 dof).
    """
    if dof <= 0:
        return float(chi2_ppf(0.95, 1))
    mean_dispersion = (1.0 - float(chi2_sf(float(dof), dof))
                       + float(chi2_sf(float(dof), dof + 2)))
    return float(f_ppf(0.95, 1, dof)) * mean_dispersion


def expected_widths(jac: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """
    Return the expected relative 95 % half-widths from the Fisher information of a GLS fit.

    Parameters
    ----------
    jac : np.ndarray
        Shape (k, p), d avar / d log-parameter at the fitted taus [unit^2, scaled].
    sigma : np.ndarray
        Shape (k, k), covariance of the Allan estimates [same units squared].

    Returns
    -------
    np.ndarray
        Shape (p,), sinh(sqrt(t) sd(log p)) per parameter, t the profile threshold
        (:func:`interval_threshold`, about 1.96^2) [-]; inf where the parameter is not
        identified (sd above 3, or a null direction of the information).

    """
    fisher = jac.T @ np.linalg.pinv(sigma, rcond=1e-12, hermitian=True) @ jac
    # Scaled to unit diagonal before inverting (the parameters differ in leverage by
    # many decades); a tiny ridge turns an unidentified direction into a huge variance.
    d = np.sqrt(np.maximum(np.diag(fisher), 1e-300))
    scaled = fisher / np.outer(d, d) + 1e-10 * np.eye(d.size)
    inv = np.linalg.inv(scaled) / np.outer(d, d)
    sd = np.sqrt(np.maximum(np.diag(inv), 0.0))
    z = math.sqrt(interval_threshold(jac.shape[0] - jac.shape[1]))
    return np.where(sd < _MAX_SD, np.sinh(z * np.minimum(sd, _MAX_SD)), np.inf)


def relative_width(value: float, ci95: Sequence[float]) -> float:
    """Relative half-width (hi - lo) / (2 value) of an interval; inf when open."""
    lo, hi = float(ci95[0]), float(ci95[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and value > 0):
        return math.inf
    return (hi - lo) / (2.0 * value)
