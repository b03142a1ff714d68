"""
Where the output of a sensor that was just switched on has settled.

A MEMS IMU warms up after power-on: its biases move to their settled levels over
minutes, a transient that the Allan variance takes for bias instability and random
walk.  The recording procedure waits for the output to settle before it records
(step 2 of the Japanese textbook's procedure).
:func:`find_settling` judges the first stretch of a record and says from which row on
the output has settled.

Per axis the stretch is cut into about :data:`BLOCKS` block means, fitted by least
squares with a level plus a decaying exponential ``c + a exp(-t / tau)`` over a grid
of time constants.  The transient counts when ``|a|`` is
:data:`~imu_allan.core.rules.SETTLE_SCORE` times the record's own wander at the scale
``tau``: the Allan deviation of the fit's residuals over the later half of the stretch
(and from :data:`SETTLED_TAUS` time constants on, whichever is larger), fitted with
white, flicker and random-walk terms, the random walk taken at a third of the stretch
(how far apart the early and the settled levels are), so that the flicker,
Gauss-Markov and random-walk wander of a settled sensor is not taken for a transient.
The output has settled where what is left of the transient, ``|a| exp(-t / tau)``, is
down to :data:`~imu_allan.core.rules.SETTLE_LEFT` times that wander, or where a fit
with two time constants is (when its slower part is
:data:`~imu_allan.core.rules.SETTLE_TAIL` wanders: a second time constant, a ramp to a
level).  What follows the cut is judged again, at most
:data:`~imu_allan.core.rules.SETTLE_PASSES` times.
"""

from dataclasses import dataclass
import math
from typing import NamedTuple

import numpy as np

from imu_allan.core.rules import SETTLE_LEFT, SETTLE_PASSES, SETTLE_SCORE, SETTLE_TAIL

#: Block means a judged stretch is cut into: the time resolution of the cut.
BLOCKS = 256
#: Fewest blocks a stretch must give to be judged; a shorter one is taken as settled.
MIN_BLOCKS = 32
#: Time constants tried per factor of 10 (log-spaced), from 2 blocks to a quarter of the
#: stretch (slower transients have not settled within it: what is left is cut next).
TAUS_PER_DECADE = 12
#: The noise is also measured from this many time constants on: the stretch where the
#: fitted transient is over (a quiet later half does not hide a random walk).
SETTLED_TAUS = 3.0


class Transient(NamedTuple):
    """
    One axis' settling transient, as fitted.

    Attributes
    ----------
    axis : int
        Column of the samples.
    amplitude : float
        ``a``: the output at ``start_s`` less its settled level [unit].
    tau_s : float
        Time constant ``tau`` [s].
    wander : float
        The settled part's Allan deviation at ``tau_s`` [unit].
    start_s : float
        Where the fitted stretch starts, from the first row judged [s].
    settled_s : float
        Where what is left of it is down to SETTLE_LEFT wanders, from the first row
        judged [s].

    """

    axis: int
    amplitude: float
    tau_s: float
    wander: float
    start_s: float
    settled_s: float

    @property
    def score(self) -> float:
        """Return the amplitude in wanders, ``|a| / wander``."""
        return abs(self.amplitude) / self.wander


@dataclass(frozen=True)
class Settling:
    """
    Where a stretch of samples has settled.

    Attributes
    ----------
    rows : int
        Rows judged.
    cut_rows : int
        Rows before the settled point (0: settled from the start).
    rate_hz : float
        Sample rate [Hz].
    transients : tuple of Transient
        The transients found, in the order of the passes.
    needed_rows : int
        Rows the transients need cut; more than ``cut_rows`` when the cut was capped:
        the output was still settling at the cut.

    """

    rows: int
    cut_rows: int
    rate_hz: float
    transients: tuple = ()
    needed_rows: int = 0

    @property
    def cut_s(self) -> float:
        """Return the time left out [s]."""
        return self.cut_rows / self.rate_hz

    @property
    def capped(self) -> bool:
        """Return whether the output was still settling at the cut."""
        return self.needed_rows > self.cut_rows

    @property
    def axes(self) -> tuple:
        """Return the columns with a transient, in order."""
        return tuple(sorted({t.axis for t in self.transients}))

    def left_at_cut(self, axis: int) -> float:
        """Return what is left of the axis' transients at the cut [unit], 0 for none."""
        t_s = self.cut_s
        return float(sum(t.amplitude * math.exp(-max(t_s - t.start_s, 0.0) / t.tau_s)
                         for t in self.transients if t.axis == axis))


def find_settling(samples: np.ndarray, rate_hz: float, max_cut_rows: int | None = None) \
        -> Settling:
    """
    Find where the output of a record's first stretch has settled.

    Parameters
    ----------
    samples : np.ndarray
        Shape (n, k), the stretch's samples in time order [unit per column].
    rate_hz : float
        Sample rate [Hz]; times are row numbers over it.
    max_cut_rows : int, optional
        Most rows the cut may take (default ``n``).

    Returns
    -------
    Settling
        The cut and the transients that set it.

    """
    y = np.asarray(samples, dtype=np.float64)
    n = y.shape[0]
    cap = n if max_cut_rows is None else max(0, min(int(max_cut_rows), n))
    found: list[Transient] = []
    start = 0
    for _ in range(SETTLE_PASSES):
        if start >= n:
            break
        more = _judge(y[start:], rate_hz, start / rate_hz)
        if not more:
            break
        found += more
        start = max(start, max(int(math.ceil(t.settled_s * rate_hz)) for t in more))
    needed = start if found else 0
    return Settling(rows=n, cut_rows=min(needed, cap), rate_hz=float(rate_hz),
                    transients=tuple(found), needed_rows=needed)


def _judge(y: np.ndarray, rate_hz: float, start_s: float) -> list[Transient]:
    """Return the transients of one stretch (n, k) that starts at ``start_s`` [s]."""
    n, k = y.shape
    size = max(1, n // BLOCKS)
    nb = n // size
    if nb < MIN_BLOCKS:
        return []
    m = y[:nb * size].reshape(nb, size, k).mean(axis=1)
    m -= np.median(m, axis=0)
    block_s = size / rate_hz
    t_s = (np.arange(nb) + 0.5) * block_s
    lo, hi = 2 * block_s, nb * block_s / 4
    taus = np.geomspace(lo, hi, int(math.ceil(TAUS_PER_DECADE * math.log10(hi / lo))) + 1)
    # Least squares of c + a e per axis and tau, with e centred: a = cov / var.
    e = np.exp(-t_s[None, :] / taus[:, None])
    ec = e - e.mean(axis=1, keepdims=True)
    var = np.einsum('ij,ij->i', ec, ec)
    cov = ec @ (m - m.mean(axis=0))
    best = np.argmax(cov * cov / var[:, None], axis=0)
    out = []
    for j in range(k):
        b = best[j]
        a = cov[b, j] / var[b]
        # The noise of the later half, and from SETTLED_TAUS time constants on, with
        # the fitted transient taken off: the larger.
        resid = m[:, j] - a * ec[b]
        apart = nb * block_s / 3
        after = int(np.searchsorted(t_s, SETTLED_TAUS * taus[b]))
        wander = _wander(resid[nb // 2:], block_s, float(taus[b]), apart)
        if nb - after >= MIN_BLOCKS // 2:
            wander = max(wander, _wander(resid[after:], block_s, float(taus[b]), apart))
        if not (wander > 0 and math.isfinite(wander)):
            continue            # a frozen or constant axis: nothing to judge
        score = abs(a) / wander
        if score > SETTLE_SCORE:
            settled = max(float(taus[b]) * math.log(score / SETTLE_LEFT),
                          _settled_two(ec, cov[:, j], taus, wander))
            out.append(Transient(j, float(a), float(taus[b]), wander, start_s,
                                 start_s + settled))
    return out


def _settled_two(ec: np.ndarray, cov: np.ndarray, taus: np.ndarray, wander: float) -> float:
    """
    Return where a fit with two time constants is down to SETTLE_LEFT wanders [s].

    A transient of two time constants (or a ramp to a level) has a slower tail than
    the one exponential that fits it best: ``a1 exp(-t / tau1) + a2 exp(-t / tau2)``,
    ``tau2`` at least 3 ``tau1``, ``a1`` and ``a2`` of one sign, fitted by least
    squares over every such pair.  It counts when its slower part is SETTLE_TAIL
    wanders (else 0 is returned): noise alone fits a small slow part.

    Parameters
    ----------
    ec : np.ndarray
        Shape (n_taus, nb), the exponentials at the block times, centred.
    cov : np.ndarray
        Shape (n_taus,), their products with the block means.
    taus : np.ndarray
        Shape (n_taus,), the time constants [s].
    wander : float
        The noise at the transient's scale [unit].

    """
    g = ec @ ec.T
    p, q = np.nonzero(taus[None, :] >= 3 * taus[:, None])
    if not p.size:
        return 0.0
    det = g[p, p] * g[q, q] - g[p, q] ** 2
    ok = det > 1e-12 * g[p, p] * g[q, q]
    p, q, det = p[ok], q[ok], det[ok]
    a1 = (g[q, q] * cov[p] - g[p, q] * cov[q]) / det
    a2 = (g[p, p] * cov[q] - g[p, q] * cov[p]) / det
    # Parts of one sign (a warm-up moves one way): opposite ones cancel in the data and
    # part only after it.
    gain = np.where(a1 * a2 > 0, a1 * cov[p] + a2 * cov[q], -np.inf)
    k = int(np.argmax(gain))
    if not np.isfinite(gain[k]) or abs(a2[k]) < SETTLE_TAIL * wander:
        return 0.0
    t_s = np.linspace(0.0, 20 * taus[q[k]], 4001)
    f = a1[k] * np.exp(-t_s / taus[p[k]]) + a2[k] * np.exp(-t_s / taus[q[k]])
    over = np.flatnonzero(np.abs(f) > SETTLE_LEFT * wander)
    return float(t_s[over[-1] + 1]) if over.size else 0.0


def nnls_few(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """
    Return the non-negative least-squares solution of a few unknowns.

    Every subset of the columns solved by least squares, the best one whose
    coefficients are all non-negative: the optimum of a convex problem is the
    least-squares solution on its own support.  Three unknowns make 7 subsets; numpy
    only, so the main process of an analysis imports no scipy.optimize.

    Parameters
    ----------
    a : numpy.ndarray
        Shape (m, k), the design, k small.
    b : numpy.ndarray
        Shape (m,), the data.

    Returns
    -------
    numpy.ndarray
        Shape (k,), the coefficients (>= 0).

    """
    k = a.shape[1]
    best, best_ss = np.zeros(k), float(b @ b)
    for mask in range(1, 2 ** k):
        cols = [j for j in range(k) if mask >> j & 1]
        sol = np.linalg.lstsq(a[:, cols], b, rcond=None)[0]
        if (sol < 0).any():
            continue
        r = b - a[:, cols] @ sol
        if float(r @ r) < best_ss:
            best_ss, best = float(r @ r), np.zeros(k)
            best[cols] = sol
    return best


def _wander(x: np.ndarray, block_s: float, tau_s: float, apart_s: float) -> float:
    """
    Return how far a level fitted over ``tau_s`` wanders from one ``apart_s`` away [unit].

    Overlapping Allan variances of the block means ``x`` (h,) (NIST SP 1065 eq. 14) at
    1, 2, 4 ... blocks, while a cluster is at most a quarter of ``x``, fitted by
    non-negative least squares with white, flicker and random-walk terms,
    ``A / tau + C + D tau`` (IEEE Std 952 C.1), each weighted by its clusters: the
    model pools every cluster size, so one low estimate at the longest clusters (a few
    differences) does not hide a random walk.  The white and flicker parts are taken at
    ``tau_s``, the random walk at ``apart_s`` at least: it moves the early level away
    from the later one, and they are about that far apart.
    """
    h = x.size
    c = np.concatenate(([0.0], np.cumsum(x)))
    rows, avar = [], []
    s = 1
    while 4 * s <= h:
        avg = (c[s:] - c[:-s]) / s
        d = avg[s:] - avg[:-s]
        rows.append((s * block_s, d.size / s))
        avar.append(float(np.mean(d * d)) / 2)
        s *= 2
    v = np.array(avar)
    if v.size < 2 or not (v > 0).all():
        return 0.0
    tau, clusters = np.array(rows).T
    design = np.stack([1 / tau, np.ones_like(tau), tau], axis=1)
    # The variance of an Allan variance is about 2 avar^2 / clusters: weights from the
    # model, not from the estimates (a low estimate would weigh most), refined twice.
    model = np.full_like(v, v.mean())
    for _ in range(3):
        w = np.sqrt(clusters / 2) / model
        coef = nnls_few(design * w[:, None], v * w)
        model = np.maximum(design @ coef, 1e-3 * v.mean())
    return math.sqrt(float(coef @ [1 / tau_s, 1.0, max(tau_s, apart_s)]))
