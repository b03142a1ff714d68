"""
Bounded local minimisers of the fit: projected Levenberg-Marquardt and a 1-D search.

Both only ever return a point at least as good as the start, so a polish cannot make a
fit worse.
"""

import numpy as np
from scipy.optimize import minimize_scalar

#: Relative drop of J below which a Levenberg-Marquardt polish stops (J is a chi-square:
#: 1e-7 of it is far below what moves an interval end or a model choice).
_LM_FTOL = 1e-7
#: Most Levenberg-Marquardt iterations of one polish.
_LM_MAX_ITER = 100


def _polish_lm(residual_jac, x: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """
    Levenberg-Marquardt from x within bounds (k, 2), projected; only improving steps count.

    ``residual_jac(x)`` returns the residual vector r and its Jacobian; J = r^T r.
    Parameters at a bound whose gradient pushes them out are held there (an active
    set), so a solution on a bound (a T at the edge of its range) converges as fast as
    an interior one.  The damping follows the gain ratio (Nielsen 1999, as in Madsen,
    Nielsen & Tingleff, "Methods for non-linear least squares problems", 2004).  Stops
    when an accepted step lowers J by less than _LM_FTOL (J + 1), or moves no parameter
    by more than 1e-7 in log units.
    """
    lo, hi = bounds[:, 0], bounds[:, 1]
    x = np.clip(x, lo, hi)
    r, jac = residual_jac(x)
    cost = float(r @ r)
    lam, nu = None, 2.0
    for _ in range(_LM_MAX_ITER):
        grad = jac.T @ r
        free = ~(((x <= lo) & (grad > 0)) | ((x >= hi) & (grad < 0)))
        if not free.any():
            break
        jf = jac[:, free]
        h = jf.T @ jf
        if lam is None:
            lam = 1e-3 * float(np.max(np.diag(h))) + 1e-300
        d = np.zeros(x.size)
        try:
            d[free] = np.linalg.solve(h + lam * np.eye(h.shape[0]), -grad[free])
        except np.linalg.LinAlgError:
            lam, nu = lam * nu, nu * 2.0
            continue
        x_new = np.clip(x + d, lo, hi)
        d = x_new - x
        predicted = -float(2.0 * grad @ d + d @ (jac.T @ (jac @ d)))
        r_new, jac_new = residual_jac(x_new)
        cost_new = float(r_new @ r_new)
        gain = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if gain <= 0:
            lam, nu = lam * nu, nu * 2.0
            if np.max(np.abs(d)) < 1e-7:
                break
            continue
        done = cost - cost_new < _LM_FTOL * (cost + 1.0) or np.max(np.abs(d)) < 1e-7
        x, r, jac, cost = x_new, r_new, jac_new, cost_new
        lam *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
        nu = 2.0
        if done:
            break
    return x


def _polish_1d(objective, lo: float, hi: float, x0: float, f0: float) -> float:
    """Bounded 1-D minimisation of objective on [lo, hi]; keep x0 unless it improves on f0."""
    res = minimize_scalar(lambda v: objective(np.array([v])), bounds=(lo, hi),
                          method='bounded', options={'xatol': 1e-4})
    return float(res.x) if res.fun <= f0 else x0
