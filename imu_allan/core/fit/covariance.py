"""
Covariance of the Allan estimates at all fitted taus, exact for Gaussian terms.

Part of :mod:`imu_allan.core.fit` (see its docstring for the method).
"""

import math
from typing import Sequence

import numpy as np

from imu_allan.core.noise.terms import Term

# Lag-sum quadrature: lags within _EXACT of a kink are summed exactly, the rest is
# integrated with Gauss-Legendre on pieces that grow _GROWTH-fold away from the kinks.
# (8, 4 points, 4-fold) keeps Sigma within 3e-4 (relative to its diagonal) of (24, 8
# points, 2-fold) on the ADIS16405 curves (1 M samples at 100 Hz, white, random walk,
# flicker, Gauss-Markov T from 0.003 s to 300 s), with 2/3 of the nodes of 2-fold
# pieces; earlier checks (3 h, 100 Hz octave and dense curves, a short 10 Hz one, T_B
# from 3 s to 3000 s) set the exact lags and points (bench/bench_fit.py: the fit's
# main cost).
_EXACT = 8
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
_GROWTH = 4.0
_STENCIL = ((0, 1.0), (1, -2.0), (2, 1.0))
_STENCIL_WEIGHTS = np.array([ai * aj for _, ai in _STENCIL for _, aj in _STENCIL])
#: Grid of the nonlinear parameters at which Sigma is evaluated, in steps per octave
#: (the weights of a GLS fit need not follow T to better than 1 %).
_NL_STEPS = 32.0


class _LagQuadrature:
    """
    Quadrature of sum_{k<n_p} sum_{l<n_q} f(l - k) for every pair p <= q of taus.

    For each pair the lag axis is cut at the stencil kinks i m_p - j m_q (i, j in 0..2)
    and at the kinks of the pair-count weight w(h); lags within ``_EXACT`` of a cut are
    summed exactly, the rest is integrated (sum_{h=s}^{e} f(h) ~ int_{s-1/2}^{e+1/2})
    with 8-point Gauss-Legendre on pieces graded geometrically away from the cuts.
    """

    def __init__(self, m: np.ndarray, n_terms: np.ndarray, reach: np.ndarray):
        k = m.size
        self.pairs = np.array([(p, q) for p in range(k) for q in range(p, k)], dtype=np.int64)
        # Each pair's items, in order: its exact lag ranges, then its graded pieces.
        a, b, is_piece, per_pair = _layout(m, n_terms, reach, self.pairs)
        counts = np.where(is_piece, _GL_X.size, b).astype(np.int64)
        item = np.repeat(np.arange(a.size), counts)
        at = np.arange(item.size) - np.repeat(np.cumsum(counts) - counts, counts)
        # A piece [a, b] gets Gauss-Legendre nodes mid + half x_i with weights half w_i.
        half, mid = 0.5 * (b - a), 0.5 * (b + a)
        gl = np.minimum(at, _GL_X.size - 1)
        node_piece = is_piece[item]
        self.h = np.where(node_piece, mid[item] + half[item] * _GL_X[gl], a[item] + at)
        n_pairs = len(self.pairs)
        nodes_per_pair = np.bincount(np.repeat(np.arange(n_pairs), per_pair), weights=counts,
                                     minlength=n_pairs).astype(np.int64)
        self.pair = np.repeat(np.arange(n_pairs), nodes_per_pair)
        self.starts = np.cumsum(nodes_per_pair) - nodes_per_pair
        n1 = n_terms[self.pairs[self.pair, 0]].astype(np.float64)
        n2 = n_terms[self.pairs[self.pair, 1]].astype(np.float64)
        # Lag h pairs terms k, k + h of the two taus: min(n1, n2 - h) - max(0, -h) of them.
        w_pairs = np.clip(np.minimum(n1, n2 - self.h) - np.maximum(0.0, -self.h), 0.0, None)
        self.weight = np.where(node_piece, half[item] * _GL_W[gl], 1.0) * w_pairs
        self.m1 = m[self.pairs[self.pair, 0]].astype(np.float64)
        self.m2 = m[self.pairs[self.pair, 1]].astype(np.float64)
        # Inner kink range of each node's pair: polynomial terms vanish outside it.
        self.kmin = -2.0 * self.m2
        self.kmax = 2.0 * self.m1
        self.k = k
        self._lags: tuple | None = None
        # Lags beyond the kink range of each node's pair (where tails apply).
        self.outside = (self.h < self.kmin) | (self.h > self.kmax)
        self.beyond = np.where(self.h > self.kmax, self.h - self.kmax, self.kmin - self.h)

    def _stencil_lags(self, dt: float) -> tuple:
        """Inside nodes and the lags [s] of their nine stencil terms, (9, n_inside)."""
        if self._lags is None or self._lags[0] != dt:
            inside = np.flatnonzero((self.h >= self.kmin) & (self.h <= self.kmax))
            h, m1, m2 = self.h[inside], self.m1[inside], self.m2[inside]
            lags = np.stack([dt * (i * m1 - j * m2 - h) for i, _ in _STENCIL
                             for j, _ in _STENCIL])
            self._lags = (dt, inside, lags)
        return self._lags[1], self._lags[2]

    def gamma(self, term: Term, nonlinear: tuple, dt: float) -> np.ndarray:
        """Covariance of the second differences per unit coefficient at every node."""
        gcov = term.gcov
        assert gcov is not None, term.name  # the caller keeps only terms that have one
        g = np.zeros(self.h.size)
        if term.reach is None or term.tail is not None:
            # Direct sums only between the kinks (beyond them the term has no
            # covariance, or its tail formula): one call over all nine stencil lags.
            inside, lags = self._stencil_lags(dt)
            g[inside] = _STENCIL_WEIGHTS @ gcov(lags, *nonlinear)
        else:
            reach = term.reach(self.m1, self.m2, dt, *nonlinear)
            direct = (self.h >= self.kmin - reach) & (self.h <= self.kmax + reach)
            h, m1, m2 = self.h[direct], self.m1[direct], self.m2[direct]
            for i, ai in _STENCIL:
                for j, aj in _STENCIL:
                    g[direct] += ai * aj * gcov(dt * (i * m1 - j * m2 - h), *nonlinear)
        if term.tail is not None and term.reach is not None:
            reach = term.reach(self.m1, self.m2, dt, *nonlinear)
            tail = self.outside & (self.beyond <= reach)
            g[tail] = term.tail(self.beyond[tail], self.m1[tail], self.m2[tail], dt, *nonlinear)
        return g

    def blocks(self, gammas: list, scale: np.ndarray) -> np.ndarray:
        """C[a, b] (k, k) = sum of weight * gamma_a * gamma_b per pair, times scale."""
        n = len(gammas)
        out = np.zeros((n, n, self.k, self.k))
        if n == 0:
            return out
        p, q = self.pairs[:, 0], self.pairs[:, 1]
        a_idx, b_idx = np.triu_indices(n)
        g = np.stack(gammas)
        # The nodes are stored pair by pair, so each pair's sum is one segment.
        sums = np.add.reduceat((g * self.weight)[a_idx] * g[b_idx], self.starts, axis=1)
        sums *= scale[p, q]
        for s, a, b in zip(sums, a_idx, b_idx):
            out[a, b, p, q] = s
            out[a, b, q, p] = s
            out[b, a] = out[a, b]
        return out


def _lru_get(cache: dict, key, size: int, make):
    """Return cache[key], computed by ``make()`` when absent; drops the oldest entries."""
    value = cache.pop(key, None)
    if value is None:
        value = make()
    cache[key] = value
    while len(cache) > size:
        cache.pop(next(iter(cache)), None)
    return value


def _layout(m: np.ndarray, n_terms: np.ndarray, reach: np.ndarray,
            pairs: np.ndarray) -> tuple:
    """
    Lay out the lag axis of every pair of taus at once.

    Per pair (m1, m2 samples; n1, n2 terms) the cuts are the stencil kinks
    i m1 - j m2, the pair-count kinks 0 and n2 - n1, and the ends of the lag range;
    lags within ``_EXACT`` of a cut form exact runs (merged where they touch), and the
    gaps between runs are covered by pieces of ``_EXACT``, ``_GROWTH`` times that ...
    from both ends of the gap.

    Parameters
    ----------
    m, n_terms, reach : np.ndarray
        Shape (k,): cluster sizes [samples], Allan terms, and the lag reach of each tau
        beyond its kinks [lags].
    pairs : np.ndarray
        Shape (n_pairs, 2), int64: the tau indices (p, q) of each pair.

    Returns
    -------
    lo_a, hi_b : np.ndarray
        Shape (n,): per item, an exact run's first lag and its length, or a piece's
        lower and upper edge [lags].
    is_piece : np.ndarray
        Shape (n,), bool.
    per_pair : np.ndarray
        Shape (n_pairs,), int64: items per pair; each pair's items are its runs, then
        its pieces, both in lag order.

    """
    p, q = pairs[:, 0], pairs[:, 1]
    m1, m2 = m[p].astype(np.int64), m[q].astype(np.int64)
    n1, n2 = n_terms[p].astype(np.int64), n_terms[q].astype(np.int64)
    kinks = np.stack([i * m1 - j * m2 for i in range(3) for j in range(3)], axis=1)
    lo = np.maximum(kinks.min(axis=1) - (reach[p] + reach[q]), -(n1 - 1))
    hi = np.minimum(kinks.max(axis=1) + (reach[p] + reach[q]), n2 - 1)
    cuts = np.column_stack([kinks, np.zeros_like(lo), n2 - n1, lo, hi])
    inside = (cuts >= lo[:, None]) & (cuts <= hi[:, None])
    cuts = np.sort(np.where(inside, cuts, np.iinfo(np.int64).max), axis=1)
    row, col = np.nonzero(cuts != np.iinfo(np.int64).max)
    c = cuts[row, col]
    s, e = np.maximum(lo[row], c - _EXACT), np.minimum(hi[row], c + _EXACT)
    # Runs of one pair that touch merge (s and e grow with the cut, so the run so far
    # ends at the previous cut's e).
    first = np.ones(c.size, bool)
    first[1:] = (row[1:] != row[:-1]) | (s[1:] > e[:-1] + 1)
    starts = np.flatnonzero(first)
    ends = np.r_[starts[1:], c.size] - 1
    run_s, run_e, run_row = s[starts], e[ends], row[starts]
    # Gaps between consecutive runs of a pair, and their graded pieces: edge t of a gap
    # lies steps[t] = x0 (G^t - 1) / (G - 1) from its end (x0 = _EXACT, G = _GROWTH), and a
    # gap of L lags takes n steps from each end, n = #{t >= 0: L > 2 steps[t + 1]}.
    gap = np.flatnonzero(run_row[1:] == run_row[:-1])
    a, b = run_e[gap] + 0.5, run_s[gap + 1] - 0.5
    steps = _EXACT * (_GROWTH ** np.arange(32) - 1.0) / (_GROWTH - 1.0)
    n = np.searchsorted(2.0 * steps[1:], b - a, side='left')
    n_edges = 2 * n + 2
    gi = np.repeat(np.arange(gap.size), n_edges)
    k = np.arange(gi.size) - np.repeat(np.cumsum(n_edges) - n_edges, n_edges)
    edges = np.where(k <= n[gi], a[gi] + steps[k], b[gi] - steps[n_edges[gi] - 1 - k])
    keep = np.ones(edges.size, bool)
    keep[np.cumsum(n_edges) - 1] = False                # a piece per edge but the last
    piece_lo, piece_hi = edges[keep], edges[np.flatnonzero(keep) + 1]
    piece_row = run_row[gap][gi[keep]]
    lo_a = np.concatenate([run_s.astype(float), piece_lo])
    hi_b = np.concatenate([(run_e + 1 - run_s).astype(float), piece_hi])
    is_piece = np.r_[np.zeros(run_s.size, bool), np.ones(piece_lo.size, bool)]
    order = np.argsort(np.r_[run_row, piece_row] * 2 + is_piece, kind='stable')
    per_pair = np.bincount(np.r_[run_row, piece_row], minlength=len(pairs))
    return lo_a[order], hi_b[order], is_piece[order], per_pair


class CurveCovariance:
    """Sigma(c, phi) of the overlapping Allan estimates of one curve (module docstring)."""

    def __init__(self, m: np.ndarray, n_terms: np.ndarray, dt: float, n_samples: int):
        self.m, self.n_terms, self.dt = m, n_terms, dt
        tau = m * dt
        # float: the product of two term counts overflows int64 beyond 3e9 samples.
        n_f = n_terms.astype(np.float64)
        self.scale = 2.0 / (4.0 * np.outer(tau ** 2, tau ** 2) * np.outer(n_f, n_f))
        self.n_samples = n_samples
        self._quad: dict[int, _LagQuadrature] = {}
        self._gammas: dict = {}     # second-difference covariances at the nodes
        self._blocks: dict = {}     # per-pair blocks of a term combination (small)

    def _quadrature(self, tails: bool) -> _LagQuadrature:
        # Without tails (polynomial covariances) the lags stop at the kinks; with them
        # (Gauss-Markov, flicker) they run over the whole record, graded, so that one
        # set of nodes serves every correlation time.
        if tails not in self._quad:
            reach = np.full(self.m.size, int(self.n_terms.max()) if tails else 0)
            self._quad[tails] = _LagQuadrature(self.m, self.n_terms, reach)
        return self._quad[tails]

    def blocks(self, terms: Sequence[Term], nonlinear: Sequence[tuple]) -> tuple:
        """
        Per-pair covariance blocks of a model's random terms.

        Parameters
        ----------
        terms : sequence of Term
            The model's terms; deterministic ones (gcov None) are skipped.
        nonlinear : sequence of tuple
            Each term's nonlinear parameter values.

        Returns
        -------
        blocks : np.ndarray
            Shape (n_active, n_active, k, k): Sigma = sum_ab c_a c_b blocks[a, b]
            [unit^4 per unit coefficients].
        active : list of int
            Index into ``terms`` of each block row.

        """
        active = [i for i, t in enumerate(terms) if t.gcov is not None]
        quad = self._quadrature(any(terms[i].reach is not None for i in active))
        gammas, keys = [], []
        for i in active:
            # Sigma varies slowly with T: a grid of _NL_STEPS steps per octave lets the
            # IRLS steps, profiles, bounds and rival terms of the same kind (bias
            # instability, further Gauss-Markov processes) share the work.
            t, nl = terms[i], tuple(2.0 ** (round(_NL_STEPS * math.log2(v)) / _NL_STEPS)
                                    for v in nonlinear[i])
            key = (id(quad), t.gcov, t.tail, nl)
            gamma = _lru_get(self._gammas, key, 24, lambda: quad.gamma(t, nl, self.dt))
            gammas.append(gamma)
            keys.append(key)
        blocks = _lru_get(self._blocks, tuple(keys), 256,
                          lambda: quad.blocks(gammas, self.scale))
        return blocks, active

    def sigma(self, terms: Sequence[Term], coef: np.ndarray, nonlinear: Sequence[tuple],
              coef_cov: np.ndarray | None = None):
        """
        Covariance matrix of the Allan estimates under a model.

        Sigma is quadratic in the coefficients, Sigma = sum_ab c_a c_b blocks[a, b]; with
        ``coef_cov`` the product c_a c_b is replaced by its expectation
        c_a c_b + cov(c_a, c_b) over uncertain coefficients.

        Parameters
        ----------
        terms : sequence of Term
            The model's terms; deterministic ones (gcov None) add nothing.
        coef : np.ndarray
            Shape (n_terms,), linear coefficients.
        nonlinear : sequence of tuple
            Each term's nonlinear parameter values.
        coef_cov : np.ndarray, optional
            Shape (n_terms, n_terms), covariance of the coefficients (same units).

        Returns
        -------
        np.ndarray
            Shape (k, k), covariance [unit^4].

        """
        blocks, active = self.blocks(terms, nonlinear)
        c = np.asarray(coef, dtype=np.float64)[active]
        moment = np.outer(c, c)
        if coef_cov is not None:
            moment = moment + np.asarray(coef_cov, dtype=np.float64)[np.ix_(active, active)]
        return np.einsum('ab,abij->ij', moment, blocks)


_COV_CACHE: dict = {}
#: Curves whose covariance machinery is kept: the six axes of one Allan curve share the
#: taus and term counts, so their quadrature nodes and the Sigma blocks of the terms
#: without nonlinear parameters are built once (about a third of a fit's time).  One
#: curve: its nodes and cached covariances take some 10-50 MB on a 3 h, 100 Hz record.
_COV_CACHE_SIZE = 1


def _shared_covariance(m: np.ndarray, n_terms: np.ndarray, dt: float,
                       n_samples: int) -> CurveCovariance:
    """Return the cached :class:`CurveCovariance` of a curve geometry (small LRU)."""
    key = (m.tobytes(), n_terms.tobytes(), float(dt), int(n_samples))
    cov = _COV_CACHE.pop(key, None)
    if cov is None:
        cov = CurveCovariance(m, n_terms, dt, n_samples)
    _COV_CACHE[key] = cov            # most recent last
    while len(_COV_CACHE) > _COV_CACHE_SIZE:
        _COV_CACHE.pop(next(iter(_COV_CACHE)))
    return cov
