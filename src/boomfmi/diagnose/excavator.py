"""Diagnosis per joint of an excavator recording: which joint, and which effect.

**Localise.**  Each joint's pneumatics (its valve and its two chambers, the boom
model's own ``model.Boom`` with that joint's valve and cylinder) run on the
recording's command of that joint and its *measured* motion (the piston position
from the measured angle), as ``localise.simulate_pneumatics`` does for the boom: the
cut puts measured signals in place of the linkage's, so a pressure gap that remains is
that joint's own, not carried over from a neighbour through the linkage.  Each joint's
gap is the NRMSE of its two pressures (over their range in the recording), compared
with that joint's noise floor (``attribute.noise_floor``'s law: the RMS of what a 50 Hz
low-pass removes, over the range): a joint whose gap exceeds ``NOISE_FACTOR`` times its
floor plus ``ABS_FLOOR`` (``attribute``'s margins) is flagged.

**Attribute.**  On a flagged joint, every candidate of the catalogue
(``model/catalogue.py``) that acts in that cut (the ``command``, ``port`` and ``seal``
stages: valve deadband, end cushioning, piston leakage, with each of their laws) is
fitted by output error of the joint's pneumatics, its parameters over the catalogue's
bounds (``attribute.fit_effects``' screening then a bounded search, on a log scale
where the catalogue says so); the best is named if it removes ``MIN_SHRINK`` of the
joint's gap, else ``"unexplained"`` (an effect outside this cut, e.g. friction, which
acts through the linkage).  The verdict lists ``"<effect>@<joint>"``; ``[]`` where no
joint's gap exceeds its noise.

The cut needs no identified load: it does not run the linkage, so an effect on the
joint's load (friction) shows here only through the motion it causes, which is
measured; that is its limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
from scipy.optimize import minimize_scalar

from ..compare import as_sensed
from ..identify.preprocess import lowpass
from ..model import EFFECTS, Boom, Model
from ..physics import excavator as exc
from .attribute import ABS_FLOOR, MIN_SHRINK, NOISE_FACTOR
from .localise import simulate_pneumatics

#: the catalogue's effects that act inside one joint's pneumatics (the cut's stages)
PNEUMATIC_STAGES = ("command", "port", "seal")


def pneumatic_candidates() -> dict:
    """name -> its laws, each [(parameter, lower, upper, log)], of the effects in the cut
    (one-parameter laws only: the cut's fits are scalar searches; a setting that does not
    switch the effect, as the cushion's needle area, stays at the catalogue's start)."""
    out = {}
    for name, e in EFFECTS.items():
        if e.stage not in PNEUMATIC_STAGES:
            continue
        forms = [[(p.name, p.lower, p.upper, p.log) for p in form if p.switch] for form in e.forms]
        forms = [f for f in forms if len(f) == 1]
        if forms:
            out[name] = forms
    return out


def joint_cut(data, joint: str, ex: exc.Excavator = exc.Excavator(), P_atm: float | None = None):
    """One joint's measured signals as ``localise.simulate_pneumatics`` takes them: t,
    u, x (from the measured angle, clipped to the stroke) and the pressures [Pa,
    absolute]."""
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
                           fs=fs)


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
    """NRMSE of the two pressures (each as its sensor would read it), summed."""
    return sum(float(np.sqrt(np.mean((m - as_sensed(m, s)) ** 2)) / _span(m))
               for m, s in ((cut.p_a_raw, pa), (cut.p_b_raw, pb)))


def joint_noise(cut) -> float:
    """The joint's pressures' noise floor, summed over the two (each over its range)."""
    return sum(float(np.std(m - lowpass(m, cut.fs, 50.0)) / _span(m)) for m in (cut.p_a_raw, cut.p_b_raw))


def joint_pressures(cut, joint: str, ex: exc.Excavator = exc.Excavator(), effects: dict | None = None):
    """The joint's pneumatics (with ``effects``) on the cut: ``(p_a, p_b)`` [Pa, absolute]."""
    # the cut starts from the first 20 ms's mean pressures, not one noisy sample
    n0 = max(1, int(0.02 * cut.fs))
    start = SimpleNamespace(**{**vars(cut), "p_a_raw": np.r_[np.mean(cut.p_a_raw[:n0]), cut.p_a_raw[1:]],
                               "p_b_raw": np.r_[np.mean(cut.p_b_raw[:n0]), cut.p_b_raw[1:]]})
    return simulate_pneumatics(start, joint_model(joint, ex, effects))


def joint_gap(cut, joint: str, ex: exc.Excavator = exc.Excavator(), effects: dict | None = None) -> float:
    """The gap of the joint's pneumatics (with ``effects``) on the recording."""
    pa, pb = joint_pressures(cut, joint, ex, effects)
    return _gap(cut, pa, pb)


@dataclass
class JointFinding:
    joint: str
    gap: float                  #: summed NRMSE of the two pressures, the cut without effects
    noise: float                #: the noise floor, summed
    flagged: bool
    candidates: list = field(default_factory=list)   #: (name, params, gap after, shrink), best first
    verdict: str | None = None


@dataclass
class ExcavatorDiagnosis:
    joints: dict                #: joint -> JointFinding
    verdict: list               #: "<effect>@<joint>" (or "unexplained@<joint>")


def _fit(cut, joint, ex, name, form, gap0):
    (param, lo, hi, log), = form
    to = (lambda z: 10 ** z) if log else (lambda z: z)
    zl, zh = (math.log10(lo), math.log10(hi)) if log else (lo, hi)
    settings = {p.name: p.start for p in EFFECTS[name].parameters if not p.switch}   # at their start values
    cost = lambda z: joint_gap(cut, joint, ex, {name: {**settings, param: float(to(z))}})
    grid = np.linspace(zl, zh, 6)
    costs = [cost(z) for z in grid]
    k = int(np.argmin(costs))
    best_z, best = grid[k], costs[k]
    if best < gap0:
        res = minimize_scalar(cost, bounds=(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]), method="bounded",
                              options={"xatol": 0.02 * (zh - zl), "maxiter": 12})
        if res.fun < best:
            best_z, best = float(res.x), float(res.fun)
    return {param: float(to(best_z))}, best


def diagnose_excavator(data, ex: exc.Excavator = exc.Excavator(), joints=exc.JOINTS) -> ExcavatorDiagnosis:
    """Localise the gap per joint and attribute it (see the module's docstring).
    ``data``: an excavator recording (DataFrame, pressures gauge)."""
    findings, verdict = {}, []
    cands = pneumatic_candidates()
    for joint in joints:
        cut = joint_cut(data, joint, ex)
        gap0 = joint_gap(cut, joint, ex)
        noise = joint_noise(cut)
        flagged = gap0 > NOISE_FACTOR * noise + ABS_FLOOR
        f = JointFinding(joint, gap0, noise, flagged)
        if flagged:
            for name, forms in cands.items():
                best = min((_fit(cut, joint, ex, name, form, gap0) for form in forms), key=lambda r: r[1])
                f.candidates.append((name, best[0], best[1], 1.0 - best[1] / gap0))
            f.candidates.sort(key=lambda c: -c[3])
            f.verdict = f.candidates[0][0] if f.candidates and f.candidates[0][3] >= MIN_SHRINK else "unexplained"
            verdict.append(f"{f.verdict}@{joint}")
        findings[joint] = f
    return ExcavatorDiagnosis(findings, verdict)
