"""
Rival explanations of the same gap, compared by their full likelihood.

Each rival is re-fitted at its own weights (IRLS), so effects that change the curve's
covariance differently compete on -2 ln L plus BIC's penalty, not on one screen.
"""

import math

import numpy as np

from imu_allan.core.fit.axis import n_params
from imu_allan.core.fit.criterion import criterion
from imu_allan.core.fit.judge import shows_quantization
from imu_allan.core.rules import DELTA_MIN, N_RIVALS
from imu_allan.core.search.rules import _label_for, Choice, RunnerUp


def _by_likelihood(fitter, slots_of, labels: list, ranked: list, penalty: float) -> list:
    """
    Order the qualifying effects by penalised Gaussian likelihood, best first.

    The first screen scores every effect at the current model's weights.  Rivals can
    trade roles there (a second Gauss-Markov process against flicker noise, a
    Gauss-Markov process of very long T against a random walk), and each changes the
    covariance of the curve in its own way, so the best :data:`N_RIVALS` are re-fitted
    to convergence and compared by -2 ln L = J + ln det Sigma (GLS chi-square at the
    model's own covariance plus its log-determinant) + ln(k) per parameter (BIC).
    """
    ranked = sorted(ranked, key=lambda r: -r.score)
    if len(ranked) < 2:
        return ranked
    scored = []
    for r in ranked[:N_RIVALS]:
        slots = slots_of(labels + [r.label])
        sol, _ = fitter.irls(slots, phi0=r.solution.phi, local=True)
        logdet = 2.0 * float(np.sum(np.log(np.abs(np.diag(fitter.data.chol)))))
        scored.append((sol.j + logdet + n_params(slots) * penalty, r))
    scored.sort(key=lambda x: x[0])
    return [r for _, r in scored] + ranked[N_RIVALS:]


def _neg2_loglik(fitter, sol, n_params: int, penalty: float) -> float:
    """-2 ln L + BIC penalty of a solution at the fitter's current Sigma (:mod:`criterion`)."""
    logdet = 2.0 * float(np.sum(np.log(np.abs(np.diag(fitter.data.chol)))))
    return criterion(sol.j + logdet, n_params, penalty)


def _second_chance(fitter, slots_of, labels: list, sol, sigma, effects, penalty: float):
    """
    Re-fit each noise effect with its own weights; return the best step or None.

    Used when the screen at the current weights found nothing but the chi-square still
    rejects the model.  Sinusoids and ramps need their time-domain evidence and are
    not tried here.  A step is taken when its penalised -2 ln L (:func:`_by_likelihood`)
    beats the current model's by :data:`DELTA_MIN`.
    """
    fitter.data.set_sigma(sigma)
    current = _neg2_loglik(fitter, sol, n_params(slots_of(labels)), penalty)
    best = None
    for effect in effects:
        label = _label_for(effect, labels)
        if label is None or effect in ('sinusoid', 'rate_ramp'):
            continue
        if effect == 'quantization' and not shows_quantization(fitter.data.tau, fitter.data.y):
            continue
        slots = slots_of(labels + [label])
        if n_params(slots) >= fitter.data.tau.size:
            continue
        new, _ = fitter.irls(slots, phi0=list(sol.phi) + [
            tuple(math.sqrt(lo * hi) for lo, hi in slots[-1].bounds)],
            grid_slots=_grid_slots(effect, slots))
        if new.coef[-1] <= 0:
            continue
        value = _neg2_loglik(fitter, new, n_params(slots), penalty)
        if current - value > DELTA_MIN and (best is None or value < best[0]):
            best = (value, Choice(float(current - value), effect, label, new, RunnerUp(),
                                  'chosen by likelihood with its own weights'))
    return None if best is None else best[1]


def _grid_slots(effect: str, slots) -> list | None:
    """Slots whose parameters a fit with an added effect (the last slot) grids anew."""
    # Interchangeable Gauss-Markov terms keep their order (shortest T first), so a
    # further one may need to take the other's place: grid them all.
    family = effect == 'gauss_markov' and any(
        x.term.name in ('gauss_markov', 'bias_instability') for x in slots[:-1])
    return None if family else [len(slots) - 1]
