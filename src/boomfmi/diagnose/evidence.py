"""How probable each explanation of a gap is: the evidence of every candidate set.

A *set* is an explanation of the holdout gap: ``none`` (the baseline as identified),
each effect of the catalogue alone, each pair fitted jointly, and ``unexplained``
(something not in the catalogue).  Each is scored by its evidence on both kinds of
recording, ``log p(fit, holdout | set) = log p(fit | set) + log p(holdout | fit, set)``:

* **The fit recordings** (where the set's parameters were fitted): the likelihood at the
  fitted parameters, penalised by BIC, ``k / 2 log n`` for ``k`` parameters (the
  Laplace approximation's Occam factor with a unit-information prior; ``n`` the larger
  of the fit recordings' and the holdout's effective sample counts).  Only the sum of
  the channels' squared NRMSE is kept of a fit (``attribute.fit_cost``), so the fit
  recordings' channels are pooled: one Gaussian of variance ``fit_cost / 3`` per sample.
* **The holdout recordings** (never fitted on): the predictive likelihood of the set's
  residual, per channel a Gaussian whose variance is the residual's mean square
  (its NRMSE squared), never below the predictive floor: the channel's noise floor
  (``identify.preprocess.noise_floor``) plus what the baseline's own uncertainty moves
  the prediction (``attribute.baseline_spread``), in quadrature: differences within
  what the identification leaves open tell little.
* **Samples are not independent.**  Thousands of samples at 1 kHz carry far fewer
  independent values: a model's misfit is slow.  Each channel counts its *effective*
  samples, ``N / tau`` with ``tau = 1 + 2 sum rho_k`` the integrated autocorrelation time
  of the baseline's holdout residual (summed over the lags up to the first whose
  autocorrelation falls below ``RHO_CUT``, where the correlation is lost in its own
  noise: a truncated sum as in Sokal's or Geyer's estimators), :func:`effective_count`.  The baseline's residual is the one every set
  is judged against, and the slowest (its gap is the misfit): a count that errs on the
  side of too few, so that tiny differences between sets are not over-trusted (a naive
  BIC at 1 kHz calls every 0.1 % a certainty).  The fit recordings count at the same
  rate per second.
* **"unexplained"**: an explicit model of something not in the catalogue: the best
  explanation (by evidence, ``none`` included) plus an unknown mechanism that removes
  what it leaves on the holdout beyond the floor ``sqrt((NOISE_FACTOR sigma)^2 +
  spread^2)`` per channel (``sigma`` the noise floor, ``spread`` the baseline's own
  uncertainty, ``attribute.baseline_spread``: a residual within that is no finding, as
  the identification itself leaves it open), at the price of ``K_UNEXPLAINED`` further
  parameters (more than any catalogue effect has: an unknown form is a wider family).
  Its fit term is the best explanation's (nothing is known of the unknown there).
* **Form error.**  A catalogue law is one variant of a real component's (a cushion's
  needle, spear or check valve): the right effect of a not quite right form leaves a
  residual that grows with what it explains.  Each set's predictive floor (holdout and
  fit recordings alike) therefore adds ``FORM_ERROR`` times what it explains of the
  baseline's error, per channel (the fit recordings' pooled), and "unexplained" removes
  only what the best explanation leaves beyond that too: a strong explanation of a
  slightly wrong form is not taken for something outside the catalogue.
* **The prior**: each effect of the catalogue, and the unknown mechanism, present with
  odds ``PRIOR_ODDS`` independently, so ``log prior(set) = |set| log PRIOR_ODDS``
  (``none``: 0; a pair twice one effect's).

The probabilities are the evidences normalised (a softmax over the sets' log evidence),
and sum to 1; the verdict is the most probable set.  ``PRIOR_ODDS``, ``K_UNEXPLAINED``
and ``FORM_ERROR`` were checked on the blind benchmark's cases
(``benchmarks/diagnosis_blind.py``, their diagnoses replayed): the verdicts are the same
for odds 0.03 to 0.1, 4 to 8 parameters and a form error of 0.3 to 0.7 but for one
case; without the form error, cushions of another variant than the catalogue's were
"unexplained"; leaving the fit recordings' term out loses the pair of a weak effect
beside a strong one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..compare import PRESSURES, as_sensed, recorded
from ..identify.preprocess import NOISE_FACTOR

#: the autocorrelation below which the residual's lags stop counting (its own noise)
RHO_CUT = 0.05
#: each effect's (and an unknown mechanism's) prior odds of being present
PRIOR_ODDS = 0.1
#: the parameters of "something not in the catalogue": twice the widest law of the
#: catalogue (three), as an unknown form is a wider family than any one effect's
K_UNEXPLAINED = 6
#: an explanation's form error: the share of what it explains (per channel) by which a
#: right effect of a not quite right form may still miss (a catalogue law is one variant
#: of a real component's), within which what it leaves tells nothing further
FORM_ERROR = 0.5

NONE, UNEXPLAINED = "none", "unexplained"


def effective_count(residual) -> float:
    """The effective number of independent samples of a residual series: ``N / tau``,
    ``tau = 1 + 2 sum_k rho_k`` over the lags while the autocorrelation ``rho_k`` stays
    above ``RHO_CUT`` (at least 1, at most ``N``)."""
    r = np.asarray(residual, dtype=float)
    r = r[np.isfinite(r)]
    n = r.size
    if n < 3:
        return float(max(n, 1))
    r = r - r.mean()
    var = float(np.dot(r, r))
    if var <= 0.0:
        return float(n)
    size = 1 << int(2 * n - 1).bit_length()
    f = np.fft.rfft(r, size)
    acf = np.fft.irfft(f * np.conj(f), size)[:n] / var
    below = np.nonzero(acf[1:] < RHO_CUT)[0]
    last = int(below[0]) if below.size else n - 1      # lags 1 .. last
    tau = 1.0 + 2.0 * float(np.sum(acf[1:last + 1]))
    return float(min(max(n / max(tau, 1.0), 1.0), n))


def residual_counts(sims, recs) -> tuple[dict, float]:
    """The effective sample count per channel of the residuals of ``sims`` (a model's
    runs, one per recording, each channel on the recording's samples) on ``recs``,
    summed over the recordings (:func:`effective_count`), and the recordings' length in
    seconds."""
    counts: dict = {}
    seconds = 0.0
    for sim, rec in zip(sims, recs):
        t = rec.data["t"].to_numpy(float)
        seconds += float(t[-1] - t[0]) if t.size > 1 else 0.0
        for c, measured in recorded(rec).items():
            model = np.asarray(sim[c], float)
            if c in PRESSURES:
                model = as_sensed(measured, model)
            counts[c] = counts.get(c, 0.0) + effective_count(measured - model)
    return counts, seconds


@dataclass
class Hypothesis:
    """One candidate set: its name (effects joined by " + "; ``none``), its number of
    fitted parameters, its holdout NRMSE per channel, its fit cost (the fit recordings'
    summed squared NRMSE; None: not known, the fit term left out for every set alike)
    and its number of effects (the prior)."""
    name: str
    k: int
    holdout: dict
    fit_cost: float | None = None
    effects: int = 0
    explained: dict | None = None   #: per channel what it explains of the baseline's error (None: from ``none``'s)


def _holdout_loglik(holdout: dict, noise: dict, counts: dict, spread: dict, explained: dict) -> float:
    out = 0.0
    for c, e in holdout.items():
        if not math.isfinite(e):
            return -math.inf
        var = max(float(e) ** 2, float(noise.get(c, 0.0)) ** 2 + float(spread.get(c, 0.0)) ** 2
                  + (FORM_ERROR * explained.get(c, 0.0)) ** 2, 1e-18)
        out += -0.5 * counts[c] * (math.log(2.0 * math.pi * var) + float(e) ** 2 / var)
    return out


def _fit_loglik(cost: float | None, noise: dict, n_fit: float, base_cost: float | None = None) -> float:
    if cost is None or n_fit <= 0:
        return 0.0
    if not math.isfinite(cost):       # no value of the set's parameters fitted (no physical load)
        return -math.inf
    channels = max(len(noise), 1)
    explained = max(math.sqrt(base_cost / channels) - math.sqrt(float(cost) / channels), 0.0) \
        if base_cost is not None and math.isfinite(base_cost) else 0.0
    var = max(float(cost) / channels,
              sum(v * v for v in noise.values()) / channels + (FORM_ERROR * explained) ** 2, 1e-18)
    return -0.5 * n_fit * (math.log(2.0 * math.pi * var) + float(cost) / channels / var)


def log_evidence(h: Hypothesis, noise: dict, counts: dict, n_fit: float, spread: dict | None = None,
                 base_cost: float | None = None) -> float:
    """``h``'s log evidence (see the module's docstring): holdout predictive likelihood
    (its variance at least the noise's plus the baseline's ``spread``'s), fit
    likelihood, BIC penalty on the fit recordings' effective count, prior."""
    penalty = 0.5 * h.k * math.log(max(n_fit, sum(counts.values()), 2.0))
    return (_holdout_loglik(h.holdout, noise, counts, spread or {}, h.explained or {})
            + _fit_loglik(h.fit_cost, noise, n_fit, base_cost)
            - penalty + h.effects * math.log(PRIOR_ODDS))


def unexplained(best: Hypothesis, noise: dict, spread: dict) -> Hypothesis:
    """``best`` plus an unknown mechanism that removes what ``best`` leaves on the holdout
    beyond ``sqrt((NOISE_FACTOR sigma)^2 + spread^2 + (FORM_ERROR explained)^2)`` per
    channel (``explained``: what ``best`` explains there, whose form error the unknown
    cannot be told from)."""
    explained = best.explained or {}
    floor = {c: math.sqrt((NOISE_FACTOR * noise.get(c, 0.0)) ** 2 + spread.get(c, 0.0) ** 2
                          + (FORM_ERROR * explained.get(c, 0.0)) ** 2) for c in best.holdout}
    return Hypothesis(UNEXPLAINED, best.k + K_UNEXPLAINED, {c: min(e, floor[c]) for c, e in best.holdout.items()},
                      best.fit_cost, best.effects + 1, explained)


def probabilities(hypotheses: list, noise: dict, counts: dict, n_fit: float,
                  spread: dict | None = None) -> dict:
    """``{set name: probability}`` over ``hypotheses`` (``none`` among them) and
    ``unexplained``; summing to 1, the most probable first."""
    if not hypotheses:
        raise ValueError("no candidate set to weigh: at least the baseline ('none') is needed")
    base = next((h.holdout for h in hypotheses if h.name == NONE), None)
    base_cost = next((h.fit_cost for h in hypotheses if h.name == NONE), None)
    if base is not None:        # what each explains of the baseline's error, per channel (its form error's scale)
        hypotheses = [h if h.explained is not None else
                      Hypothesis(h.name, h.k, h.holdout, h.fit_cost, h.effects,
                                 {c: max(base.get(c, e) - e, 0.0) for c, e in h.holdout.items()})
                      for h in hypotheses]
    scored = {h.name: log_evidence(h, noise, counts, n_fit, spread, base_cost) for h in hypotheses}
    best = max(hypotheses, key=lambda h: scored[h.name])
    if UNEXPLAINED not in scored:
        scored[UNEXPLAINED] = log_evidence(unexplained(best, noise, spread or {}), noise, counts, n_fit, spread,
                                           base_cost)
    top = max(scored.values())
    w = {n: math.exp(v - top) for n, v in scored.items()}
    total = sum(w.values())
    return dict(sorted(((n, v / total) for n, v in w.items()), key=lambda kv: -kv[1]))


__all__ = ["RHO_CUT", "PRIOR_ODDS", "K_UNEXPLAINED", "NONE", "UNEXPLAINED", "effective_count", "residual_counts",
           "Hypothesis", "log_evidence", "unexplained", "probabilities"]
