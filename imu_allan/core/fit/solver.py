"""
The GLS solver: NNLS inside a search over the nonlinear parameters, profiles, IRLS.

Part of :mod:`imu_allan.core.fit` (see its docstring for the method).
"""

from dataclasses import dataclass
import math
from typing import NamedTuple, Sequence

import numpy as np
from scipy.optimize import nnls

from imu_allan.core.fit.covariance import _shared_covariance
from imu_allan.core.fit.polish import _polish_1d, _polish_lm
from imu_allan.core.noise.terms import Term


@dataclass(frozen=True)
class Slot:
    """One term of a model: its label, registry entry and nonlinear search bounds."""

    label: str
    term: Term
    bounds: tuple  # ((lo, hi), ...) per nonlinear parameter


class Solution(NamedTuple):
    """A fit at fixed weights: scaled coefficients, nonlinear parameters, chi-square J."""

    coef: np.ndarray       # (p,) linear coefficients (scaled units)

    phi: tuple             # per slot, tuple of nonlinear values
    j: float               # GLS chi-square


class _Data:
    """The curve in scaled units and the whitening of the current weight matrix."""

    def __init__(self, tau: np.ndarray, avar: np.ndarray, scale: float):
        self.tau = tau
        self.y = avar / scale
        self.scale = scale
        self.chol: np.ndarray = np.empty((0, 0))
        self.inv: np.ndarray = np.empty((0, 0))
        self.yw: np.ndarray = np.empty(0)

    def set_sigma(self, sigma_scaled: np.ndarray) -> None:
        """Whiten with Sigma (scaled units); a tiny relative ridge keeps it definite."""
        s = 0.5 * (sigma_scaled + sigma_scaled.T)
        d = np.diag(s).copy()
        s = s + np.diag(1e-9 * d + 1e-300)
        for ridge in (0.0, 1e-7, 1e-5, 1e-3):
            try:
                self.chol = np.linalg.cholesky(s + np.diag(ridge * d))
                break
            except np.linalg.LinAlgError:
                continue
        else:
            self.chol = np.diag(np.sqrt(d))
        # numpy, not scipy.linalg: numpy's BLAS is held to one thread during a fit.
        self.inv = np.linalg.solve(self.chol, np.eye(d.size))
        self.yw = self.inv @ self.y

    def whiten(self, a: np.ndarray) -> np.ndarray:
        """Return L^-1 a for Sigma = L L^T."""
        return self.inv @ a


def _design(slots: Sequence[Slot], tau: np.ndarray, phi: Sequence[tuple]) -> np.ndarray:
    """Design matrix (k, p): AVAR shape of each slot per unit coefficient."""
    return np.column_stack([s.term.shape(tau, *nl) for s, nl in zip(slots, phi)])


def _solve_linear(data: _Data, a: np.ndarray, fixed: np.ndarray | None = None):
    """
    Non-negative GLS coefficients for a fixed design.

    Returns (coef, chi-square, whitened residual of shape (k,)).
    """
    aw = data.whiten(a)
    yw = data.yw if fixed is None else data.yw - data.whiten(fixed)
    norm = np.sqrt((aw ** 2).sum(axis=0))
    norm[norm == 0] = 1.0
    coef, rnorm = nnls(aw / norm, yw, maxiter=50 * a.shape[1] + 50)
    coef = coef / norm
    return coef, rnorm ** 2, yw - aw @ coef


class Fix(NamedTuple):
    """A parameter held fixed while the rest is fitted (profile intervals)."""

    slot: int              # index of the slot
    symbol: str            # the slot's reported symbol: its level or a nonlinear name
    value: float           # SI value of that symbol


def _families(slots: Sequence[Slot]) -> list:
    """Group the interchangeable slots (two Gauss-Markov terms, two sinusoids)."""
    groups: dict[str, list[int]] = {}
    for i, s in enumerate(slots):
        if s.bounds:
            key = 'gm' if s.term.name in ('gauss_markov', 'bias_instability') else s.term.name
            groups.setdefault(key, []).append(i)
    return [g for g in groups.values() if len(g) > 1]


# Long by design: the variable-projection problem's state (column cache, held
# parameters, bounds) is shared by its evaluations (objective, residual and Jacobian,
# grid sweeps), each a short method.
class _Problem:
    """
    One model at fixed weights: its nonlinear parameters x (log phi) and their bounds.

    Evaluates the GLS chi-square at the optimal NNLS coefficients for any x (variable
    projection), its residual and Jacobian for :func:`_polish_lm`, and keeps the
    columns already computed.  Interchangeable terms fit the curve the same either way
    round, so x is evaluated sorted within each family (a smooth objective); a profile
    that holds one of them must keep their roles, and there a quadratic penalty keeps
    their order (``held``).  See :func:`fit_fixed_weights` for ``fix``.
    """

    def __init__(self, data: _Data, slots: Sequence[Slot], phi0, fix: Fix | None):
        self.data, self.slots, self.phi0 = data, slots, phi0
        self.fixed_nl: dict = {}
        self.fixed_level: Fix | None = None
        if fix is not None:
            term = slots[fix.slot].term
            if fix.symbol in term.nonlinear:
                self.fixed_nl[(fix.slot, term.nonlinear.index(fix.symbol))] = fix.value
            else:
                self.fixed_level = fix
        nl_all = [(i, j) for i, s in enumerate(slots) for j in range(len(s.bounds))]
        self.nl_index = [ij for ij in nl_all if ij not in self.fixed_nl]
        self.bounds = np.log(np.array([slots[i].bounds[j] for i, j in self.nl_index])
                             ).reshape(-1, 2)
        # Columns depend only on their own slot's nonlinear parameters: a search that
        # moves one of them (grid sweeps, profiles) reuses the others.
        self.columns: dict = {}
        self.families = _families(slots)
        self.held = fix is not None and any(fix.slot in fam for fam in self.families)
        self.fam_dims = [] if self.held or not self.nl_index else [
            [self.nl_index.index((i, 0)) for i in fam] for fam in self.families]
        self.dim_of = {ij: d for d, ij in enumerate(self.nl_index)}

    def start(self) -> np.ndarray:
        """Return the starting x: phi0's values, else the middle of the bounds."""
        if self.phi0 is not None:
            x = np.log([self.phi0[i][j] for i, j in self.nl_index])
        else:
            x = self.bounds.mean(axis=1)
        return np.clip(x, self.bounds[:, 0], self.bounds[:, 1])

    def unpack(self, x) -> tuple:
        """Return phi (per slot, a tuple of nonlinear values) for x."""
        vals = [list(p) for p in (self.phi0 if self.phi0 is not None else
                                  [[0.0] * len(s.bounds) for s in self.slots])]
        b = self.bounds
        for (i, j), v in zip(self.nl_index, np.exp(np.clip(x, b[:, 0], b[:, 1]))):
            vals[i][j] = float(v)
        for (i, j), v in self.fixed_nl.items():
            vals[i][j] = float(v)
        return tuple(tuple(v) for v in vals)

    def column(self, i: int, nl: tuple) -> np.ndarray:
        """Return slot i's AVAR shape (k,) at nonlinear values nl (cached)."""
        key = (i, nl)
        col = self.columns.get(key)
        if col is None:
            col = self.slots[i].term.shape(self.data.tau, *nl)
            if len(self.columns) < 4096:
                self.columns[key] = col
        return col

    def solve(self, phi) -> tuple:
        """Return (coef, chi-square, whitened residual) at phi; a fixed level stays fixed."""
        a = np.column_stack([self.column(i, nl) for i, nl in enumerate(phi)])
        fl = self.fixed_level
        if fl is None:
            return _solve_linear(self.data, a)
        i = fl.slot
        c_i = self.slots[i].term.to_coef(fl.value, *phi[i]) / self.data.scale
        rest = [k for k in range(len(self.slots)) if k != i]
        coef_rest, j, resid = _solve_linear(self.data, a[:, rest], fixed=a[:, i] * c_i)
        coef = np.empty(len(self.slots))
        coef[rest], coef[i] = coef_rest, c_i
        return coef, j, resid

    def ordered(self, x) -> tuple:
        """Return x sorted within each family and the permutation that did it."""
        x, perm = x.copy(), np.arange(x.size)
        for dims in self.fam_dims:
            o = np.argsort(x[dims], kind='stable')
            x[dims], perm[dims] = x[dims][o], np.asarray(dims)[o]
        return x, perm

    def objective(self, x) -> float:
        """Return the GLS chi-square at x (plus the order penalty of a held family)."""
        phi = self.unpack(self.ordered(x)[0])
        pen = float(np.sum(self.order_rows(phi)[0] ** 2)) if self.held else 0.0
        return self.solve(phi)[1] + pen

    def residual_jac(self, x) -> tuple:
        """
        Return the whitened residual r(x) and its Jacobian (variable projection).

        Golub & Pereyra (1973) with Kaufman's Jacobian: r(x) = L^-1 (y - A(x) c(x)) at
        the optimal coefficients (NNLS), and dr/dx = -P (L^-1 d(A c)/dx) with c held, P
        the projection off the active columns.  The columns' derivatives in log(phi)
        by a forward difference; a fixed level's coefficient moves with its slot's
        nonlinear parameters (to_coef) and is differentiated with them.
        """
        data, slots, fl = self.data, self.slots, self.fixed_level
        xs, perm = self.ordered(x)
        phi = self.unpack(xs)
        coef, _, resid = self.solve(phi)
        dm = np.zeros((data.tau.size, len(self.nl_index)))
        for d, (i, jj) in enumerate(self.nl_index):
            held_level = fl is not None and i == fl.slot
            if coef[i] == 0.0 and not held_level:
                continue
            step = list(phi[i])
            step[jj] *= _EXP_H
            col = slots[i].term.shape(data.tau, *step)
            if held_level and fl is not None:
                c_step = slots[i].term.to_coef(fl.value, *step) / data.scale
                dm[:, d] = (col * c_step - self.column(i, phi[i]) * coef[i]) / _H
            else:
                dm[:, d] = (col - self.column(i, phi[i])) * (coef[i] / _H)
        dmw = data.whiten(dm)
        free = [i for i in range(len(slots))
                if coef[i] > 0 and not (fl is not None and i == fl.slot)]
        if free:
            active = np.column_stack([self.column(i, phi[i]) for i in free])
            q = np.linalg.qr(data.whiten(active))[0]
            dmw = dmw - q @ (q.T @ dmw)
        jac = np.empty_like(dmw)
        jac[:, perm] = -dmw
        if self.held:
            rows, jrows = self.order_rows(phi)
            resid = np.concatenate([resid, rows])
            jac = np.vstack([jac, jrows])
        return resid, jac

    def order_rows(self, phi) -> tuple:
        """Penalty residuals sqrt(w) max(0, log T_a - log T_b) of neighbours out of order."""
        rows, jrows = [], []
        w = math.sqrt(_ORDER_WEIGHT)
        for fam in self.families:
            for a, b in zip(fam[:-1], fam[1:]):
                gap = max(math.log(phi[a][0] / phi[b][0]), 0.0)
                jr = np.zeros(len(self.nl_index))
                if gap > 0.0:
                    for i, sign in ((a, w), (b, -w)):
                        if (i, 0) in self.dim_of:
                            jr[self.dim_of[(i, 0)]] = sign
                rows.append(w * gap)
                jrows.append(jr)
        return np.array(rows), np.array(jrows).reshape(-1, len(self.nl_index))

    def polish(self, x) -> np.ndarray:
        """Return x after a Levenberg-Marquardt polish, sorted within families."""
        return self.ordered(_polish_lm(self.residual_jac, x, self.bounds))[0]

    def polish_1d(self, x, half_width: float = 1.5) -> np.ndarray:
        """Return x (one parameter) after a bounded 1-D search within half_width of it."""
        b = self.bounds
        lo, hi = max(x[0] - half_width, b[0, 0]), min(x[0] + half_width, b[0, 1])
        x = x.copy()
        x[0] = _polish_1d(self.objective, lo, hi, x[0], self.objective(x))
        return x

    def grid(self, x, grid_slots) -> np.ndarray:
        """Coordinate sweeps over 41-point grids (twice when several parameters move)."""
        n_nl = len(self.nl_index)
        sweep = [d for d, (i, _) in enumerate(self.nl_index)
                 if grid_slots is None or i in grid_slots]
        for _ in range(1 if n_nl == 1 or grid_slots is not None else 2):
            for d in sweep:
                grid = np.linspace(self.bounds[d, 0], self.bounds[d, 1], 41)
                vals = []
                for g in grid:
                    x[d] = g
                    vals.append(self.objective(x))
                best = int(np.argmin(vals))
                x[d] = grid[best]
                if n_nl == 1:
                    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
                    if hi > lo:
                        x[d] = _polish_1d(self.objective, lo, hi, x[d], vals[best])
        return x

    def solution(self, x) -> Solution:
        """Return the solution at x."""
        phi = self.unpack(self.ordered(x)[0])
        coef, j, _ = self.solve(phi)
        return Solution(coef, phi, j)


def fit_fixed_weights(data: _Data, slots: Sequence[Slot], phi0: Sequence[tuple] | None = None,
                      fix: Fix | None = None, local: bool = False,
                      grid_slots: Sequence[int] | None = None) -> Solution:
    """
    Fit one model at the current weights: NNLS inside a search over phi.

    With ``fix`` one parameter is held at a value: a nonlinear one leaves the search, a
    level fixes that slot's coefficient (through ``Term.to_coef``, which depends on the
    slot's nonlinear parameters, e.g. S_B from B and T) and the other coefficients are
    fitted to the rest of the curve.  Interchangeable terms keep their order (first
    label, shortest T), so a profile cannot swap their roles.  ``local`` skips the grid
    and searches near ``phi0`` only (profiles move in small steps).  ``grid_slots``
    limits the grid sweeps to those slots' parameters (a term added to a fitted model:
    the others start where they are and move in the polish).  The search itself is
    :class:`_Problem`: grid sweeps, then a 1-D bounded search or Levenberg-Marquardt.
    """
    problem = _Problem(data, slots, phi0, fix)
    if not problem.nl_index:
        return problem.solution(np.zeros(0))
    x = problem.start()
    one = len(problem.nl_index) == 1
    if local and phi0 is not None:
        return problem.solution(problem.polish_1d(x) if one else problem.polish(x))
    x = problem.grid(x, grid_slots)
    if not one:
        x = problem.polish(x)
    sol = problem.solution(x)
    if fix is None:
        coef, phi = _canonical(slots, sol.coef, sol.phi)
        sol = Solution(coef, phi, sol.j)
    return sol


#: Forward-difference step in log(phi) for the variable-projection Jacobian.
_H = 1e-7
_EXP_H = math.exp(_H)
#: Weight w of the order penalty on interchangeable terms held in a profile (chi-square
#: per squared log-ratio: a swap by 0.1 % costs 1e-2).
_ORDER_WEIGHT = 1e4


def _canonical(slots: Sequence[Slot], coef: np.ndarray, phi: tuple) -> tuple:
    """
    Order interchangeable terms by their nonlinear parameter.

    Two Gauss-Markov terms (or two sinusoids) fit the same curve either way round; by
    convention the first label gets the shortest correlation time (the lowest
    frequency), so 'bias_instability' is the fastest Gauss-Markov term.
    """
    coef, phi_list = coef.copy(), list(phi)
    for members in _families(slots):
        order = sorted(members, key=lambda i: phi_list[i][0])
        new_coef = [coef[i] for i in order]
        new_phi = [phi_list[i] for i in order]
        for dst, c, p in zip(members, new_coef, new_phi):
            coef[dst], phi_list[dst] = c, p
    return coef, tuple(phi_list)


class Fitter:
    """Everything a fit of one curve needs: data, covariance model, candidate slots."""

    def __init__(self, tau, avar, edf, m, n_terms, dt, n_samples, method):
        scale = float(np.median(avar))
        self.data = _Data(tau, avar, scale)
        self.edf = edf
        self.edf0 = np.clip(edf, 1.0, np.maximum(1.5 * n_terms / m, 1.0))
        self.cov = _shared_covariance(m, n_terms, dt, n_samples)
        self.method = method

    def sigma(self, slots, sol: Solution, expected: bool = False) -> np.ndarray:
        """
        Model covariance of the curve (scaled units) at a solution.

        ``expected``: average Sigma over the coefficients' GLS uncertainty at the
        current weights (:meth:`_coef_cov`); used for the re-weighting steps.

        A coefficient fitted at zero sits on the edge of the parameter space, not at a
        certainty: in the covariance it keeps a floor of 10 % of the data at the tau
        where that term is largest relative to them.  Without it a random walk fitted at
        zero in a first step would make the long-tau points look exact, and the
        re-weighted fit would swing between models.
        """
        a = _design(slots, self.data.tau, sol.phi)
        floor = 0.1 * np.min(self.data.y[:, None] / np.maximum(a, 1e-300), axis=0)
        coef = np.maximum(sol.coef, floor)
        cov = self._coef_cov(a) * self.data.scale ** 2 if expected else None
        s = self.cov.sigma([x.term for x in slots], coef * self.data.scale, sol.phi, cov)
        s = s / self.data.scale ** 2 + self._sinusoid_cross(slots, sol)
        model = _design(slots, self.data.tau, sol.phi) @ sol.coef
        floor = 2.0 * (1e-3 * np.maximum(model, 1e-300)) ** 2
        if self.method == 'nonoverlapping':
            # Correlations of the overlapping model, variances from the given EDF.
            sd = np.sqrt(np.maximum(np.diag(s), 1e-300))
            want = model * np.sqrt(2.0 / self.edf)
            s = s / np.outer(sd, sd) * np.outer(want, want)
        return s + np.diag(floor)

    def _coef_cov(self, a: np.ndarray) -> np.ndarray:
        """
        GLS covariance (A^T Sigma^-1 A)^-1 of the coefficients at the current weights.

        Used for the *expected* covariance of the curve (:meth:`sigma`): the Sigma of
        the data is Sigma(c_true), and c_hat is uncertain.  A weight matrix built from
        c_hat alone follows its errors (a record whose long-tau points run low gets a
        small K, hence small variances there, hence more pull from those same low
        points); averaging Sigma over the coefficients' uncertainty breaks that loop.
        """
        aw = self.data.whiten(a)
        return np.linalg.pinv(aw.T @ aw)

    def _sinusoid_cross(self, slots, sol: Solution) -> np.ndarray:
        """
        Spread a sinusoid adds by beating with the noise (scaled units).

        avar_p contains 2 mean_k(d_noise d_sin) / (2 tau_p^2); averaged over the random
        phase its covariance is, for records long against the lags (edge effects left
        out), 16 A^2 s_p^2 s_q^2 S_X(f0) / (pi^2 f0^2 dt tau_p^2 tau_q^2 max(n_p, n_q))
        with s = sin^2(pi f0 tau) and S_X the noise's two-sided phase PSD at f0.  The
        sinusoid's own part is deterministic up to edge effects and left out.
        """
        k = self.data.tau.size
        out = np.zeros((k, k))
        sines = [(i, s) for i, s in enumerate(slots) if s.term.name == 'sinusoid']
        if not sines:
            return out
        tau, dt = self.data.tau, self.cov.dt
        n = self.cov.n_terms.astype(np.float64)
        for i, s in sines:
            amp2, f0 = sol.coef[i], sol.phi[i][0]
            if amp2 <= 0:
                continue
            s_x = sum(c * x.term.psd_phase(f0, dt, *nl) for x, c, nl in
                      zip(slots, sol.coef, sol.phi) if x.term.psd_phase is not None)
            sp2 = np.sin(math.pi * f0 * tau) ** 4 / tau ** 2
            out += (16.0 * amp2 * s_x / (math.pi ** 2 * f0 ** 2 * dt) * np.outer(sp2, sp2)
                    / np.maximum.outer(n, n))
        return out

    def irls(self, slots, phi0=None, sigma0: np.ndarray | None = None,
             max_iter: int = 8, local: bool = False,
             grid_slots: Sequence[int] | None = None) -> tuple[Solution, np.ndarray]:
        """
        Fit one model by iteratively re-weighted GLS; return the fit and Sigma at it.

        The first step uses the paper's weights 2 avar^2 / edf with the EDF capped at the
        white-noise value 1.5 n_terms / m (a long-tau EDF from a misidentified noise type
        would otherwise pin the fit to one point), or ``sigma0`` when given (the
        covariance of a related model already fitted).  Then the *expected* Sigma
        (Sigma(theta) averaged over the GLS uncertainty of the coefficients,
        :meth:`_coef_cov`) until the fitted curve moves by less than 1 % of its standard
        deviation at every tau.  The plug-in Sigma(theta) weights a record by its own
        estimate: where the long-tau points run low, K comes out small, their variances
        small and their pull large, so errors feed back.  On the u-blox accelerometer
        example (3 h, 50 seeds, bench/validate_fit.py) the expected Sigma brought the
        median error of K from 0.31 to 0.24 and of B from 0.067 to 0.052.  The returned
        Sigma, used for term selection and the profile intervals, is the plug-in one at
        the solution (the profile accounts for the parameters' uncertainty itself).
        """
        y = self.data.y
        self.data.set_sigma(np.diag(2.0 * y ** 2 / self.edf0) if sigma0 is None else sigma0)
        # local: the nonlinear parameters start at a fitted model's (an effect search
        # step) and are polished, not searched again over their whole ranges.
        sol = fit_fixed_weights(self.data, slots, phi0, local=local and phi0 is not None,
                                grid_slots=grid_slots)
        last_sigma, moves = None, [math.inf]
        for it in range(max_iter):
            if not np.any(sol.coef > 0):
                break
            sigma = self.sigma(slots, sol, expected=True)
            if last_sigma is not None and moves[-1] > 0.5 * moves[-2]:
                # Not contracting (two models that pull each other's weights back and
                # forth): relax, half the new Sigma and half the last one.
                sigma = 0.5 * (sigma + last_sigma)
            self.data.set_sigma(sigma)
            # The first re-weighting may move the model to another basin (the paper's
            # weights and the model's covariance differ most); later ones polish it.
            new = fit_fixed_weights(self.data, slots, sol.phi, local=local or it > 0,
                                    grid_slots=grid_slots)
            before = _design(slots, self.data.tau, sol.phi) @ sol.coef
            after = _design(slots, self.data.tau, new.phi) @ new.coef
            sol = new
            moved = float(np.max(np.abs(after - before) / np.sqrt(np.diag(sigma))))
            if moved < 0.01:
                break
            last_sigma = sigma
            moves.append(moved)
        sigma = self.sigma(slots, sol) if np.any(sol.coef > 0) else np.diag(
            2.0 * y ** 2 / self.edf0)
        self.data.set_sigma(sigma)
        return sol, sigma
