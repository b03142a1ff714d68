"""
The terms over filled samples in the streaming accumulator: left out, or repaired.

Missing samples (:meth:`~imu_allan.core.allan.accumulator.AllanAccumulator.add` with
``missing``): a short gap filled by the caller keeps the segment whole.  At exact taus
the accumulator also sums the terms whose 2m samples hold a filled one
(:func:`imu_allan.core.allan.window_sums.dirty_terms`), and :func:`used_terms` leaves
them out while that keeps at least half of the terms (:data:`SKIP_SHARE`): the
overlapping estimator over the available terms, the gap estimator of Sesia and Tavella
(Metrologia 45, 2008, S134), unbiased whatever the noise.  Beyond (at 2 % of samples
missing at random, from m = 17 on) nearly every term holds a filled sample and the
filled terms are used, with their count scaled by the share of real samples, so the
EDF and the curve's covariance count only real data.  A fill reads white noise high: a
gap of g samples filled by linear interpolation gives its two neighbours the weight
1 + g / 2 in a cluster, so the sum over all terms of a cluster size m exceeds the
real samples' by sigma^2 (g + g^2 / 2) (2 m - 4) (summed over the term positions,
the gap's neighbours straddling a cluster edge included; sigma^2 the variance of
white samples).  With K the sum of g + g^2 / 2 over the gaps (:func:`gap_excess`) and
N the samples, the filled taus subtract sigma^2 K (m - 2) / (N m^2) from the AVAR,
sigma^2 read off the first tau over real samples alone.  Unrepaired, 2 % of the
samples lost at random read white noise 3 % high there (15 % at 10 %); repaired,
within 0.5 % (1.5 % at 10 %, m >= 4) on simulated white and random-walk noise
(test/test_fill_terms.py).
"""

import numpy as np

#: A tau keeps only the terms free of missing samples while they are at least this share
#: of all its terms; below, the terms over filled samples are kept too (module docstring).
SKIP_SHARE = 0.5


def gap_excess(missing: np.ndarray, run: int) -> tuple[float, int]:
    """
    Return a block's share of K, the sum of g + g^2 / 2 over the gaps, and its last run.

    Each missing sample adds 1.5 + r, r its place in its gap (0 for the first), so a gap
    of g samples adds g + g^2 / 2 however the blocks cut it.

    Parameters
    ----------
    missing : np.ndarray
        Shape (n,), bool: the block's missing (filled) samples.
    run : int
        Missing samples that ended the previous block (a gap that goes on here).

    Returns
    -------
    excess : float
        The block's part of K [samples].
    run : int
        Missing samples that end this block.

    """
    if not missing.any():
        return 0.0, 0
    idx = np.arange(missing.size)
    last_real = np.maximum.accumulate(np.where(missing, -1, idx))
    place = idx - last_real - 1 + np.where(last_real < 0, run, 0)
    return float(np.sum(1.5 + place[missing])), (int(place[-1]) + 1 if missing[-1] else 0)


def used_terms(m: np.ndarray, sums: np.ndarray, counts: np.ndarray, dirty_sums: np.ndarray,
               dirty_counts: np.ndarray, n_missing: int, n_samples: int,
               fill_excess: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return the sums, term counts and effective counts a curve uses per tau.

    With missing samples, an exact tau keeps the terms free of them while they are at
    least :data:`SKIP_SHARE` of its terms (then every term counts in full); otherwise
    all terms are kept, less the fills' white-noise excess (module docstring), and
    count by the share of real samples.

    Parameters
    ----------
    m : np.ndarray
        Shape (K,), cluster sizes [samples], the exact ones first.
    sums, counts : np.ndarray
        Shapes (K, n_axes) and (K,): the pooled sums of squared second differences and
        their term counts.
    dirty_sums, dirty_counts : np.ndarray
        Shapes (k0, n_axes) and (k0,): the part of them over missing samples, at the k0
        exact taus.
    n_missing, n_samples : int
        Missing samples and all samples added.
    fill_excess : float
        K, the sum of g + g^2 / 2 over the gaps (:func:`gap_excess`) [samples].

    Returns
    -------
    sums : np.ndarray
        Shape (K, n_axes), the sums used.
    counts : np.ndarray
        Shape (K,), their terms.
    eff : np.ndarray
        Shape (K,), the terms' count as real data (for the EDF).

    """
    if not n_missing:
        return sums, counts, counts
    k0 = dirty_counts.size
    clean = counts[:k0] - dirty_counts
    skip = (dirty_counts > 0) & (clean >= SKIP_SHARE * counts[:k0])
    sums, counts = sums.copy(), counts.copy()
    # The clean sums are the larger part here: the difference keeps their digits.
    sums[:k0][skip] = np.maximum(sums[:k0][skip] - dirty_sums[skip], 0.0)
    counts[:k0][skip] = clean[skip]
    real = 1.0 - n_missing / max(n_samples, 1)
    eff = np.maximum(np.round(counts * real).astype(np.int64), np.minimum(counts, 1))
    kept = np.zeros(counts.size, bool)
    kept[:k0] = skip | (dirty_counts == 0)
    eff[kept] = counts[kept]
    if counts[0] and m[0] == 1:
        # sigma^2 from the first tau over real samples alone; the excess per term.
        sigma2 = sums[0] / (2.0 * counts[0])
        mf = m.astype(float)
        excess = (sigma2[None, :] * (fill_excess / max(n_samples, 1))
                  * np.maximum(2.0 * mf - 4.0, 0.0)[:, None])
        fix = ~kept & (counts > 0)
        # Never more than half the sum: a guard for noise far from white at tau0.
        sums[fix] = np.maximum(sums[fix] - excess[fix] * counts[fix, None], 0.5 * sums[fix])
    return sums, counts, eff
