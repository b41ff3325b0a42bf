"""A joint judged apart from the linkage: the diagnosis of a machine of several joints
(the whole excavator), per joint: which joint, which effect, how far it shrinks.

``diagnose.report.diagnose`` runs it for a machine of more than one joint (the boom rig,
one joint, is judged whole by ``diagnose.attribute``: with one joint the whole model is
the cut) and writes its report.

**Two cuts per joint.**  Each joint is judged apart from the linkage, measured signals
in place of its neighbours':

* the **pneumatic cut**: the joint's valve and two chambers (the boom model's own
  ``model.Boom`` with that joint's valve and cylinder, stepped as
  ``localise.simulate_pneumatics`` steps the boom's) run on the joint's recorded
  command and its *measured* motion (the piston position from the measured angle).
  A pressure gap that remains is that joint's own, not carried over from a neighbour.
  Its gap is the NRMSE of the two pressures (each over its range, as its sensor reads
  it), summed;
* the **load cut** (``diagnose/joint_load.py``, where it is installed): the joint as
  an equivalent single cylinder, its measured pressures and the other joints' measured
  motion in, its own motion out; its gap is the position's NRMSE.

A cut is **flagged** on a holdout where its gap exceeds ``NOISE_FACTOR`` times that
recording's own noise floor plus ``ABS_FLOOR`` (``attribute``'s margins); the load
cut's threshold adds its model's own error (:func:`_model_error`: the least gap its load,
or a friction candidate, leaves on the fit recordings it is fitted on, less their noise),
so a gap within what the cut cannot reproduce where it is fitted is no finding, and a
friction candidate is named only on a gap beyond that; and any finding of the load cut
(a candidate named, or ``unexplained``) only on a gap beyond what the load's own
uncertainty from the fit recordings moves the cut and what the joint's load identified
on the holdout itself leaves (:func:`_own_load`: "cannot tell", said in the notes).

**Every effect on any joint.**  On a flagged cut each candidate of the catalogue
(``model/catalogue.py``) that acts there is fitted **on the fit recordings' cuts** of that
joint and scored **on the holdouts' cuts**, which are never fitted on:
``shrink = 1 - gap_after / gap_before`` (the holdouts' mean gaps).  The pneumatic cut
takes the effects of the stages ``spool`` (valve_dynamics: the spool's lag is a state of
the cut), ``command``, ``port``, ``seal``, ``heat`` (the cut carries the air masses) and
``measurement`` (sensor_lag: the cut's pressures as the sensors report them,
``model.measure``; and, since the angle sensor lags alike, the cut is driven by the
motion the measured angle lags behind, :func:`unlagged`; the lag is taken to be the data
acquisition's, on every joint's channels as the excavator bridge's ``tau_sensor``,
except on a joint whose own fit recordings refuse it, so what it makes worse on those
other joints' holdout cuts counts against it (:func:`_hold_gaps`): on one joint's
cut alone a sensor's lag and a slow spool are much the same delay of the pressures'
answer to the command); the load cut the ``friction``
stage's (stribeck_friction, pressure_friction, each law), with the joint's load
re-identified with the effect on (``joint_load.fit_load_effect``), then the load (the
baseline's as each candidate's) refined by the load cut's own output error on the fit
recordings (:func:`joint_load.refine_load`).  Every law of an
effect is fitted by the boom's own law fit (``attribute.fit_laws``, ``attribute.fit_effects``
on the cut's error): each law screened over the catalogue's bounds and refined (a
bounded scalar search, or Nelder-Mead for several parameters), the best kept; a law that
holds its parameters and more grown from its fit, kept where it fits better and the
holdouts bear it out; a further parameter the fit cuts cannot tell, told by the
holdouts (the candidate says so: ``Fitted.told``, ``holdout_told`` in the report).

**Pairs.**  On a cut where the best single effect removes less than ``MIN_SHRINK`` of
the gap or leaves more than the noise margin, pairs among its ``PAIR_POOL`` best singles
are fitted jointly (from the singles' fits, both halved, or the weaker screened beside
the stronger's fit), kept where they remove ``MIN_SHRINK`` and each member pays for
itself (``attribute._pays``).

**Verdict.**  Each joint's findings, the joint furthest beyond its threshold first:
``"<effect>@<joint>"`` per effect named, ``"unexplained@<joint>"`` for a flagged cut no
candidate explains; ``[]`` where no joint's cut is flagged.
"""
from __future__ import annotations

import itertools
import math
import os
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from ..compare import as_sensed
from ..identify.preprocess import lowpass
from ..model import EFFECTS, Boom, Model, measure
from ..model.boom import measurement_lag
from ..model.catalogue import capped
from ..physics import linkage as exc
from .attribute import (ABS_FLOOR, CANDIDATES, FORMS, MIN_SHRINK, MIN_SHRINK_SECOND, NOISE_FACTOR, PAIR_POOL,
                        _map, _pays, fit_effects, fit_laws, fit_pair_jointly, law_of)
from .localise import simulate_pneumatics

#: the catalogue's stages that act inside one joint's pneumatics (the pneumatic cut)
PNEUMATIC_STAGES = ("spool", "command", "port", "seal", "heat", "measurement")
#: and on its load (the load cut)
LOAD_STAGES = ("friction",)


def candidates(stages=PNEUMATIC_STAGES) -> list[str]:
    """The catalogue's effects that act in ``stages``, in the catalogue's order."""
    return [name for name, e in EFFECTS.items() if e.stage in stages]


def joint_forms(name: str, joint: str, ex: exc.Excavator = exc.Excavator()) -> list:
    """The laws of effect ``name`` as fitted on ``joint``: [[(parameter, lower, upper,
    log)]], the catalogue's bounds, a cushion's port volume kept below that joint's
    dead volumes (``physics.effects.check_cushion_port``)."""
    cyl = ex.actuators[exc.JOINTS.index(joint)].cylinder
    out = []
    for form in FORMS.get(name, [CANDIDATES[name]]):
        f = []
        for p, lo, hi, log in form:
            f.append((p, lo, capped(EFFECTS[name], p, cyl, hi), log))
        out.append(f)
    return out


def joint_cut(data, joint: str, ex: exc.Excavator = exc.Excavator(), P_atm: float | None = None):
    """One joint's measured signals as ``localise.simulate_pneumatics`` takes them: t,
    u, x (from the measured angle, clipped to the stroke) and the pressures [Pa,
    absolute]."""
    data = getattr(data, "data", data)
    P_atm = ex.P_atm if P_atm is None else P_atm
    i = exc.JOINTS.index(joint)
    q = np.column_stack([data[f"angle_{j}"].to_numpy(float) for j in exc.JOINTS])
    t = data["t"].to_numpy(float)
    fs = 1.0 / float(np.median(np.diff(t)))
    # the angle sensor's steps, smoothed (zero-phase, 20 Hz): a step of a short lever's
    # angle is a jump of the chamber's volume the cut would turn into a pressure spike
    x = np.clip(lowpass(exc.pistons_from_angles(q, ex)[:, i], fs, 20.0), 0.0, ex.strokes[i])
    return SimpleNamespace(t=t, u=data[f"u_{joint}"].to_numpy(float), x=x, x_raw=x,
                           p_a_raw=data[f"p_a_{joint}"].to_numpy(float) + P_atm,
                           p_b_raw=data[f"p_b_{joint}"].to_numpy(float) + P_atm,
                           fs=fs, L=float(ex.strokes[i]))


def joint_model(joint: str, ex: exc.Excavator = exc.Excavator(), effects: dict | None = None) -> Boom:
    """That joint's valve and cylinder as the boom model's pneumatics, with ``effects``."""
    a = ex.actuators[exc.JOINTS.index(joint)]
    return Boom(Model(valve=a.valve, cylinder=a.cylinder, P_atm=ex.P_atm, effects=dict(effects or {})),
                check=False)


#: the least span [Pa] a pressure's error is measured over: a chamber that barely moves
#: in the recording (a closed rod side) is judged against half a bar, not its noise
P_SPAN_MIN = 5e4


def _span(m) -> float:
    return max(float(np.ptp(m)), P_SPAN_MIN)


def _gap(cut, pa, pb) -> float:
    """NRMSE of the two pressures (each as its sensor would read it), summed; inf where
    the model's pressures are not finite (parameters no machine has)."""
    if not (np.all(np.isfinite(pa)) and np.all(np.isfinite(pb))):
        return math.inf
    return sum(float(np.sqrt(np.mean((m - as_sensed(m, s)) ** 2)) / _span(m))
               for m, s in ((cut.p_a_raw, pa), (cut.p_b_raw, pb)))


def joint_noise(cut) -> float:
    """The joint's pressures' noise floor, summed over the two (each over its range)."""
    return sum(float(np.std(m - lowpass(m, cut.fs, 50.0)) / _span(m)) for m in (cut.p_a_raw, cut.p_b_raw))


def threshold(noise: float) -> float:
    """The gap beyond which a cut is flagged: ``NOISE_FACTOR`` times its noise floor
    plus ``ABS_FLOOR``."""
    return NOISE_FACTOR * noise + ABS_FLOOR


def unlagged(x, t, tau: float = 0.0, delay: float = 0.0, L: float | None = None) -> np.ndarray:
    """The motion a sensor path of dead time ``delay`` [s] then first-order lag ``tau``
    [s] (``model.measure``) turned into the measured ``x``: the lag undone
    (``x + tau dx/dt``) and the signal moved ``delay`` earlier (held at the end);
    clipped to the stroke ``L``."""
    x = np.asarray(x, float)
    y = x + tau * np.gradient(x, t) if tau > 0.0 else x
    if delay > 0.0:
        y = np.interp(t + delay, t, y)
    return np.clip(y, 0.0, L) if L is not None else y


def _initial(t, p) -> float:
    """A pressure's value at ``t[0]`` from its first samples: the least-squares line's
    (their mean where there are fewer than three)."""
    if len(p) < 3:
        return float(np.mean(p))
    slope, at0 = np.polyfit(np.asarray(t, float) - float(t[0]), np.asarray(p, float), 1)
    return float(at0)


def joint_pressures(cut, joint: str, ex: exc.Excavator = exc.Excavator(), effects: dict | None = None):
    """The joint's pneumatics (with ``effects``) on the cut: ``(p_a, p_b)`` [Pa, absolute],
    as the sensors report them."""
    effects = dict(effects or {})
    tau, delay = measurement_lag(effects)      # the measurement stage's, applied to the outputs below
    effects = {n: q for n, q in effects.items() if EFFECTS[n].stage != "measurement"}
    # the cut starts from the first 20 ms's pressures, not one noisy sample: a line's value
    # at the start (a recording that opens a valve at once fills a chamber at some bar per
    # 10 ms from the first sample on; their mean would start it that much too full, and a
    # chamber sealed after it keeps the excess)
    n0 = max(1, int(0.02 * cut.fs))
    start = SimpleNamespace(**{**vars(cut), "p_a_raw": np.r_[_initial(cut.t[:n0], cut.p_a_raw[:n0]), cut.p_a_raw[1:]],
                               "p_b_raw": np.r_[_initial(cut.t[:n0], cut.p_b_raw[:n0]), cut.p_b_raw[1:]]})
    if tau > 0.0 or delay > 0.0:     # the angle lags as the pressures do: the cut moves as the piston did
        start.x = unlagged(cut.x, cut.t, tau, delay, getattr(cut, "L", None))
    pa, pb = simulate_pneumatics(start, joint_model(joint, ex, effects))
    if tau > 0.0 or delay > 0.0:
        pa, pb = measure(pa, cut.t, tau, delay), measure(pb, cut.t, tau, delay)
    return pa, pb


def joint_gap(cut, joint: str, ex: exc.Excavator = exc.Excavator(), effects: dict | None = None) -> float:
    """The gap of the joint's pneumatics (with ``effects``) on the recording."""
    pa, pb = joint_pressures(cut, joint, ex, effects)
    return _gap(cut, pa, pb)


# ----------------------------------------------------------------------------- results
@dataclass
class Fitted:
    """A candidate (one effect, or a pair ``"a+b"``) fitted on a joint's fit cuts."""
    name: str
    params: dict                 #: {effect: {parameter: value}}
    fit_gap: float               #: the fit cuts' mean gap with it
    hold_gaps: list              #: each holdout cut's gap with it
    shrink: float                #: 1 - mean(hold_gaps) / the holdouts' mean gap before
    values: dict | None = None   #: the joint's load re-identified with it (a friction effect)
    not_fitted: str | None = None  #: why it could not be fitted (then no shrink)
    told: list = field(default_factory=list)   #: its parameters the holdouts told (``attribute.told_by_holdout``): no held-out figure for them

    @property
    def names(self) -> list[str]:
        return self.name.split("+")


@dataclass
class CutFinding:
    """One cut of one joint on the holdouts."""
    kind: str                    #: "pressures" (the pneumatic cut) or "position" (the load cut)
    gaps: list                   #: each holdout's gap without effects
    noises: list                 #: each holdout's noise floor
    fit_gap: float = math.nan    #: the fit cuts' mean gap without effects
    candidates: list = field(default_factory=list)   #: :class:`Fitted`, best first (a pair first where named)
    verdict: list = field(default_factory=list)      #: effect names, or ["unexplained"]
    values: dict | None = None   #: the load cut's joint load identified on the fit cuts
    own_gaps: list | None = None  #: the load cut's gaps with the load identified on each holdout itself
    spreads: list | None = None   #: what the load's static friction interval moves the load cut, per holdout
    model_error: float = 0.0     #: what the cut's model leaves where it is fitted (:func:`_model_error`), added to its threshold

    @property
    def thresholds(self) -> list:
        return [threshold(n) + self.model_error for n in self.noises]

    @property
    def flagged(self) -> bool:
        return any(g > h for g, h in zip(self.gaps, self.thresholds))

    @property
    def gap(self) -> float:
        return float(np.mean(self.gaps))

    @property
    def noise(self) -> float:
        return float(np.mean(self.noises))

    @property
    def excess(self) -> float:
        """How far beyond its threshold the cut is, as a share of it (the worst holdout)."""
        return max((g - h) / h for g, h in zip(self.gaps, self.thresholds))


@dataclass
class JointFinding:
    joint: str
    pressures: CutFinding
    position: CutFinding | None = None   #: None where the load cut is not available
    load_note: str | None = None         #: why there is no load cut

    @property
    def flagged(self) -> bool:
        return self.pressures.flagged or bool(self.position and self.position.flagged)

    @property
    def cuts(self) -> list:
        return [c for c in (self.pressures, self.position) if c is not None]

    @property
    def named_cuts(self) -> list:
        """The cuts whose findings are the joint's: the pneumatic cut's where it names an
        effect, else the load cut's.  An effect on the pneumatics changes how the joint
        holds and breaks away (a leak's creep, a deadband's closed chambers), which the
        load cut, run on the measured pressures with a friction law's few parameters,
        shows as a gap at its starts from rest that a friction law takes up; so there
        the load cut's candidates are reported, not named (a friction effect on the same
        joint as a pneumatic one is then missed: the price of no false friction)."""
        named = lambda c: bool(c.verdict) and c.verdict != ["unexplained"]
        if named(self.pressures):
            return [self.pressures]
        return [c for c in self.cuts if named(c)]

    @property
    def verdict(self) -> list[str]:
        """The effects its cuts name (:attr:`named_cuts`); ``["unexplained"]`` only where
        no cut names one and a cut is left unexplained."""
        out = [n for c in self.named_cuts for n in c.verdict]
        if not out and any(c.verdict == ["unexplained"] for c in self.cuts):
            out = ["unexplained"]
        return out

    @property
    def candidates(self) -> list:
        return [c for cut in self.cuts for c in cut.candidates]

    # the pneumatic cut's figures (the report's table and older callers)
    @property
    def gap(self) -> float:
        return self.pressures.gap

    @property
    def noise(self) -> float:
        return self.pressures.noise


@dataclass
class JointsDiagnosis:
    joints: dict                #: joint -> JointFinding
    verdict: list               #: "<effect>@<joint>" (or "unexplained@<joint>")
    notes: list = field(default_factory=list)


# ----------------------------------------------------------------------------- fitting
def _mean_gap(cuts, joint, ex, effects) -> float:
    return float(np.mean([joint_gap(c, joint, ex, effects) for c in cuts]))


def _hold_gaps(joint, ex, effects, hold_cuts, others) -> list:
    """Each holdout's gap of ``joint``'s cut with ``effects``.  A measurement effect may be
    the data acquisition's (the bridge's sensor_lag lags every joint's channels) or one
    joint's sensors': it is taken to be on another joint's channels unless that joint's
    fit recordings reject it (its lag there makes their gap worse beyond their noise's
    threshold).  What it makes worse on the holdout cuts of the joints it is taken to be
    on (``others``: [(joint, their holdout cuts, their gaps without, their fit cuts,
    their fit gap without, their fit noise)]) is added to the joint's gap, so that a lag
    that only suits one joint's pressures (as a slow spool's does) does not pass for the
    sensors'; a lag the other joints' own fit recordings refuse is this joint's alone."""
    gaps = [joint_gap(c, joint, ex, effects) for c in hold_cuts]
    if any(EFFECTS[n].stage == "measurement" for n in effects):
        lag = {n: q for n, q in effects.items() if EFFECTS[n].stage == "measurement"}
        for other, cuts, before, fit_cuts, fit_before, fit_noise in others:
            if _mean_gap(fit_cuts, other, ex, lag) > fit_before + threshold(fit_noise):
                continue            # not on that joint's channels: its fit recordings refuse it
            gaps = [g + max(joint_gap(c, other, ex, lag) - b, 0.0) for g, c, b in zip(gaps, cuts, before)]
    return gaps


def _fit_single(job):
    """One effect of the pneumatic cut on one joint, every law, as the boom's whole model
    fits it (``attribute.fit_laws``: each simple law screened and refined, the best kept;
    a wider law grown from its fit where the fit cuts and the holdouts bear it out; a
    further parameter the fit cuts cannot tell, told by the holdouts).  Returns
    ``(name, effects, fit gap, holdout gaps, told)``."""
    joint, name, ex, fit_cuts, hold_cuts, base, others = job
    cost_of = lambda effects: _mean_gap(fit_cuts, joint, ex, effects)

    def hold(effects):
        gaps = _hold_gaps(joint, ex, effects, hold_cuts, others)
        return float(np.mean(gaps)), gaps
    fx, cost, gaps, told = fit_laws(name, joint_forms(name, joint, ex),
                                    lambda **kw: fit_effects([name], {}, None, cost_of=cost_of, **kw), hold, base,
                                    refine_each=True, told_costs=(cost_of, lambda e: hold(e)[0]))
    return name, fx, cost, gaps, told


def _fit_pair(job):
    """Two effects of the pneumatic cut on one joint, fitted jointly
    (``attribute.fit_pair_jointly``: both singles' fits, both halved, the weaker
    screened beside the stronger's fit); None where no start lowers the fit error below
    the better single's by SCREEN."""
    joint, names, ex, fit_cuts, hold_cuts, start, single_costs, others = job
    cost_of = lambda effects: _mean_gap(fit_cuts, joint, ex, effects)
    forms = {n: law_of(joint_forms(n, joint, ex), start[n]) for n in names}
    fitted = fit_pair_jointly(names, start, single_costs, forms, {n: [forms[n]] for n in names}, cost_of)
    if fitted is None:
        return None
    fx, cost = fitted
    return list(names), fx, cost, _hold_gaps(joint, ex, fx, hold_cuts, others)


def _fit_load(job):
    """A friction effect on one joint's load cut (``joint_load.fit_load_effect``: the
    joint's load re-identified at each value; then :func:`joint_load.refine_load`), scored on the
    holdouts' load cuts; the reason where it cannot be fitted."""
    from . import joint_load as jl
    _, joint, name, fit_cuts, hold_cuts = job
    try:
        params, values, _ = jl.fit_load_effect(fit_cuts, name)
        fx = {name: params}
        values, fit_gap = jl.refine_load(fit_cuts, values, fx)
        return name, fx, fit_gap, [jl.load_gap(c, values, fx) for c in hold_cuts], values
    except (ValueError, ArithmeticError) as e:
        return f"{joint}'s load with {name}: {e}"


def _fit_job(job):
    if job[0] == "position":
        out = _fit_load(job)
        return out if isinstance(out, str) else (*out, [])
    name, fx, cost, gaps, told = _fit_single(job[1:])
    return name, fx, cost, gaps, None, told


def _job_cost(job) -> float:
    """A fit's rough cost, for scheduling: a friction effect's (the load identified at
    each value) first, then the cushion's three parameters."""
    if job[0] == "position":
        return 1000.0 * len(EFFECTS[job[2]].forms)
    if isinstance(job[1], (list, tuple)):
        return 50.0
    name = job[2] if job[0] == "pressures" else job[1]
    return float(max(len(f) for f in FORMS.get(name, [CANDIDATES[name]])) ** 3 * len(FORMS.get(name, [None])))


def _shrink(before: list, after: list) -> float:
    b = float(np.mean(before))
    return 1.0 - float(np.mean(after)) / b if b > 0.0 else 0.0


def _needs_pair(cut: CutFinding) -> bool:
    best = cut.candidates[0] if cut.candidates else None
    if best is None or best.not_fitted:
        return False
    return best.shrink < MIN_SHRINK or float(np.mean(best.hold_gaps)) > threshold(cut.noise)


def _pair_jobs(joint, cut: CutFinding, ex, fit_cuts, hold_cuts, others) -> list:
    helped = [c for c in cut.candidates if c.shrink > 0.0 and not c.not_fitted][:PAIR_POOL]
    combos = list(itertools.combinations(helped, 2))
    if helped and helped[0].shrink >= MIN_SHRINK:
        # the best explains the gap alone: a partner must show on its own at least half
        # of what it would have to remove beside it (attribute._pairs' rule)
        needed = MIN_SHRINK_SECOND * (float(np.mean(helped[0].hold_gaps)) - cut.noise)
        combos = [(helped[0], c) for c in helped[1:] if cut.gap - float(np.mean(c.hold_gaps)) >= 0.5 * needed]
    return [(joint, (a.name, b.name), ex, fit_cuts, hold_cuts, {a.name: a.params[a.name], b.name: b.params[b.name]},
             {a.name: a.fit_gap, b.name: b.fit_gap}, others) for a, b in combos]


def _decide(cut: CutFinding, pairs: list) -> None:
    """The cut's verdict from its singles (sorted) and its fitted ``pairs``."""
    if not cut.flagged:
        return
    by_name = {c.name: c for c in cut.candidates}
    noise = cut.noise
    best_pair = None
    for p in pairs:
        pays = all(_pays({"gap": float(np.mean(by_name[n].hold_gaps))}, {"gap": float(np.mean(p.hold_gaps))},
                             noise) for n in p.names)
        if p.shrink >= MIN_SHRINK and pays and (best_pair is None or p.shrink > best_pair.shrink):
            best_pair = p
    fitted = [c for c in cut.candidates if not c.not_fitted]
    if best_pair is not None:
        cut.candidates.insert(0, best_pair)
        cut.verdict = best_pair.names
    elif fitted and fitted[0].shrink >= MIN_SHRINK:
        cut.verdict = [fitted[0].name]
    else:
        cut.verdict = ["unexplained"]


def _model_error(cut: CutFinding, fit_noise: float) -> float:
    """What the load cut's model cannot reproduce even on the recordings it is fitted on:
    the least gap left on the fit cuts, by the joint's load identified there or by any
    friction candidate fitted there (each with the load re-identified), less the fit
    cuts' own noise floor.  A holdout's gap within that (beyond the noise's threshold) is
    the model's error, not something wrong on the holdout: no finding; so a candidate is
    named only where the gap it is to explain is beyond it too."""
    fitted = [c.fit_gap for c in cut.candidates if not c.not_fitted and math.isfinite(c.fit_gap)]
    least = min([cut.fit_gap] + fitted) if math.isfinite(cut.fit_gap) else min(fitted, default=0.0)
    return max(least - fit_noise, 0.0)


def _own_load(f: JointFinding, jl, hold_cuts, notes: list, fit_cuts=(), fit_noise: float = 0.0) -> None:
    """A load cut's finding (a friction candidate named, or ``unexplained``) stands only
    where the gap is beyond what the joint's load itself leaves open: beyond the
    threshold plus what the load's uncertainty from the fit recordings moves the cut
    (``joint_load.load_spread``), and beyond what the joint's load identified on each
    holdout itself (no effect) leaves there.  A gap that this closes is the fit
    recordings' uncertainty of the load (a static friction, a payload they did not pin),
    which is no finding (``attribute``'s rule for a gap within the baseline's own
    uncertainty): "cannot tell", said in the notes.  A named candidate stands where its
    holdout gaps are below what the holdout's own load leaves (by more than their noise
    floor: it explains what no load does), or where the fit recordings (``fit_cuts``,
    their noise ``fit_noise``) refuse the holdout's own load (their gap with it beyond
    their own gap plus their noise's threshold): the two recordings need two loads, the
    difference the candidate explains, which is no uncertainty of one load.  Where the
    holdout holds too little of the joint's motion to identify its load there, an
    unexplained gap cannot be judged (no finding, said); a named candidate stands.
    Nothing is fitted on the holdout for a candidate's score."""
    lc = f.position
    named = lc.verdict != ["unexplained"]
    best = lc.candidates[0] if named and lc.candidates else None
    what = f"{'+'.join(lc.verdict)}@{f.joint} not named" if named else "not a finding"
    try:
        loads = [jl.refine_load([c], jl.identify_load([c], {}), {}) for c in hold_cuts]
        own = [g for _, g in loads]
    except (ValueError, ArithmeticError) as e:
        if named:
            return
        # the holdout holds too little of the joint's motion to tell a gap of its load
        # from the load's own uncertainty: not judged, said
        lc.verdict = []
        notes.append(f"{f.joint}: the load cut's gap ({100 * lc.gap:.2f} %) cannot be judged: its load cannot be "
                     f"identified on the holdout itself ({e}); not a finding")
        return
    lc.own_gaps = own
    if best is not None and all(a < o - n for a, o, n in zip(best.hold_gaps, own, lc.noises)):
        return
    if best is not None and fit_cuts and math.isfinite(lc.fit_gap):
        refused = lc.fit_gap + threshold(fit_noise)
        if any(float(np.mean([jl.load_gap(c, v, {}) for c in fit_cuts])) > refused for v, _ in loads):
            return
    # what the load's own uncertainty (F_s's 95 % interval from the fit recordings' starts)
    # moves the cut's position by: a gap within the threshold plus that is no finding
    lc.spreads = [jl.load_spread(c, lc.values, {}) for c in hold_cuts]
    if all(g <= h + s for g, h, s in zip(lc.gaps, lc.thresholds, lc.spreads)):
        lc.verdict = []
        notes.append(f"{f.joint}: the load cut's gap ({100 * lc.gap:.2f} %) is within what the uncertainty of the "
                     f"{f.joint}'s static friction moves it ({100 * float(np.mean(lc.spreads)):.2f} % beyond the "
                     f"noise's threshold): the fit recordings do not pin its starts closely enough to tell; {what}")
        return
    if all(g <= h + s for g, h, s in zip(own, lc.thresholds, lc.spreads)):
        lc.verdict = []
        notes.append(f"{f.joint}: the load cut's gap ({100 * lc.gap:.2f} %) is within what the joint's load "
                     f"identified on the holdout itself leaves ({100 * float(np.mean(own)):.2f} %): the fit "
                     f"recordings do not pin the {f.joint}'s load, and no friction effect explains more than a "
                     f"load identified there; {what}")


def _judge_load(f: JointFinding, jl, fit_cuts, hold_cuts, notes: list) -> None:
    """The load cut's verdict, its candidates fitted: its threshold with the model's own
    error (:func:`_model_error`), the best candidate or ``unexplained`` (:func:`_decide`),
    then any finding held against the load's own uncertainty (:func:`_own_load`)."""
    lc = f.position
    was = lc.flagged
    fit_noise = float(np.mean([jl.load_noise(c) for c in fit_cuts]))
    lc.model_error = _model_error(lc, fit_noise)
    if was and not lc.flagged:
        notes.append(f"{f.joint}: the load cut's gap ({100 * lc.gap:.2f} %) is within what its model leaves "
                     f"on the fit recordings themselves ({100 * lc.model_error:.2f} % beyond their noise) "
                     f"plus the noise's threshold: the model's own error; not a finding")
    _decide(lc, [])
    if lc.verdict:
        _own_load(f, jl, hold_cuts, notes, fit_cuts, fit_noise)


def _load_module():
    """``diagnose.joint_load`` where it is installed, else ``(None, why)``."""
    try:
        from . import joint_load
    except ImportError as e:
        return None, (f"the joints' load cut (boomfmi.diagnose.joint_load) is not available ({type(e).__name__}): "
                      f"the friction effects ({', '.join(candidates(LOAD_STAGES))}) are not fitted")
    return joint_load, None


def _frames(recs) -> list:
    if recs is None:
        return []
    if hasattr(recs, "columns") or hasattr(recs, "data"):
        return [recs]
    return list(recs)


def diagnose_joints(fit, hold, ex: exc.Excavator = exc.Excavator(), joints=exc.JOINTS,
                    workers: int | None = None, progress=None) -> JointsDiagnosis:
    """Localise the gap per joint and cut, and attribute it (see the module's docstring).
    ``fit``, ``hold``: recordings of the linkage ``ex`` (``recording.Recording`` or DataFrames,
    pressures gauge; one or a list each): candidates are fitted on ``fit``, scored and
    flagged on ``hold``.  ``workers``: processes at once (default: one per core)."""
    say = progress or (lambda text: None)
    fit, hold = _frames(fit), _frames(hold)
    if not fit or not hold:
        raise ValueError("the per-joint diagnosis needs at least one fit and one holdout recording")
    workers = workers or os.cpu_count() or 1
    jl, load_note = _load_module()
    notes = [load_note] if load_note else []
    findings, fit_cuts, hold_cuts = {}, {}, {}
    for joint in joints:
        fit_cuts[joint] = [joint_cut(r, joint, ex) for r in fit]
        hold_cuts[joint] = [joint_cut(r, joint, ex) for r in hold]
        pc = CutFinding("pressures", [joint_gap(c, joint, ex) for c in hold_cuts[joint]],
                        [joint_noise(c) for c in hold_cuts[joint]])
        findings[joint] = JointFinding(joint, pc, load_note=load_note)
    # the load cuts (friction through the joint's load, re-identified on the fit recordings)
    load_fit, load_hold = {}, {}
    if jl is not None:
        for joint in joints:
            try:
                load_fit[joint] = [jl.load_cut(r, joint, ex) for r in fit]
                load_hold[joint] = [jl.load_cut(r, joint, ex) for r in hold]
                values, fit_gap = jl.refine_load(load_fit[joint], jl.identify_load(load_fit[joint], {}), {})
                lc = CutFinding("position", [jl.load_gap(c, values, {}) for c in load_hold[joint]],
                                [jl.load_noise(c) for c in load_hold[joint]], values=values)
                lc.fit_gap = fit_gap
                findings[joint].position = lc
            except (ValueError, ArithmeticError) as e:
                findings[joint].load_note = f"{joint}'s load cut: {e}"
                notes.append(findings[joint].load_note)
    # every candidate on every flagged cut, at once
    fit_without = {j: (_mean_gap(fit_cuts[j], j, ex, {}), float(np.mean([joint_noise(c) for c in fit_cuts[j]])))
                   for j in joints}
    others = {j: [(o, hold_cuts[o], findings[o].pressures.gaps, fit_cuts[o], *fit_without[o]) for o in joints if o != j]
              for j in joints}
    jobs = []
    for joint, f in findings.items():
        if f.pressures.flagged:
            f.pressures.fit_gap = fit_without[joint][0]
            jobs += [("pressures", joint, name, ex, fit_cuts[joint], hold_cuts[joint], f.pressures.fit_gap,
                      others[joint]) for name in candidates(PNEUMATIC_STAGES)]
        if f.position is not None and f.position.flagged:
            jobs += [("position", joint, name, load_fit[joint], load_hold[joint]) for name in candidates(LOAD_STAGES)]
        elif f.position is None and f.flagged:
            f.pressures.candidates += [Fitted(name, {}, math.nan, [], 0.0, not_fitted=f.load_note)
                                       for name in candidates(LOAD_STAGES)]
    flagged = [j for j, f in findings.items() if f.flagged]
    say(f"flagged: {', '.join(flagged) or 'no joint'}; fitting {len(jobs)} candidate(s) on the fit recordings")
    for job, out in zip(jobs, _map(_fit_job, jobs, workers, cost=_job_cost)):
        cut = getattr(findings[job[1]], job[0])
        if isinstance(out, str):
            cut.candidates.append(Fitted(job[2], {}, math.nan, [], 0.0, not_fitted=out))
            continue
        name, fx, cost, gaps, values, told = out
        cut.candidates.append(Fitted(name, fx, cost, gaps, _shrink(cut.gaps, gaps), values=values, told=told))
    for joint, f in findings.items():
        for c in f.cuts:
            c.candidates.sort(key=lambda k: (k.not_fitted is not None, -k.shrink))
    # pairs on the cuts whose best single leaves a gap
    pair_jobs = [job for j, f in findings.items() if f.pressures.flagged and _needs_pair(f.pressures)
                 for job in _pair_jobs(j, f.pressures, ex, fit_cuts[j], hold_cuts[j], others[j])]
    if pair_jobs:
        say(f"fitting {len(pair_jobs)} pair(s) of candidates")
    pairs = {j: [] for j in findings}
    for job, out in zip(pair_jobs, _map(_fit_pair, pair_jobs, workers, cost=_job_cost)):
        if out is None:
            continue
        names, fx, cost, gaps = out
        cut = findings[job[0]].pressures
        pairs[job[0]].append(Fitted("+".join(names), fx, cost, gaps, _shrink(cut.gaps, gaps)))
    for joint, f in findings.items():
        _decide(f.pressures, pairs[joint])
        if f.position is not None:
            _judge_load(f, jl, load_fit[joint], load_hold[joint], notes)
    order = sorted((f for f in findings.values() if f.flagged),
                   key=lambda f: -max(c.excess for c in f.cuts if c.flagged))
    verdict = [f"{name}@{f.joint}" for f in order for name in f.verdict]
    return JointsDiagnosis(findings, verdict, notes)

__all__ = [
    "PNEUMATIC_STAGES", "LOAD_STAGES", "candidates", "joint_forms", "joint_cut", "joint_model",
    "P_SPAN_MIN", "joint_noise", "threshold", "unlagged", "joint_pressures", "joint_gap", "Fitted",
    "CutFinding", "JointFinding", "JointsDiagnosis", "diagnose_joints",
]
