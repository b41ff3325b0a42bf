"""Which unmodelled effect explains the gap, and by how much the model improves.

Every candidate of ``effects.md`` (the catalogue, ``model/catalogue.py``, with its
bounds; its laws in ``physics/effects.py``) is fitted on the fit recordings and scored
on the holdout recordings, which are never fitted on:
``shrink = 1 - (error after) / (error before)``, the errors (NRMSE) summed over x, p_a
and p_b.

* **Laws.**  Where a mechanism has more than one law (a seal that leaks laminar,
  turbulent or both; a sensor path with a lag, or a dead time and a lag; a cushion
  with or without its port cut off the sensed chamber), each is screened over its
  range and the one that screens best on the fit recordings is fitted; a law that
  holds another's parameters and more is grown from that one's fit, where it removes
  ``GROW`` of the fit error (an effect that barely shows cannot tell its shape), or
  where its further parameters screened beside it remove that much (a cushion without
  a check valve slows the return, which the needle's law never touches): its further
  parameters screened beside it, or, where its own screen takes at most
  ``FRESH_SCREEN`` runs and fits better there, the wider law screened afresh (a lag
  fitted alone bends to mimic a speed limit, and the limit screened beside that lag
  finds nothing), then all refined together, kept where it fits better (a
  three-parameter screen is too coarse to find the cushion's narrow valley) and the
  holdout bears its further parameters out: predicts it no worse than the narrower law
  (a speed limit that slow ramps never reach is fitted to whatever else they miss, and
  the fit recordings alone cannot tell).  The holdout chooses between an effect's laws
  as the evidence chooses between sets (:mod:`.evidence`), on the same recordings.
  Where the fit recordings cannot tell a further parameter at all (screened beside the
  narrower law's fit, it moves their error nowhere by ``SCREEN``: slow ramps and a
  speed limit), the holdout tells it among the values they allow
  (:func:`told_by_holdout`), and the candidate says so (``Candidate.holdout_told``).
* **Fits.**  An effect's parameters are fitted by output error of the whole model (the
  monolithic reference with the effect on, ``compare.simulate_recording``), each
  channel's residual over its range.  Its range is screened first
  (:func:`fit_effects`): an effect that lowers the fit error nowhere by ``SCREEN`` is
  not fitted further.
* **The baseline with the effect.**  The baseline load is identified once, on the
  fit recordings (``identify.fit``: from the recorded pressures, so an effect on the
  pneumatics or on every sensor alike does not bias it).  An effect that changes the
  load's own law (the ``friction`` stage) is fitted jointly with the load: for each
  value of its parameters the load is identified anew with the effect in Eq. 8 and 9
  (:func:`_fit_friction`), so a baseline that absorbed part of the effect does not
  hide it: by the entry's own faster fit where it names one (``Effect.fit``: the
  Stribeck velocity's search, :func:`fit_stribeck`; the seal-pressure coefficient as
  one more linear column, :func:`fit_seal_laws`), else generically
  (:func:`fit_with_load`: the load by nonlinear least squares of the equation error
  with the effect's form in it, the effect's parameters by output error).  No fit
  reads an effect's name: a stage, a fit, a load law or an integrator of its entry.
* **Pairs.**  Where no single effect explains the gap (``MIN_SHRINK``), or the best
  leaves one beyond the noise (the best by holdout shrink, and the most probable
  single where that is another or "unexplained": :func:`pairs_needed`), pairs are
  fitted jointly (:func:`_pairs`) among every candidate that lowers the fit
  recordings' error at all, whatever it does alone to the holdout
  (:func:`pair_combos`: two effects may each explain little alone, or one make the
  holdout worse with the other's misfit around it): both effects and the baseline
  together (a friction effect's load re-identified with it), from the singles' fits
  (:func:`fit_pair_jointly`).  The cost is capped by a budget: at most ``PAIR_JOBS``
  joint fits (as many as the former pool of five candidates allowed), the pairs whose
  singles lowered the fit error most first, each fit at most ``PAIR_EVALUATIONS``
  evaluations; a pair no start of which lowers the fit error is not fitted, but for the
  first ``PAIR_ALWAYS``, whose weaker effect is also screened in each of its laws
  beside the stronger's fit (a single's fit may have absorbed part of the other effect,
  or taken a law that only fits alone).

The verdict is the most probable explanation (:mod:`.evidence`): every candidate set
(``none``: the baseline; each effect; each pair fitted; but a seal-pressure friction the
load's own velocity fit does not tell, :func:`_load_confirms`, which is listed and not
weighed) and ``unexplained`` (something
not in the catalogue) weighed by its evidence on the fit and holdout recordings under
their own noise (each channel's noise floor, the residuals' correlation in time as an
effective sample count, a BIC penalty per parameter, a prior per effect); the
probabilities are reported (``Attribution.probabilities``, each candidate's ``score``
is its set's).  Margins against the recordings' own noise stay where they decide what
is fitted at all:

* no gap: the baseline's holdout error is within ``NOISE_FACTOR`` times the noise
  floor (each channel's noise over its range) plus ``ABS_FLOOR``: verdict ``[]``, and
  no candidate is fitted by the outputs (none could show more than the noise), unless
  the load's own fit tells pressure_friction (:func:`_friction_told`: the seals'
  friction that the baseline's F_d holds at the mean pressure, which may leave the
  outputs within their noise);
* ``none`` most probable: verdict ``[]``, or pressure_friction where the load's own
  fit tells it (as above; that verdict is the load fit's: its candidate, the load
  re-identified with it, is then weighed in place of its output fit, so that its
  probability is reported; it need not be the most probable there);
* ``unexplained`` most probable: ``["unexplained"]``.  Its model removes what the best
  explanation leaves beyond the noise and beyond what the baseline's own uncertainty
  moves its prediction (each identified parameter at the nearer end of its 95 %
  interval, combined in quadrature: :func:`baseline_spread`), so a gap within that is
  no finding: the identification itself leaves it open.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from ..compare import CHANNELS, nrmse, rig_model, shrink, simulate_recording
from ..identify.fit import PRESSURE_COEFFICIENT, identify, load_with_effect, motion, static_friction
from ..identify.preprocess import ABS_FLOOR, NOISE_FACTOR, noise_floor, prepare
from ..model import EFFECTS, Boom, measure
from ..model.boom import measurement_lag
from ..model.reference import SolverError
from ..model.catalogue import STAGES, fit_hook
from .evidence import NONE, UNEXPLAINED, Hypothesis, probabilities, residual_counts

class _Laws(Mapping):
    """The catalogue's laws as the fits read them, read from :data:`model.EFFECTS` at
    each use (not copied at import): a plug-in's effect loaded later (``boomfmi --effects
    FILE``, ``catalogue.load_plugins``) is a candidate on the boom and on each joint's
    cut alike.  ``several``: only the effects with more than one law, each as its laws;
    else every effect as its first law."""

    def __init__(self, several: bool):
        self._several = several

    def _names(self):
        return [n for n, e in EFFECTS.items() if not self._several or len(e.forms) > 1]

    def __getitem__(self, name):
        if name not in self._names():
            raise KeyError(name)
        laws = [[(p.name, p.lower, p.upper, p.log) for p in form] for form in EFFECTS[name].forms]
        return laws if self._several else laws[0]

    def __iter__(self):
        return iter(self._names())

    def __len__(self):
        return len(self._names())


#: name -> [(parameter, lower, upper, log scale)] of its first law, from the catalogue
CANDIDATES = _Laws(several=False)
#: effects with more than one law for their mechanism: each law is fitted and the one
#: that fits the fit recordings best is kept (a seal leaks laminar or turbulent)
FORMS = _Laws(several=True)
MIN_SHRINK = 0.35
MIN_SHRINK_SECOND = 0.4     #: the share of the gap left by the best that a second effect must remove (the excavator's cuts)
PAIR_POOL = 3               #: the candidates among which the excavator's cuts try pairs
SCREEN_POINTS = 4           #: points per parameter that screen an effect's range
SCREEN = 0.02               #: the share of the fit error a screened point must remove to go on
PAIR_EVALUATIONS = 24       #: the joint fit of a pair: its simplex's evaluations at most
GROW_EVALUATIONS = 30       #: and of a law grown by further parameters from a narrower law's fit
GROW = 0.1                  #: the share of the fit error the narrower law must remove to be grown
FRESH_SCREEN = 9            #: the most runs a wider law's own screen may take (two parameters' grid)
FRICTION_GAIN = 0.03   #: the share by which a seal-pressure law must lower the load's velocity misfit
RTOL = 1e-5            #: the reference solver's tolerance when scoring
FIT_RTOL = 1e-4        #: and while fitting (each fit runs the model a dozen times or more)


def errors(values: dict, effects: dict, rec, rtol: float = RTOL) -> dict:
    """NRMSE per channel of the model (``values`` and ``effects``) on one recording.

    The measurement stage's effects (the sensor lag) act on the measured channels only,
    after the physics: with them alone, the model runs once (cached) and only the
    measurement path varies.  A model the reference solver cannot integrate (a
    candidate's load re-identified with a mass of nanograms, whose steps collapse) has
    an infinite error on every channel: it explains nothing."""
    only_measured = bool(effects) and all(EFFECTS[n].stage == "measurement" for n in effects)
    try:
        sim = (_baseline(values, rec, rtol) if only_measured
               else simulate_recording(values, rec, effects=effects, rtol=rtol))
    except SolverError:         # a candidate's model the solver cannot integrate explains nothing
        return {c: math.inf for c in CHANNELS}
    if only_measured:
        t = sim["time"].to_numpy()
        tau, delay = measurement_lag(effects)
        sim = {c: measure(sim[c].to_numpy(), t, tau, delay) for c in CHANNELS}
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


def fit_cost(values: dict, effects: dict, recs) -> float:
    """The fit error a fit minimises: the squares of :func:`mean_errors` at
    ``FIT_RTOL``, summed over the channels."""
    return sum(e * e for e in mean_errors(values, effects, recs, FIT_RTOL).values())


@dataclass
class Candidate:
    name: str
    params: dict
    fit_error: float
    holdout: dict = field(default_factory=dict)
    shrink: float = 0.0
    score: float = 0.0
    values: dict | None = None   #: the baseline re-identified with the effect (None: the common one)
    #: the parameters the fit recordings cannot tell, told by the holdout (:func:`told_by_holdout`)
    holdout_told: list = field(default_factory=list)


def fit_effects(names: list[str], values: dict, fit_recs, start: dict | None = None,
                fixed: dict | None = None, forms: dict | None = None,
                baseline_cost: float | None = None, max_evaluations: int = 40,
                screen_only: bool = False, screened: tuple | None = None,
                cost_of=None) -> tuple[dict, float]:
    """Fit the parameters of the effects ``names`` together on the fit recordings:
    ``({name: {param: value}}, cost)``.

    Without ``start``, the parameters' ranges are screened first: a few points spread
    over them (``SCREEN_POINTS`` per parameter, on a log scale where the catalogue says
    so).  Where none of them lowers the fit recordings' error below ``baseline_cost``
    (the model without the effects) by ``SCREEN`` of it, the effect explains nothing
    there and the best screened point is returned as it is; else the fit goes on from
    the best point: a bounded scalar search around it for one parameter, Nelder-Mead
    for more (the cushion's cost is a narrow valley).  ``start``
    (``{name: {param: value}}``, e.g. each effect's own fit) starts Nelder-Mead there.
    ``fixed``: further effects switched on with their parameters held (returned with
    the fit).  ``forms``: {name: [(param, lower, upper, log)]} in place of
    CANDIDATES[name].  ``screen_only``: the best screened point, not refined;
    ``screened``: ``(effects, cost)``, such a point from before, refined without a
    screen anew.  ``cost_of(effects) -> float``: the error to minimise in place of
    :func:`fit_cost` on ``values`` and ``fit_recs`` (a cut of the model: the
    excavator's per-joint diagnosis)."""
    spec = [(n, *s) for n in names for s in (forms or {}).get(n) or _laws(EFFECTS[n])[0]]

    def to_effects(z):
        out: dict = {n: dict(p) for n, p in (fixed or {}).items()}
        for (n, p, lo, hi, log), v in zip(spec, z):
            out.setdefault(n, {})[p] = float(10 ** v if log else v)
        return out

    def cost(z):
        if cost_of is not None:
            return cost_of(to_effects(z))
        return fit_cost(values, to_effects(z), fit_recs)

    bounds = [(math.log10(lo), math.log10(hi)) if log else (lo, hi) for _, _, lo, hi, log in spec]
    if start is not None:
        z0 = [min(max(math.log10(start[n][p]) if log else start[n][p], b[0]), b[1])
              for (n, p, lo, hi, log), b in zip(spec, bounds)]
        res = minimize(cost, z0, method="Nelder-Mead", bounds=bounds,
                       options={"maxfev": max_evaluations, "xatol": 1e-3, "fatol": 1e-9})
        return to_effects(res.x), float(res.fun)
    points = SCREEN_POINTS if len(spec) == 1 else SCREEN_POINTS - 1
    if screened is None:
        levels = [lo + (np.arange(points) + 0.5) / points * (hi - lo) for lo, hi in bounds]
        fun, z0 = min([(cost(z), list(z)) for z in itertools.product(*levels)], key=lambda c: c[0])
    else:
        fun = float(screened[1])
        z0 = [math.log10(screened[0][n][p]) if log else screened[0][n][p] for n, p, lo, hi, log in spec]
    if screen_only or (baseline_cost is not None and fun > (1.0 - SCREEN) * baseline_cost):
        return to_effects(z0), float(fun)
    if len(spec) == 1:
        lo, hi = bounds[0]
        step = (hi - lo) / points
        res = minimize_scalar(lambda v: cost([v]), bounds=(max(lo, z0[0] - step), min(hi, z0[0] + step)),
                              method="bounded", options={"xatol": 0.03 * (hi - lo)})
        return (to_effects([res.x]), float(res.fun)) if res.fun < fun else (to_effects(z0), float(fun))
    res = minimize(cost, z0, method="Nelder-Mead", bounds=bounds,
                   options={"maxfev": 30, "xatol": 1e-3, "fatol": 1e-9})
    return (to_effects(res.x), float(res.fun)) if res.fun < fun else (to_effects(z0), float(fun))


@dataclass
class Attribution:
    baseline_holdout: dict
    noise: dict
    gap: bool
    candidates: list
    verdict: list
    threshold: float = 0.0    #: the summed NRMSE beyond which a gap no effect explains is "unexplained"
    spread: dict = field(default_factory=dict)   #: the baseline's own uncertainty, per channel
    beyond_noise: float = 0.0  #: the summed NRMSE beyond which candidates are fitted (noise alone)
    told: bool = False         #: the verdict was told by the load's own fit (:func:`_friction_told`), not the gap
    refused: list = field(default_factory=list)   #: names of the candidates the load's own fit does not tell (:func:`_load_confirms`), listed last and not weighed
    probabilities: dict = field(default_factory=dict)   #: {set: probability} (:mod:`.evidence`), the verdict's first
    effective_samples: dict = field(default_factory=dict)   #: the holdout's independent samples per channel
    fit_samples: float = 0.0   #: and the fit recordings', all channels
    fit_error: float = math.nan   #: the baseline's fit cost (:func:`fit_cost`; nan: not fitted, no gap)


def _fit_and_score(args):
    name, values, fit_recs, hold_recs, fixed, base_cost = args
    effect = EFFECTS[name]
    if effect.stage not in STAGES:
        raise ValueError(f"effect {name!r} acts in the stage {effect.stage!r}, which the model does not have "
                         f"({', '.join(STAGES)}): it cannot be fitted")
    if not fixed:      # alone: the entry's own faster fit, or a friction effect's with its load
        hook = fit_hook(effect)
        if hook is not None:
            return (*hook(effect, fit_recs, hold_recs), [])
        if effect.stage == "friction":
            return (*_fit_friction(name, fit_recs, hold_recs), [])

    def hold(effects):
        after = mean_errors(values, effects, hold_recs)
        return sum(after.values()), after
    fx, cost, after, told = fit_laws(
        name, _laws(effect), lambda **kw: fit_effects([name], values, fit_recs, **kw), hold, base_cost, fixed,
        told_costs=(lambda e: fit_cost(values, e, fit_recs),
                    lambda e: sum(mean_errors(values, e, hold_recs, FIT_RTOL).values())))
    return name, fx, cost, after, None, told


def fit_laws(name: str, forms: list, fit, hold, base_cost: float, fixed: dict | None = None,
             refine_each: bool = False, *, told_costs):
    """Effect ``name`` fitted over its laws ``forms`` (``_laws``: [[(parameter, lower,
    upper, log)]]) and scored on the holdouts: the boom's whole model and a joint's cut
    of the excavator alike.  ``fit(**options) -> (effects, cost)`` is
    :func:`fit_effects` on the fit recordings (or their cuts, with its ``cost_of``);
    ``hold(effects) -> (total, errors)`` the holdouts' summed error and its breakdown;
    ``base_cost`` the fit error without the effect; ``fixed`` further effects held on;
    ``told_costs``: ``(fit_of, hold_of)`` for :func:`told_by_holdout`.  Returns
    ``(effects, cost, errors, told)`` (``told``: the parameters the holdout told).

    Every law that holds no other's parameters is screened, and the one that screens
    best refined (``refine_each``: each refined, the best kept: a cut's leak has an
    orifice law whose narrow valley the screen's few points step over); then a law that
    holds its parameters and more (a leak both laminar and turbulent, a cushion with
    its port's volume, a spool's lag with a speed limit) is grown from that fit: its
    further parameters screened beside it, or the wider law screened afresh where that
    fits better (the narrower law's fit bends to mimic the wider one's shape: a slower
    lag for a speed limit), then all refined together, kept where it fits better and
    the holdout bears it out (a speed limit the fit recordings never reach is fitted to
    whatever else they miss); a further parameter the fit recordings cannot tell is
    told by the holdout where that lowers the holdout's error by ``GROW``."""
    simple = simple_laws(forms)
    if refine_each:
        fits = [(*fit(fixed=fixed, forms={name: form}, baseline_cost=base_cost), form) for form in simple]
        fx, cost, form = min(fits, key=lambda f: f[1])
    else:
        screens = [(*fit(fixed=fixed, forms={name: form}, screen_only=True), form) for form in simple]
        fx, cost, form = min(screens, key=lambda f: f[1])
        fx, cost = fit(fixed=fixed, forms={name: form}, baseline_cost=base_cost, screened=(fx, cost))
    fx_narrow, cost_narrow = fx, cost
    untold: list = []
    shows = cost <= (1.0 - GROW) * base_cost      # (an effect that barely shows cannot tell its law's shape)
    for wider, more in wider_laws(forms, form):
        held, cost_h = fit(fixed={**(fixed or {}), name: fx_narrow[name]}, forms={name: more}, screen_only=True)
        # where the narrower law shows nothing, the wider law is grown only where its further
        # parameters alone show something (a cushion without a check valve slows the return,
        # which the needle's law never touches)
        if not (shows or cost_h <= (1.0 - GROW) * base_cost):
            continue
        if shows and not fixed and cost_h > (1.0 - SCREEN) * cost_narrow:
            untold.append(more)     # its further parameter screened beside the fit tells nothing there
        fresh, cost_f = (fit(fixed=fixed, forms={name: wider}, screen_only=True)
                         if (SCREEN_POINTS - 1) ** len(wider) <= FRESH_SCREEN else (None, math.inf))
        fx_w, cost_w = fit(start=fresh if cost_f < cost_h else held, fixed=fixed, forms={name: wider},
                           max_evaluations=GROW_EVALUATIONS)
        if cost_w < cost:
            fx, cost = fx_w, cost_w
    total, after = hold(fx)
    if cost < cost_narrow:      # a wider law is kept only where the holdout bears out its further
        total_n, after_n = hold(fx_narrow)      # parameters (not told by the fit recordings, they
        if total_n < total:                     # bend to a misfit)
            fx, cost, after, total = fx_narrow, cost_narrow, after_n, total_n
    told: list = []
    for more in untold:
        found = told_by_holdout(name, fx_narrow, cost_narrow, more, *told_costs)
        if found is None:
            continue
        total_t, after_t = hold(found[0])
        if total_t < (1.0 - GROW) * total:
            fx, cost, after, total, told = found[0], found[1], after_t, total_t, [more[0][0]]
    return fx, cost, after, told


def told_by_holdout(name: str, fx_narrow: dict, cost_narrow: float, more: list, fit_of, hold_of):
    """A wider law's further parameter that the fit recordings cannot tell, told by the
    holdout: ``(effects, fit cost)``, or None.

    A speed limit that slow ramps never reach leaves the fit recordings' error the same
    at every value (calibration case 64: a spool's lag and a slew-rate limit, fitted on
    slow ramps, the limit shown by the holdout's steps).  An explanation's evidence is
    ``p(fit) p(holdout | fit)`` (:mod:`.evidence`); where the fit recordings leave a
    parameter open, the holdout's predictive is over every value they allow, not at one
    they chose blindly.  So the further parameter (``more``: [(parameter, lower, upper,
    log)], one) is screened over its range beside the narrower law's fit
    (``fx_narrow``, its cost ``cost_narrow``); the values whose fit error
    (``fit_of(effects)``) stays within ``SCREEN`` of the narrower law's are allowed (the
    fit recordings cannot tell them apart); the one of them that predicts the holdout
    best (``hold_of(effects)``: its summed NRMSE) is refined by a bounded search, and
    kept where the fit recordings still allow it.  The parameter is then told by the
    holdout, not by the fit recordings: the candidate says so (``Candidate.holdout_told``),
    its holdout shrink is not a held-out figure for that parameter, and the evidence
    charges it as a fitted parameter (BIC)."""
    if len(more) != 1:
        return None
    p, lo, hi, log = more[0]
    a, b = (math.log10(lo), math.log10(hi)) if log else (lo, hi)

    def effects_at(z):
        return {name: {**fx_narrow[name], p: float(10 ** z if log else z)}}
    allowed_cost = (1.0 + SCREEN) * cost_narrow
    grid = [a + (k + 0.5) / SCREEN_POINTS * (b - a) for k in range(SCREEN_POINTS)]
    costs = {z: fit_of(effects_at(z)) for z in grid}
    held = {z: hold_of(effects_at(z)) for z, cost in costs.items() if cost <= allowed_cost}
    if not held:
        return None
    z0 = min(held, key=held.get)
    step = (b - a) / SCREEN_POINTS
    res = minimize_scalar(lambda z: hold_of(effects_at(z)), bounds=(max(a, z0 - step), min(b, z0 + step)),
                          method="bounded", options={"xatol": 0.01 * (b - a)})
    if res.fun < held[z0]:
        cost = fit_of(effects_at(res.x))
        if cost <= allowed_cost:
            return effects_at(res.x), cost
    return effects_at(z0), costs[z0]     # (its fit error from the screen: allowed)


def _laws(effect) -> list:
    """The effect's laws as :func:`fit_effects` takes them: [[(parameter, lower, upper, log)]]."""
    return [[(p.name, p.lower, p.upper, p.log) for p in form] for form in effect.forms]


def _fit_friction(name, fit_recs, hold_recs):
    """A friction effect fitted jointly with the baseline it changes: a baseline
    identified without the effect would have absorbed part of it (F_s, F_d, M, K_v) and
    hidden the rest.  By the entry's own faster fit where it has one (``Effect.fit``:
    :func:`fit_stribeck`, :func:`fit_seal_laws`), else by the generic one
    (:func:`fit_with_load`).  Returns ``(name, fx, cost, holdout errors, load)``."""
    effect = EFFECTS[name]
    if effect.stage != "friction":
        raise ValueError(f"effect {name!r} acts in the {effect.stage!r} stage, not the friction stage: "
                         f"its fit does not re-identify the load")
    return (fit_hook(effect) or fit_with_load)(effect, fit_recs, hold_recs)


def _prepared(fit_recs):
    rig = rig_model(fit_recs[0])
    return rig, [prepare(r, geometry=rig.geometry, P_atm=rig.P_atm) for r in fit_recs]


def fit_with_load(effect, fit_recs, hold_recs):
    """The generic fit of a friction-stage effect (an entry without a faster one): for
    each value of its parameters the baseline load is re-identified with the effect's
    form in the load (``identify.fit.load_with_effect``: the equation error by
    nonlinear least squares, from the effect-free fit), and the parameters are fitted
    by output error of the model with that load (:func:`fit_effects`: screened, then
    refined), each law of the entry, the one that fits the fit recordings best kept."""
    name = effect.name
    rig, preps = _prepared(fit_recs)
    plain = identify(preps, rig.cylinder, rig.P_atm, valve=rig.valve, gas=rig.gas).values()
    plain = {k: v for k, v in plain.items() if math.isfinite(v)}
    motions = [motion(p, rig.cylinder, rig.P_atm) for p in preps]
    context = Boom(rig, check=False)       # the stage's context (catalogue.StageContext)
    loads: dict = {}

    def load_for(fx):        # the baseline re-identified with the effect at fx
        q = dict(fx[name])
        key = tuple(sorted(q.items()))
        if key not in loads:
            joint = load_with_effect(
                motions, plain, lambda ld, v, p_a, p_b: effect.apply(ld, v, p_a, p_b, q, context))
            if all(math.isfinite(joint[k]) and joint[k] > 0.0 for k in ("M", "K_v", "F_d")):
                # F_s from the starts anew, on the load found with the effect: the plain
                # fit's excess over F_d holds what the effect took from the sliding friction
                F_s, _, _ = static_friction(motions, joint, rig.cylinder, rig.P_atm)
                if F_s is not None:
                    joint["F_s"] = max(F_s.value, joint["F_d"])
            loads[key] = joint
        return loads[key]
    def cost_of(fx):         # the fit error with the effect at fx and its load (inf: no physical load)
        joint = load_for(fx)
        if not (all(math.isfinite(joint[k]) and joint[k] > 0.0 for k in ("M", "K_v", "F_d"))
                and math.isfinite(joint["F_L"])):
            return math.inf
        return fit_cost(joint, fx, fit_recs)
    base_cost = fit_cost(plain, {}, fit_recs)
    fx, cost = min((fit_effects([name], plain, fit_recs, forms={name: form}, baseline_cost=base_cost,
                                cost_of=cost_of) for form in _laws(effect)), key=lambda f: f[1])
    joint = load_for(fx)
    if not math.isfinite(cost):         # no value of the effect leaves a physical load: the plain one
        joint = plain
    return name, fx, cost, mean_errors(joint, fx, hold_recs), joint


def fit_stribeck(effect, fit_recs, hold_recs):
    """stribeck_friction's faster fit (its ``Effect.fit``; ``load_law`` "stribeck"): for
    each Stribeck velocity (a log grid, then refined) the load is identified anew
    (``identify.fit.identify``'s ``v_s``), and the value whose identification fits the
    recorded velocities best is kept, with its load."""
    name = effect.name
    rig, preps = _prepared(fit_recs)
    (param, lo, hi, log), = _laws(effect)[0]
    def fitted(v_s):         # (how far the velocity fit misses, the load) at v_s
        res = identify(preps, rig.cylinder, rig.P_atm, valve=rig.valve, gas=rig.gas, v_s=v_s)
        return res.details.get("velocity_error", {}).get("rms_velocity_m_s", math.inf), res.values()
    seen = {}

    def misfit(z):
        v_s = float(10 ** z)
        if v_s not in seen:
            seen[v_s] = fitted(v_s)
        return seen[v_s][0]
    rms0 = fitted(0.0)[0]
    zs = np.linspace(math.log10(lo), math.log10(hi), 6)
    costs = [misfit(z) for z in zs]
    i = int(np.argmin(costs))
    if costs[i] < (1.0 - SCREEN) * rms0:       # the curve explains something: refine
        minimize_scalar(misfit, bounds=(zs[max(i - 1, 0)], zs[min(i + 1, len(zs) - 1)]), method="bounded",
                        options={"xatol": 0.05})
    v_s = min(seen, key=lambda k: seen[k][0])
    joint = {k: v for k, v in seen[v_s][1].items() if math.isfinite(v)}
    fx = {name: {param: v_s}}
    cost = fit_cost(joint, fx, fit_recs)
    return name, fx, cost, mean_errors(joint, fx, hold_recs), joint


def _seal_laws(effect, rig, preps):
    """The load identified with ``effect`` (``load_law`` "seal_pressure") by each of its
    laws: per law ``(result, fx, joint)``: identify's :class:`FitResult`, the effect's
    parameters (the coefficient within its bounds) and the load without it."""
    if effect.load_law != "seal_pressure":
        raise ValueError(f"effect {effect.name!r} has no seal-pressure load law (its load_law: {effect.load_law!r})")
    out = []
    for (q,) in effect.forms:
        law = next((k for k, v in PRESSURE_COEFFICIENT.items() if v == q.name), None)
        if law is None:
            raise ValueError(f"effects.{effect.name}.{q.name}: not a seal-pressure law's coefficient "
                             f"({', '.join(PRESSURE_COEFFICIENT.values())})")
        res = identify(preps, rig.cylinder, rig.P_atm, valve=rig.valve, gas=rig.gas, pressure=law)
        found = res.values()
        joint = {k: v for k, v in found.items() if k not in PRESSURE_COEFFICIENT.values() and math.isfinite(v)}
        out.append((res, {effect.name: {q.name: float(min(max(found[q.name], q.lower), q.upper))}}, joint))
    return out


def fit_seal_laws(effect, fit_recs, hold_recs):
    """pressure_friction's faster fit (its ``Effect.fit``; ``load_law`` "seal_pressure"):
    its coefficient is one more linear term of Eq. 8, identified with the load for each
    seal-pressure law; the law whose model fits the fit recordings best is kept."""
    rig, preps = _prepared(fit_recs)
    fits = [(fit_cost(joint, fx, fit_recs), fx, joint)
            for _, fx, joint in _seal_laws(effect, rig, preps)]
    cost, fx, joint = min(fits, key=lambda f: f[0])
    return effect.name, fx, cost, mean_errors(joint, fx, hold_recs), joint


def _friction_told(fit_recs, hold_recs, before: dict, beyond_noise: float = 0.0, told: list | None = None):
    """A seal-pressure effect (``load_law`` "seal_pressure": pressure_friction) where the
    outputs cannot show it: the baseline's F_d takes the
    seals' friction at the recordings' mean pressure, and what is left may sit within
    the output noise.  The load's own fit still tells it: the friction moves with the
    pressure sample by sample.  Named (a :class:`Candidate`, score 1) only where

    * the velocity fit of the load with the coefficient (``identify.fit``, the best of
      the seal-pressure laws) misses the recorded velocities by ``FRICTION_GAIN`` less
      than without it (over every sliding run: neither noise nor an effect on the
      pneumatics, which the load's fit reads through the recorded pressures, moves it;
      on the 120 cases of ``diagnosis_blind.py --suite calibration`` each case without a
      seal-pressure friction stays within 0.8 % of its plain misfit, each with one
      lowers it 3 % or more, or not at all where it is too weak to show or its law
      saturates: a constant factor on the friction, which F_d takes whole); and
    * the model with it does not predict the holdout worse than the baseline (shrink
      > 0), which was never fitted on, or leaves it within the noise (its summed NRMSE
      within ``beyond_noise``): a holdout whose gap lies within its noise cannot refute
      what keeps it there, and a shrink of a gap within the noise is the noise's sign.

    The coefficient's interval is not asked to keep clear of a share of its value: its
    bootstrap runs over the sliding runs on a log scale, which never reaches zero, so
    that share only asked for a precision that five runs do not give (calibration case
    101, a seal friction 1.7 times the Coulomb level at 6 bar: velocity misfit 14 %
    lower, interval from 0.1 of the value).  None otherwise (the verdict stays as it
    was).  ``told``: :func:`seal_told`'s list where the caller has it."""
    told = seal_told(fit_recs) if told is None else told
    if not told:
        return None
    _, name, fx, joint = min(told, key=lambda t: t[0])
    after = mean_errors(joint, fx, hold_recs)
    gain = shrink(before, after)
    if not (gain > 0.0 or sum(after.values()) <= beyond_noise):
        return None
    cost = fit_cost(joint, fx, fit_recs)
    return Candidate(name, fx[name], cost, after, gain, score=1.0, values=joint)


def sealing() -> set:
    """The catalogue's effects whose law is the seals' pressure in the load
    (``load_law`` "seal_pressure": pressure_friction)."""
    return {e.name for e in EFFECTS.values() if e.load_law == "seal_pressure"}


def seal_told(fit_recs) -> list:
    """The seal-pressure laws the load's own velocity fit tells on ``fit_recs``: those
    whose fit (the load identified with the law's coefficient, ``identify.fit``) misses
    the recorded velocities by ``FRICTION_GAIN`` less than the plain load's, over every
    sliding run, with a positive coefficient; as ``(rms velocity misfit [m/s], effect,
    its parameters, the load)``."""
    if not sealing():
        return []
    rig, preps = _prepared(fit_recs)
    plain = identify(preps, rig.cylinder, rig.P_atm, valve=rig.valve, gas=rig.gas)
    rms0 = plain.details.get("velocity_error", {}).get("rms_velocity_m_s", math.nan)
    if not math.isfinite(rms0):
        return []
    told = []
    for name in sorted(sealing()):
        effect = EFFECTS[name]
        for res, fx, joint in _seal_laws(effect, rig, preps):
            rms = res.details.get("velocity_error", {}).get("rms_velocity_m_s", math.inf)
            (q,) = fx[effect.name]
            if rms <= (1.0 - FRICTION_GAIN) * rms0 and res.params[q].value > 0.0:
                told.append((rms, effect.name, fx, joint))
    return told


def _fit_or_seals(job):
    """A candidate's fit (:func:`_fit_and_score`), or, for ``(None, fit_recs)``, the
    seal-pressure laws the load's own fit tells (:func:`seal_told`)."""
    return seal_told(job[1]) if job[0] is None else _fit_and_score(job)


def _load_confirms(cands, fit_recs, told: list | None = None) -> tuple[list, list, list | None]:
    """Split ``cands`` into those the load's own fit allows and those it does not tell:
    a candidate holding a seal-pressure effect (its law lives in the load's
    equation, Eq. 8 and 9, which the load's fit reads with the recorded pressures) that
    the load's velocity fit does not tell (:func:`seal_told`).  Its outputs' gain is
    then the re-identified load's (F_s, F_d moved with the coefficient) absorbing
    something else: on calibration case 49 an engine's vibration, which such a
    candidate took for the seals' friction (holdout shrink 0.37, probability 1.00;
    velocity misfit 0.2 % lower).  On the 120 calibration cases every correct
    pressure_friction verdict had its misfit 4.6 % or more lower.  A seal law that
    saturates within the recordings' pressures (a constant factor on the friction, which
    F_d takes whole) lowers the misfit not at all: such a friction is refused too,
    though its outputs may show it at pressures the fit recordings do not reach (the
    calibration's case 117 is one; its verdict named the heat transfer beside it alone
    before and does now).  Returns ``(kept, refused, seal_told's list or None where no
    candidate needed it)``.  ``told``: :func:`seal_told`'s list, where it ran already."""
    seals = sealing()
    holding = [c for c in cands if seals & set(c.name.split("+"))]
    if not holding:
        return list(cands), [], None
    told = seal_told(fit_recs) if told is None else told
    names = {t[1] for t in told}
    refused = [c for c in holding if (seals & set(c.name.split("+"))) - names]
    gone = {id(c) for c in refused}
    return [c for c in cands if id(c) not in gone], refused, told


def _cost(job) -> int:
    """A fit's rough cost, for scheduling: steep in its parameters (a grid, then a
    simplex), times its laws."""
    names = job[0] if isinstance(job[0], list) else [job[0]]
    return sum(max(len(f) for f in EFFECTS[n].forms) ** 3 * len(EFFECTS[n].forms) for n in names)


def may_start_processes() -> bool:
    """Whether this process may start worker processes of its own (a process pool): not
    in a daemonic process (which may have none: a Dask nanny's worker), nor in a Dask
    worker's task of any kind.  A process forked by a Dask worker inherits its
    connections: the worker killed, the orphan keeps them open (and outlives it), so the
    scheduler does not see the worker go and its cases wait for the scheduler's
    ``worker-ttl`` (minutes) before they run again elsewhere.  There, the work runs in
    the worker's own thread, and a lost worker's cases are rescheduled at once."""
    if multiprocessing.current_process().daemon:
        return False
    if "distributed" not in sys.modules:     # no Dask in this process: no Dask worker either
        return True
    from distributed import get_worker
    try:
        get_worker()
    except ValueError:                       # "No worker found": not in a worker's task
        return True
    return False


def _map(fn, jobs, workers, cost=None):
    """``fn`` over ``jobs`` in ``workers`` processes, the costliest by ``cost(job)``
    (default: a candidate fit's, :func:`_cost`) started first (so that the
    two-parameter fit does not start last); results in the jobs' order.  One after
    the other in this process where it may start none (:func:`may_start_processes`)."""
    if workers > 1 and len(jobs) > 1 and may_start_processes():
        order = sorted(range(len(jobs)), key=lambda i: -(cost or _cost)(jobs[i]))
        with ProcessPoolExecutor(min(workers, len(jobs))) as pool:
            done = dict(zip(order, pool.map(fn, [jobs[i] for i in order])))
        return [done[i] for i in range(len(jobs))]
    return [fn(j) for j in jobs]


def baseline_spread(values: dict, intervals: dict, recs, base, workers: int = 1) -> dict:
    """How far the baseline's own uncertainty moves its prediction of ``recs``: per
    channel, the NRMSE between the model at ``values`` (its runs ``base``, one per
    recording) and at each identified parameter moved to the nearer end of its 95 %
    interval (``intervals``: name -> (lo, hi)), combined in quadrature.  A gap smaller
    than this is not beyond what the identification already leaves open."""
    names = [k for k, (lo, hi) in intervals.items()
             if k in values and math.isfinite(lo) and math.isfinite(hi) and hi > lo]
    if not names:
        return {c: 0.0 for c in CHANNELS}
    base = [{c: b[c].to_numpy() for c in CHANNELS} for b in base]
    jobs = [(values, k, intervals[k], recs, base) for k in names]
    moved = _map(_moved_error, jobs, workers, cost=lambda job: 1)
    return {c: float(math.sqrt(sum(m[c] ** 2 for m in moved))) for c in CHANNELS}


def _moved_error(job) -> dict:
    values, name, (lo, hi), recs, base = job
    v = values[name]
    step = min(abs(v - lo), abs(hi - v))
    other = dict(values, **{name: v + step if abs(hi - v) <= abs(v - lo) else v - step})
    if name == "F_s":
        other[name] = max(other[name], values.get("F_d", 0.0))
    per = [nrmse(simulate_recording(other, r, rtol=RTOL), r, against=b) for r, b in zip(recs, base)]
    return {c: float(np.mean([e[c] for e in per])) for c in CHANNELS}


def attribute(values: dict, fit_recs, hold_recs, names=None, workers: int | None = None,
              intervals: dict | None = None) -> Attribution:
    """Fit, score and rank the candidates (``workers`` processes at once; default: one
    per core); decide the verdict.  ``intervals``: the baseline's 95 % intervals
    (name -> (lo, hi)), whose effect on the holdout raises the gap's threshold."""
    names = list(CANDIDATES) if names is None else names
    workers = workers or os.cpu_count() or 1
    base = [_baseline(values, r, RTOL) for r in hold_recs]     # the baseline's runs, once
    before = {c: float(np.mean([nrmse(b, r)[c] for b, r in zip(base, hold_recs)])) for c in CHANNELS}
    floors = [noise_floor(r) for r in hold_recs]
    noise = {c: float(np.mean([f[c] for f in floors])) for c in CHANNELS}
    spread = baseline_spread(values, intervals or {}, hold_recs, base, workers)
    beyond_noise = NOISE_FACTOR * sum(noise.values()) + ABS_FLOOR
    threshold = beyond_noise + sum(spread.values())
    gap = sum(before.values()) > beyond_noise
    if not gap:        # nothing beyond the noise: no output fit can show more
        told = _friction_told(fit_recs, hold_recs, before, beyond_noise)
        att = Attribution(before, noise, gap, [told] if told else [], [told.name] if told else [])
        att.threshold, att.spread, att.beyond_noise, att.told = threshold, spread, beyond_noise, told is not None
        att.probabilities, att.effective_samples, att.fit_samples = _weigh(att.candidates, before, None, noise,
                                                                           spread, base, fit_recs, hold_recs)
        for c in att.candidates:
            c.score = round(att.probabilities.get(set_name(c), 0.0), 4)
        return att
    base_cost = fit_cost(values, {}, fit_recs)
    jobs = [(n, values, fit_recs, hold_recs, None, base_cost) for n in names]
    # the load fits that tell a seal-pressure law (:func:`seal_told`) need no candidate's
    # fit: run beside them, last (a pool's tail, where one process would wait)
    seals = bool(sealing() & set(names))
    done = _map(_fit_or_seals, jobs + ([(None, fit_recs)] if seals else []), workers,
                cost=lambda job: -1 if job[0] is None else _cost(job))
    fitted, seals_told = (done[:-1], done[-1]) if seals else (done, None)
    cands = [Candidate(n, fx[n], cost, after, shrink(before, after), values=joint,
                       holdout_told=told)
             for n, fx, cost, after, joint, told in fitted]
    # a seal-pressure effect the load's own fit does not tell is not weighed (nor paired)
    cands, refused, told_by_load = _load_confirms(cands, fit_recs, seals_told)
    cands.sort(key=lambda c: -c.shrink)
    pairs: list = []
    singles = _weigh(cands, before, base_cost, noise, spread, base, fit_recs, hold_recs)[0] if cands else {}
    if pairs_needed(cands, singles, beyond_noise):
        pairs = _pairs(cands, values, fit_recs, hold_recs, before, workers, base_cost)
    probs, counts, n_fit = _weigh(cands + pairs, before, base_cost, noise, spread, base, fit_recs, hold_recs)
    cands = sorted(cands + pairs, key=lambda c: (-probs.get(set_name(c), 0.0), -c.shrink))
    for c in cands:
        c.score = round(probs.get(set_name(c), 0.0), 4)
    top = next(iter(probs))
    told = None
    if top == UNEXPLAINED:
        verdict = ["unexplained"]
    elif top != NONE:
        verdict = top.split(" + ")
        cands.sort(key=lambda c: set_name(c) != top)      # the verdict's candidate first (the report's)
    else:            # the baseline stands, unless the load's own fit tells pressure_friction
        verdict = []
        told = _friction_told(fit_recs, hold_recs, before, beyond_noise, told_by_load)
        if told is not None:       # weighed in place of its output fit (the verdict is the load fit's)
            verdict = [told.name]
            cands = [told] + [c for c in cands if c.name != told.name]
            probs, counts, n_fit = _weigh(cands, before, base_cost, noise, spread, base, fit_recs, hold_recs)
            for c in cands:
                c.score = round(probs.get(set_name(c), 0.0), 4)
    for c in refused:      # listed last, unweighed: the load's fit does not tell them
        c.score = 0.0
    att = Attribution(before, noise, gap, cands + refused, verdict)
    att.refused = [c.name for c in refused]
    att.threshold, att.spread, att.beyond_noise = threshold, spread, beyond_noise
    att.told, att.probabilities, att.effective_samples = told is not None, probs, counts
    att.fit_samples, att.fit_error = n_fit, base_cost
    return att


def pairs_needed(cands: list, singles: Mapping, beyond_noise: float) -> bool:
    """Whether pairs are fitted: where no single effect explains the gap (``MIN_SHRINK``
    of it) or the best leaves more than the noise (``beyond_noise``: the baseline's
    spread no longer counts, the best's fit has moved the model off the baseline
    already), a pair cannot show more than the noise otherwise.  The best is the one
    that shrinks the holdout's gap most (``cands`` sorted so), and the most probable
    single set too (``singles``: the singles weighed, :func:`_weigh`), where that is
    another or "unexplained": the effect the fit recordings prefer may leave the
    holdout's gap to something outside the catalogue where a pair with it explains it
    (calibration case 103: a deadband, preferred nine to one on the fit recording,
    beside a fast spool; a sensor lag shrank the holdout most, to within the noise, and
    no pair was fitted)."""
    if not cands:
        return False

    def short(c: Candidate) -> bool:
        return c.shrink < MIN_SHRINK or sum(c.holdout.values()) > beyond_noise
    if short(cands[0]):
        return True
    top = next(iter(singles), NONE)
    if top == UNEXPLAINED:
        return True
    lead = next((c for c in cands if set_name(c) == top), None)
    return lead is not None and short(lead)


def set_name(c: Candidate) -> str:
    """A candidate's set as the probabilities name it: its effects joined by " + "."""
    return " + ".join(c.name.split("+"))


def _parameters(c: Candidate) -> int:
    """The parameters a candidate fitted (a pair's params are {effect: {param: value}})."""
    return sum(len(v) if isinstance(v, dict) else 1 for v in c.params.values())


def _weigh(cands, before, base_cost, noise, spread, base, fit_recs, hold_recs) -> tuple[dict, dict, float]:
    """The probability of each candidate set, ``none`` and ``unexplained``
    (:mod:`.evidence`), on the holdout's effective sample count per channel from the
    baseline's residual there (``base``: its runs) and the fit recordings' at the same
    rate per second; and those counts."""
    counts, seconds = residual_counts(base, hold_recs)
    fit_seconds = sum(float(r.data["t"].iloc[-1] - r.data["t"].iloc[0]) for r in fit_recs)
    n_fit = sum(counts.values()) * fit_seconds / max(seconds, 1e-9)
    hyps = [Hypothesis(NONE, 0, before, base_cost, 0)]
    hyps += [Hypothesis(set_name(c), _parameters(c), c.holdout, c.fit_error, len(c.name.split("+")))
             for c in cands]
    return probabilities(hyps, noise, counts, n_fit, spread), counts, n_fit


#: the joint fits of pairs at most (as many as the former pool of five candidates
#: allowed), the most promising first (:func:`pair_combos`)
PAIR_JOBS = 10
#: the most promising of them fitted jointly whatever their starts show, the weaker
#: effect screened in each of its laws beside the stronger (:func:`fit_pair_jointly`'s
#: ``always``): the two strongest singles' pairings, where a weak second effect hides
#: behind a strong one's fit (a heat exchange beside a valve's deadband, whose widths
#: had taken part of it; beside a sensor's lag, in the wall's law where alone it took
#: the polytropic one)
PAIR_ALWAYS = 2


def pair_combos(cands, base_cost: float, jobs: int = PAIR_JOBS) -> list:
    """The pairs to fit jointly: among every candidate that lowers the fit recordings'
    error below the baseline's (``base_cost``) at all, whatever it does alone to the
    holdout (two effects may each explain little alone, or one make the holdout worse
    with the other's misfit around it), the ``jobs`` pairs whose singles together lower
    the fit error most (the sum of their reductions) first: the budget that caps the
    cost, each joint fit itself capped at ``PAIR_EVALUATIONS`` evaluations."""
    lowered = [c for c in cands if c.fit_error < base_cost and "+" not in c.name]
    combos = list(itertools.combinations(lowered, 2))
    combos.sort(key=lambda ab: ab[0].fit_error + ab[1].fit_error)
    return combos[:jobs]


def _pairs(cands, values, fit_recs, hold_recs, before, workers, base_cost: float) -> list:
    """The pairs of :func:`pair_combos`, each fitted jointly (:func:`_fit_pair`, from the
    singles' fits), as candidates; a pair that does not lower the fit error below its
    better single's by SCREEN from any start is left out (its evidence could only be its
    better single's, less the penalty of a further effect), but for the first
    ``PAIR_ALWAYS``, fitted whatever their starts show."""
    combos = pair_combos(cands, base_cost)
    # a pair with a friction effect keeps the load identified with it
    jobs = [([a.name, b.name], a.values or b.values or values, fit_recs, hold_recs,
             {a.name: a.params, b.name: b.params}, {a.name: a.fit_error, b.name: b.fit_error}, k < PAIR_ALWAYS)
            for k, (a, b) in enumerate(combos)]
    out = []
    for job, fitted in zip(jobs, _map(_fit_pair, jobs, workers) if jobs else []):
        if fitted is None:
            continue
        pair_names, fx, cost, after = fitted
        joint = job[1] if job[1] is not values else None
        out.append(Candidate("+".join(pair_names), fx, cost, after, shrink(before, after), values=joint))
    return out


def _pays(single: dict, pair: dict, noise: float) -> bool:
    """Whether a pair (its holdout NRMSE per channel) removes MIN_SHRINK_SECOND of what
    its single effect's fit ``single`` leaves beyond the noise (``noise``: summed)."""
    left, after = sum(single.values()), sum(pair.values())
    return left > noise and left - after >= MIN_SHRINK_SECOND * (left - noise) and after < left


def _halved(effect: str, parameter: str, value: float) -> float:
    """The parameter at half its value where a smaller value is a weaker effect (a
    switching parameter, whose 0 is off: a time constant, a width, a conductance, a
    length, without a least value that is on: a polytropic exponent's 'off' is its
    top), within its bounds; else as it is."""
    q = next(p for p in EFFECTS[effect].parameters if p.name == parameter)
    return max(0.5 * value, q.lower) if q.switch and q.on_min is None else value


def _names(law: list) -> set:
    """The parameters' names of a law ([(parameter, lower, upper, log)])."""
    return {q[0] for q in law}


def simple_laws(forms: list) -> list:
    """The laws of ``forms`` ([[(parameter, lower, upper, log)]]) that hold no other's
    parameters (a leak laminar or turbulent, not both; a lag without its speed limit)."""
    return [f for f in forms if not any(_names(g) < _names(f) for g in forms)]


def wider_laws(forms: list, law: list) -> list:
    """The laws of ``forms`` that hold ``law``'s parameters and more, each as ``(wider
    law, its further parameters)`` (a leak both laminar and turbulent beside the laminar
    one; a lag with its speed limit)."""
    return [(f, [q for q in f if q[0] not in _names(law)]) for f in forms if _names(law) < _names(f)]


def law_of(laws: list, params) -> list:
    """The law of ``laws`` ([[(parameter, lower, upper, log)]]) that a fit holds the
    parameters ``params`` (names) of: each of them once, in the laws' order."""
    out: dict = {}
    for law in laws:
        for q in law:
            if q[0] in params:
                out.setdefault(q[0], q)
    return list(out.values())


def fit_pair_jointly(names, start: dict, single_costs: dict, forms: dict, weak_laws: dict, cost_of,
                     always: bool = False):
    """Two effects fitted jointly on the error ``cost_of(effects) -> float`` (the fit
    recordings', or a cut of them): ``(effects, cost)``, or None where no start lowers
    the error below the better single's (``single_costs``) by SCREEN and the pair is
    not one to fit ``always`` (the second effect adds nothing there, and a joint fit
    would only chase the noise).

    Up to three kinds of start, each tried only where the ones before do not lower the
    error by SCREEN, the best kept: both singles' fits (``start``, of the laws
    ``forms``: {name: [(parameter, lower, upper, log)]}); both halved (the parameters
    whose size is the effect's strength, :func:`_halved`); and the better single's fit
    held while the weaker is screened beside it in each of its ``weak_laws[name]``
    (forward selection: its own single's law, or each of its simple laws,
    :func:`simple_laws`).  The first fails where both singles absorbed
    the same feature (a spool lag and a sensor's dead time each take the whole delay:
    together they double it), which the second meets; the third, where the weaker is
    hidden behind the stronger's fit, and in a law of its own there (heat exchanged with
    the wall beside a sensor's lag, where alone a polytropic exponent took part of the
    lag's shape).  ``always``: fitted from the best start even where it lowers nothing
    (the singles' fits may each have absorbed part of the other effect, so that no start
    near them shows what the joint fit finds)."""
    single_cost = min(single_costs.values())
    strong = min(names, key=lambda n: single_costs[n])
    weak = next(n for n in names if n != strong)
    enough = (1.0 - SCREEN) * single_cost
    starts = [(cost_of(start), start, forms)]
    # both singles taking the same feature whole (a delay): each takes half of it
    halves = {n: {q: _halved(n, q, v) for q, v in start[n].items()} for n in names}
    if starts[0][0] > enough and halves != start:
        starts.append((cost_of(halves), halves, forms))
    if min(s[0] for s in starts) > enough:   # the weaker hidden behind the stronger: screened beside it
        for law in weak_laws[weak]:
            held, cost = fit_effects([weak], {}, None, fixed={strong: start[strong]}, forms={weak: law},
                                     screen_only=True, cost_of=cost_of)
            starts.append((cost, held, {strong: forms[strong], weak: law}))
    at_start, begin, laws = min(starts, key=lambda s: s[0])
    if at_start > enough and not always:
        return None
    fx, cost = fit_effects(list(names), {}, None, start=begin, max_evaluations=PAIR_EVALUATIONS, forms=laws,
                           cost_of=cost_of)
    if cost > at_start:
        fx, cost = begin, at_start
    return fx, cost


def _fit_pair(args):
    """A pair fitted jointly on the fit recordings (:func:`fit_pair_jointly`) and scored
    on the holdout; None where it is not fitted."""
    names, values, fit_recs, hold_recs, start, single_costs, always = args
    forms = {n: law_of(_laws(EFFECTS[n]), start[n]) for n in names}
    # the weaker screened in each of its laws for the pairs fitted always, in its own
    # single's law for the rest (their screen only decides whether to fit them)
    laws = {n: simple_laws(_laws(EFFECTS[n])) if always else [forms[n]] for n in names}
    fitted = fit_pair_jointly(names, start, single_costs, forms, laws, lambda fx: fit_cost(values, fx, fit_recs),
                              always)
    if fitted is None:
        return None
    fx, cost = fitted
    return names, fx, cost, mean_errors(values, fx, hold_recs)

__all__ = [
    "CANDIDATES", "FORMS", "FRESH_SCREEN", "MIN_SHRINK", "MIN_SHRINK_SECOND", "PAIR_POOL", "SCREEN_POINTS", "SCREEN",
    "PAIR_EVALUATIONS", "PAIR_ALWAYS", "GROW_EVALUATIONS", "GROW", "FRICTION_GAIN", "RTOL", "sealing", "seal_told",
    "FIT_RTOL", "errors", "mean_errors", "fit_cost", "Candidate", "fit_effects", "Attribution",
    "fit_with_load", "fit_stribeck", "fit_seal_laws", "may_start_processes", "baseline_spread",
    "attribute", "set_name", "told_by_holdout", "fit_laws", "PAIR_JOBS", "pair_combos", "simple_laws", "wider_laws", "law_of", "fit_pair_jointly",
]
