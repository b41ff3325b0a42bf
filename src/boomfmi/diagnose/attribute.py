"""Which unmodelled effect explains the gap, and by how much the model improves.

For each candidate of ``effects.md`` (the catalogue, ``model/catalogue.py``, with its
bounds; forms in ``physics/effects.py``; where a mechanism has two laws, as a seal's
leak, both are fitted and the better kept): its few parameters are fitted on the fit
recordings, with the baseline load parameters re-identified first (``identify.fit``),
by output error of the whole model (the monolithic reference with the effect on,
through ``compare.simulate_recording``) on x, p_a and p_b, each residual normalised by
its channel's range.  Each fitted candidate is then scored on the holdout
recordings, which are never fitted on: ``shrink = 1 - (error after) / (error before)``,
errors summed over the three channels.  A second effect is fitted beside the best
where the best leaves a gap.

Decisions carry margins against the recordings' own noise:

* no gap: the baseline's holdout error is within ``NOISE_FACTOR`` times the noise
  floor (each channel's noise over its range) plus ``ABS_FLOOR``: verdict ``[]``;
* the best candidate shrinks the error by at least ``MIN_SHRINK``: it is the verdict;
  where the error it leaves is still beyond the noise, the next candidates are fitted
  beside it, and the best of them joins the verdict when it removes at least
  ``MIN_SHRINK_SECOND`` of that remaining error;
* otherwise ``["unexplained"]``.
"""
from __future__ import annotations

import itertools
import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from ..compare import CHANNELS, nrmse, recorded, shrink, simulate_recording
from ..identify.preprocess import lowpass
from ..model import EFFECTS, lagged

#: name -> [(parameter, lower, upper, log scale)] of its first law, from the catalogue
CANDIDATES = {name: [(p.name, p.lower, p.upper, p.log) for p in e.forms[0]] for name, e in EFFECTS.items()}
#: effects with more than one law for their mechanism: each law is fitted and the one
#: that fits the fit recordings best is kept (a seal leaks laminar or turbulent)
FORMS = {name: [[(p.name, p.lower, p.upper, p.log) for p in form] for form in e.forms]
         for name, e in EFFECTS.items() if len(e.forms) > 1}
NOISE_FACTOR = 3.0
ABS_FLOOR = 0.002
MIN_SHRINK = 0.35
MIN_SHRINK_SECOND = 0.4     #: the share of the gap left by the best that a second effect must remove
PAIR_TRIES = 3              #: the candidates tried as a second effect
RTOL = 1e-5            #: the reference solver's tolerance when scoring
FIT_RTOL = 1e-4        #: and while fitting (each fit runs the model a dozen times or more)


def errors(values: dict, effects: dict, rec, rtol: float = RTOL) -> dict:
    """NRMSE per channel of the model (``values`` and ``effects``) on one recording.

    The sensor lag acts on the measured channels only, after the physics: with it
    alone, the model runs once (cached) and only the filter varies."""
    only_lag = set(effects) == {"sensor_lag"}
    sim = _baseline(values, rec, rtol) if only_lag else simulate_recording(values, rec, effects=effects, rtol=rtol)
    if only_lag:
        t = sim["time"].to_numpy()
        sim = {c: lagged(sim[c].to_numpy(), t, effects["sensor_lag"]["tau"]) for c in CHANNELS}
    return nrmse(sim, rec)


_cache: dict = {}


def _baseline(values: dict, rec, rtol: float):
    key = (id(rec), tuple(sorted(values.items())), rtol)
    if key not in _cache:
        if len(_cache) > 32:
            _cache.clear()
        _cache[key] = simulate_recording(values, rec, rtol=rtol)
    return _cache[key]


def mean_errors(values, effects, recs, rtol: float = RTOL) -> dict:
    per = [errors(values, effects, r, rtol) for r in recs]
    return {c: float(np.mean([e[c] for e in per])) for c in CHANNELS}


def noise_floor(rec) -> dict:
    """Each channel's measurement noise over its range: the RMS of what a 50 Hz
    low-pass removes."""
    m = recorded(rec)
    fs = 1.0 / float(np.median(np.diff(rec.data["t"].to_numpy(float))))
    return {c: float(np.std(m[c] - lowpass(m[c], fs, 50.0)) / max(float(np.ptp(m[c])), 1e-12)) for c in CHANNELS}


@dataclass
class Candidate:
    name: str
    params: dict
    fit_error: float
    holdout: dict = field(default_factory=dict)
    shrink: float = 0.0
    score: float = 0.0


def fit_effects(names: list[str], values: dict, fit_recs, start: dict | None = None,
                fixed: dict | None = None, forms: dict | None = None) -> tuple[dict, float]:
    """Fit the parameters of the effects ``names`` together on the fit recordings:
    ``({name: {param: value}}, cost)``.  One parameter: a bounded scalar search.  More:
    Nelder-Mead from ``start`` (``{name: {param: value}}``, e.g. each effect's own fit),
    or else from the best point of a coarse grid (4 levels per parameter), since the
    cost of a two-parameter effect such as the cushion is a narrow valley.  ``fixed``:
    further effects switched on with their parameters held (returned with the fit).
    ``forms``: {name: [(param, lower, upper, log)]} in place of CANDIDATES[name]."""
    spec = [(n, *s) for n in names for s in (forms or {}).get(n, CANDIDATES[n])]

    def to_effects(z):
        out: dict = {n: dict(p) for n, p in (fixed or {}).items()}
        for (n, p, lo, hi, log), v in zip(spec, z):
            out.setdefault(n, {})[p] = float(10 ** v if log else v)
        return out

    def cost(z):
        e = mean_errors(values, to_effects(z), fit_recs, FIT_RTOL)
        return sum(v * v for v in e.values())

    bounds = [(math.log10(lo), math.log10(hi)) if log else (lo, hi) for _, _, lo, hi, log in spec]
    if len(spec) == 1:
        res = minimize_scalar(lambda v: cost([v]), bounds=bounds[0], method="bounded",
                              options={"xatol": 0.02 * (bounds[0][1] - bounds[0][0])})
        z, fun = [res.x], res.fun
    else:
        if start is not None:
            z0 = [min(max(math.log10(start[n][p]) if log else start[n][p], b[0]), b[1])
                  for (n, p, lo, hi, log), b in zip(spec, bounds)]
        else:
            levels = [np.linspace(lo, hi, 6)[1:-1] for lo, hi in bounds]
            z0 = list(min(itertools.product(*levels), key=cost))
        res = minimize(cost, z0, method="Nelder-Mead", bounds=bounds,
                       options={"maxfev": 40, "xatol": 1e-3, "fatol": 1e-9})
        z, fun = res.x, res.fun
    return to_effects(z), float(fun)


@dataclass
class Attribution:
    baseline_holdout: dict
    noise: dict
    gap: bool
    candidates: list
    verdict: list


def _fit_and_score(args):
    name, values, fit_recs, hold_recs, fixed = args
    fx, cost = min((fit_effects([name], values, fit_recs, fixed=fixed, forms={name: form})
                    for form in FORMS.get(name, [CANDIDATES[name]])), key=lambda fit: fit[1])
    return name, fx, cost, mean_errors(values, fx, hold_recs)


def _cost(job) -> int:
    """A fit's rough cost, for scheduling: steep in its parameters (a grid, then a
    simplex), times its laws."""
    name = job[0]
    return len(CANDIDATES[name]) ** 3 * len(FORMS.get(name, [None]))


def _map(fn, jobs, workers):
    """``fn`` over ``jobs`` in ``workers`` processes, the costliest started first (so
    that the two-parameter fit does not start last); results in the jobs' order."""
    if workers > 1 and len(jobs) > 1:
        order = sorted(range(len(jobs)), key=lambda i: -_cost(jobs[i]))
        with ProcessPoolExecutor(min(workers, len(jobs))) as pool:
            done = dict(zip(order, pool.map(fn, [jobs[i] for i in order])))
        return [done[i] for i in range(len(jobs))]
    return [fn(j) for j in jobs]


def attribute(values: dict, fit_recs, hold_recs, names=None, workers: int | None = None) -> Attribution:
    """Fit, score and rank the candidates (``workers`` processes at once; default: one
    per core); decide the verdict."""
    names = list(CANDIDATES) if names is None else names
    before = mean_errors(values, {}, hold_recs)
    floors = [noise_floor(r) for r in hold_recs]
    noise = {c: float(np.mean([f[c] for f in floors])) for c in CHANNELS}
    threshold = NOISE_FACTOR * sum(noise.values()) + ABS_FLOOR
    gap = sum(before.values()) > threshold
    workers = workers or os.cpu_count() or 1
    fitted = _map(_fit_and_score, [(n, values, fit_recs, hold_recs, None) for n in names], workers)
    cands = [Candidate(n, fx[n], cost, after, shrink(before, after))
             for n, fx, cost, after in fitted]
    cands.sort(key=lambda c: -c.shrink)
    weights = [max(c.shrink, 0.0) ** 2 for c in cands]
    total_w = sum(weights) or 1.0
    best_strength = min(1.0, max(cands[0].shrink, 0.0) / MIN_SHRINK) if cands else 0.0
    for c, w in zip(cands, weights):
        c.score = round(best_strength * w / total_w, 4)
    verdict: list = []
    if gap and cands:
        best = cands[0]
        if best.shrink >= MIN_SHRINK:
            verdict = [best.name]
            pair = _second_effect(best, cands[1:], values, fit_recs, hold_recs, before, threshold, workers)
            if pair is not None:
                pair.score = round(best_strength, 4)
                verdict = pair.name.split("+")
                cands.insert(0, pair)
        else:
            verdict = ["unexplained"]
    return Attribution(before, noise, gap, cands, verdict)


def _second_effect(best, others, values, fit_recs, hold_recs, before, threshold, workers):
    """A second effect beside ``best``, where the gap left by ``best`` alone is still
    beyond the noise: each of the next candidates that helped on its own is fitted with
    ``best`` held on; the pair is kept when the second removes at least
    ``MIN_SHRINK_SECOND`` of what ``best`` left (on the holdout recordings)."""
    left = sum(best.holdout.values())
    if left <= threshold:
        return None
    seconds = [c.name for c in others if c.shrink > 0.0][:PAIR_TRIES]
    fixed = {best.name: best.params}
    fitted = _map(_fit_and_score, [(n, values, fit_recs, hold_recs, fixed) for n in seconds], workers)
    pairs = [Candidate(f"{best.name}+{n}", fx, cost, after, shrink(before, after))
             for n, fx, cost, after in fitted]
    if not pairs:
        return None
    top = max(pairs, key=lambda c: c.shrink)
    return top if shrink(best.holdout, top.holdout) >= MIN_SHRINK_SECOND else None
