"""One joint of the whole excavator as a load cut: its friction judged on its own motion.

The excavator's pneumatic cut (``diagnose/joints.py``) runs a joint's valve and
chambers on its measured motion; an effect on the joint's friction shows there only
through that motion, which is measured.  The **load cut** is the other half: the joint
as an equivalent single cylinder (``identify.preprocess.prepare_machine``: unit areas,
its own diagonal mass ``M_x[i, i]`` at each posture, and the net force on it, the
pneumatic force from its recorded pressures minus everything the other joints'
measured motion, gravity, the payload and the tip force put on it), simulated forward
with its own friction (Eq. 8, 9: K_v, F_s, F_d, the stick test at F_s, end stops at 0
and the stroke; cos(phi) on the boom) and the ``friction`` stage's effects of the
catalogue applied at every substep through :meth:`model.Boom.load_at`.  What comes out
is this joint's position; its gap is the position's NRMSE over its range, as the
sensor reads it (``compare.as_sensed``).

**Episodes.**  The simulation runs from rest to rest: at every rest of the measured
motion (at least :data:`REST` long, ``identify.fit.motion_modes``), once it has settled,
it restarts at the measured position, at rest, so that a friction level wrong by a
little drifts over one motion, not over the whole recording, while every start (F_s)
and every slide (K_v, F_d, the effects) is the model's own.  It restarts, too, after
another joint's end-stop impact, whose impulse the cut knows only as a filtered
acceleration; the samples within the filter's spread of it are not judged
(``LoadCut.judged``).

**The payload** is the one the joint's own motion pins (:func:`_payload`): the whole
machine's equation error gives it with an interval; within that interval widened by its
width, the value at which the joint's load leaves the least gap on the fit recordings.

**The load with an effect.**  The joint's K_v, F_s and F_d are identified with the
effect on (:func:`identify_load`) by the stages the excavator's identification uses:
the equation error over every sample with the linkage's terms known
(``identify.joints.equation_rows``, this joint's rows; the payload from the whole
machine's ``identify.joints.equation_error``, without the effect), its friction
column split along the Stribeck curve at the measured speed as
``identify.fit.equation_rows`` splits the boom's; then the static friction from every
start (``identify.fit.static_friction`` on the equivalent cylinder, with the joint's
mass where each start happens and the other joints' share of the net force as its
uncertainty, as ``identify.joints.identify_joints`` does).  A seal-pressure
coefficient is held: its friction is taken off the net force (against the motion while
sliding, against the drive at rest, never beyond it), so that every stage sees the
friction that is left.  :func:`fit_load_effect` searches each law's parameter over the
catalogue's bounds (``attribute.fit_effects``' screen and bounded search, on a log
scale where the catalogue says so), the load re-identified at every value (as
``attribute._fit_friction`` does for the boom), and keeps the law whose cut fits the
fit recordings best (the fit cuts' mean gap).

Figures (the four-joint virtual rig, 8 s of ``excavator_excitation`` to fit): each
simulation of 8000 samples takes 0.05 to 0.08 s, an identification 0.1 s (3 s once per
set of fit recordings for the payload), a friction effect's fit 2 to 6 s; see
``tests/test_joint_load.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from .. import physics as ph
from ..compare import as_sensed
from ..identify.joints import EE_CUTOFF, JOINTS, equivalent as _equivalent, honest_static as _honest_static
from ..identify.joints import equation_error as machine_equation_error
from ..identify.joints import equation_rows as machine_equation_rows
from ..identify.preprocess import JointData, machine_for, prepare_machine as prepare_excavator
from ..identify.fit import PRESSURE_COEFFICIENT, Motion, motion, runs, static_friction
from ..identify.preprocess import lowpass
from ..model import EFFECTS, Boom, Model, check_effects
from ..model.catalogue import LOAD_LAWS
from ..physics import effects as fx
from ..physics import linkage as exc
from .attribute import fit_effects

#: The least rest [s] at which the simulation restarts from the measured position.
REST = 0.03
#: The least span [m] a position's error is measured over: a joint that barely moves in
#: the recording is judged against 5 mm, not against its sensor's noise.
X_SPAN_MIN = 5e-3
#: Substeps per sample of the forward simulation (the net force interpolated linearly
#: between samples, each substep at its midpoint value).
SUBSTEPS = 2
#: The least motion [s of sliding, over the fit cuts] from which a joint's load is identified.
MIN_MOTION = 0.2
#: The catalogue's stages the load cut takes.
STAGES = ("friction",)


@dataclass
class LoadCut:
    """One recording's joint as its load cut (:func:`load_cut`)."""
    joint: str
    data: JointData                 #: this joint (``identify.preprocess.JointData``)
    machine: list                   #: every joint's JointData (the payload's equation error)
    ex: exc.Excavator
    p_a: np.ndarray                 #: the joint's chamber pressures [Pa, absolute], as recorded
    p_b: np.ndarray
    episodes: list                  #: (first, end, x0 [m], v0 [m/s]) from rest to rest
    source: str = ""                #: the recording's path ("" for a DataFrame)
    judged: np.ndarray | None = None  #: the samples its gap is taken over (:func:`_judged`; None: all)
    _cache: dict = field(default_factory=dict, repr=False)   #: its equation-error rows, its equivalent motions

    @property
    def x(self) -> np.ndarray:
        """The measured position [m] (from the measured angle)."""
        return self.data.p.x_raw

    @property
    def index(self) -> int:
        return JOINTS.index(self.joint)

    @property
    def actuator(self):
        return self.ex.actuators[self.index]

    @property
    def span(self) -> float:
        """The range [m] the position's errors are measured over (at least X_SPAN_MIN)."""
        return max(float(np.ptp(self.x)), X_SPAN_MIN)


def _frame(rec):
    return rec.data if hasattr(rec, "data") else rec


_prepared: list = []      #: (frame, ex, [JointData]): the last few recordings prepared


def _prepare(rec, ex):
    """``prepare_excavator`` once per recording and machine (each joint's cut reads the
    same four joints)."""
    d = _frame(rec)
    for frame, machine, data in _prepared:
        if frame is d and machine == ex:
            return data
    data = prepare_excavator(rec, ex)
    _prepared.append((d, ex, data))
    del _prepared[:-4]
    return data


#: Share of the classification's threshold speed below which a rest has settled.
SETTLED = 0.25


def _episodes(jd: JointData) -> list:
    """From rest to rest: ``(first, end, x0, v0)``.  Each rest of at least REST (and one
    at the recording's start) begins an episode where it has settled (the smoothed speed
    below SETTLED of the classification's threshold speed, which a coarse sensor sets
    high: the piston may still creep into what it calls a rest; at the latest at the
    rest's middle), at the median measured position of the next 50 ms, v = 0; the
    episode before runs on through the creep.  A recording that starts in motion starts
    at the smoothed position and speed."""
    p, modes = jd.p, jd.modes
    n = len(p.t)
    long, head = int(round(REST * p.fs)), int(round(0.05 * p.fs))
    rests = [(i0, i1) for i0, i1 in runs(~modes.sliding) if i1 - i0 >= long or i0 == 0]
    begins = []
    for i0, i1 in rests:
        calm = np.flatnonzero(np.abs(modes.v[i0:(i0 + i1) // 2 + 1]) < SETTLED * modes.v_min)
        begins.append(0 if i0 == 0 else i0 + int(calm[0]) if len(calm) else (i0 + i1) // 2)
    out = []
    if not begins or begins[0] != 0:
        out.append((0, begins[0] if begins else n, float(modes.x[0]), float(modes.v[0])))
    for k, ((i0, i1), b) in enumerate(zip(rests, begins)):
        end = begins[k + 1] if k + 1 < len(begins) else n
        x0 = float(np.clip(np.median(p.x_raw[b:max(b + 1, min(i1, b + head))]), 0.0, jd.L))
        out.append((b, end, x0, 0.0))
    return out


#: [m] a joint within this of an end of its stroke is on its stop
AT_STOP = 5e-4


def _impacts(data: list, i: int) -> list:
    """Where another joint than the ``i``-th comes to rest on an end stop (a plastic
    impact): the sample its rest begins.  The stop's reaction reaches this joint through
    the linkage's inertia as an impulse, which the load cut knows only through the other
    joint's filtered acceleration (spread over some 1/CUTOFF, across which this joint's
    friction may stick or turn): the cut cannot follow this joint through it."""
    out = []
    for o, jd in enumerate(data):
        if o == i:
            continue
        x = jd.p.x
        for i0, _ in runs(~jd.modes.sliding):
            if i0 > 0 and (x[i0] <= AT_STOP or x[i0] >= jd.L - AT_STOP):
                out.append(i0)
    return sorted(out)


def _settle(jd: JointData) -> int:
    """Samples over which the filtered acceleration spreads an impulse: two periods of
    the filter's cut-off (``jd.p.cutoff``), on either side (the filter is zero-phase)."""
    return int(round(2.0 * jd.p.fs / jd.p.cutoff))


def _judged(jd: JointData, impacts: list) -> np.ndarray | None:
    """The samples the load cut's gap is taken over: all but those within
    :func:`_settle` of another joint's impact (:func:`_impacts`), where the cut knows the
    stop's impulse only as a filtered acceleration spread on both sides of it, and so
    cannot follow this joint (the restart after it, :func:`_split_at_impacts`, keeps the
    error from running on; what the joint did through the impact is not judged).  None
    where nothing is left out, or where it would leave less than half the recording."""
    if not impacts:
        return None
    n, settle = len(jd.p.t), _settle(jd)
    keep = np.ones(n, bool)
    for k in impacts:
        keep[max(k - settle, 0):k + settle] = False
    return keep if np.count_nonzero(keep) >= n // 2 else None


def _split_at_impacts(episodes: list, jd: JointData, impacts: list) -> list:
    """The episodes restarted where another joint's impact has passed (two periods of the
    filter's cut-off after it, ``jd.p.cutoff``), at the measured position and speed
    (smoothed, as a recording that starts in motion), so that an impact the cut cannot
    follow costs it one motion's error, not the rest of the run."""
    settle = _settle(jd)
    restarts = sorted({k + settle for k in impacts if k + settle < len(jd.p.t)})
    out = []
    for i0, i1, x0, v0 in episodes:
        inner = [r for r in restarts if i0 < r < i1]
        starts = [(i0, x0, v0)] + [(r, float(np.clip(jd.modes.x[r], 0.0, jd.L)), float(jd.modes.v[r]))
                                   for r in inner]
        ends = [r for r in inner] + [i1]
        out += [(a, b, x, v) for (a, x, v), b in zip(starts, ends)]
    return out


def load_cut(rec, joint: str, ex: exc.Excavator | None = None) -> LoadCut:
    """The load cut of ``joint`` on one excavator recording (a ``recording.Recording`` or
    a DataFrame in the excavator's format, pressures gauge); ``ex`` the machine (default
    ``identify.preprocess.machine_for(rec)``'s: excavator.md's with the
    recording's P_atm)."""
    if joint not in JOINTS:
        raise ValueError(f"the load cut is of a joint: one of {', '.join(JOINTS)}, not {joint!r}")
    if ex is None:
        ex = machine_for(rec) if hasattr(rec, "P_atm") else exc.Excavator()
    d = _frame(rec)
    missing = [c for c in ("t", *(f"{q}_{j}" for q in ("u", "p_a", "p_b", "angle") for j in JOINTS))
               if c not in d]
    if missing:
        raise ValueError(f"{getattr(rec, 'path', 'the recording')}: not an excavator recording: "
                         f"missing column(s) {', '.join(missing)}")
    data = _prepare(rec, ex)
    i = JOINTS.index(joint)
    P_atm = float(rec.P_atm) if hasattr(rec, "P_atm") else ex.P_atm
    jd = data[i]
    impacts = _impacts(data, i)
    return LoadCut(joint, jd, data, ex, d[f"p_a_{joint}"].to_numpy(float) + P_atm,
                   d[f"p_b_{joint}"].to_numpy(float) + P_atm,
                   _split_at_impacts(_episodes(jd), jd, impacts),
                   str(getattr(rec, "path", "")), _judged(jd, impacts))


def load_noise(cut: LoadCut) -> float:
    """The position's noise floor over its range (``identify.preprocess.noise_floor``'s
    law, as the pressure cut's ``excavator.joint_noise``: the RMS of what a 50 Hz
    low-pass removes), the range at least :data:`X_SPAN_MIN`."""
    m = cut.x
    return float(np.std(m - lowpass(m, cut.data.p.fs, 50.0))) / cut.span


# ----------------------------------------------------------------------------- effects
def _friction_effects(effects) -> dict:
    """The effects checked (``model.check_effects``: the catalogue's names, their own
    parameters, finite, >= 0, within their maxima) and of the ``friction`` stage, the one
    the load cut takes (``physics.ParameterError``, a ValueError, naming what is not)."""
    effects = {name: dict(q) for name, q in dict(effects or {}).items()}
    check_effects(effects)
    for name in effects:
        if EFFECTS[name].stage not in STAGES:
            raise ph.ParameterError("effects", name, f"acts in the {EFFECTS[name].stage!r} stage: the load cut takes "
                                    f"the friction stage's effects only "
                                    f"({', '.join(n for n, e in EFFECTS.items() if e.stage in STAGES)})")
    return effects


def _load_law_params(effects: dict, law: str) -> dict:
    """The parameters that are on of the friction effects that enter the load's own
    identification by ``law`` (``Effect.load_law``); ValueError naming a friction effect
    that has no such law (the load cut identifies no other)."""
    out = {}
    for name, q in effects.items():
        e = EFFECTS[name]
        if e.load_law == law:
            out.update({k: v for k, v in q.items() if v > 0.0})
        elif e.load_law not in LOAD_LAWS:
            raise ValueError(f"effects.{name}: the load cut identifies a friction effect by its load law "
                             f"({', '.join(LOAD_LAWS)}), and {name} has none")
    return out


def _seal_term(effects: dict):
    """The seal-pressure law's ``(law, coefficient)`` (``identify.fit.PRESSURE_COEFFICIENT``'s
    laws) of the effect whose ``load_law`` is ``"seal_pressure"``, or ``(None, 0.0)``; one
    law at a time."""
    q = _load_law_params(effects, "seal_pressure")
    if not q:
        return None, 0.0
    if len(q) > 1:
        names = ", ".join(n for n, e in effects.items() if EFFECTS[n].load_law == "seal_pressure")
        raise ValueError(f"effects.{names}: the load cut fits one seal-pressure law at a time, "
                         f"got {', '.join(sorted(q))}")
    (name, c), = q.items()
    return next(law for law, k in PRESSURE_COEFFICIENT.items() if k == name), float(c)


def _boom(cut: LoadCut, effects: dict) -> Boom:
    a = cut.actuator
    return Boom(Model(valve=a.valve, cylinder=a.cylinder, P_atm=cut.ex.P_atm, effects=effects), check=False)


# ----------------------------------------------------------------------------- simulate
def simulate(cut: LoadCut, values: dict, effects: dict | None = None) -> np.ndarray:
    """The joint's position [m] at every sample: the equivalent cylinder driven by the
    measured net force (with ``values``' payload share), friction ``values`` (K_v, F_s,
    F_d) with ``effects`` (the friction stage's), from rest to rest (see the module's
    docstring)."""
    effects = _friction_effects(effects)
    for k in ("K_v", "F_s", "F_d"):
        v = values.get(k)
        if v is None or not math.isfinite(v) or v < 0.0:
            raise ValueError(f"{cut.joint}'s load: {k} = {v!r}: the load cut needs K_v, F_s, F_d finite and >= 0")
    if not values["K_v"] > 0.0:
        raise ValueError(f"{cut.joint}'s load: K_v = {values['K_v']!r}: must be > 0")
    jd = cut.data
    payload = max(float(values.get("payload", 0.0) or 0.0), 0.0)
    p = _equivalent(jd, payload)
    F = (p.p_a_raw - p.p_b_raw).tolist()
    M = (jd.Mii0 + payload * jd.dMii).tolist()
    scale = jd.scale.tolist()
    boom = _boom(cut, effects)
    rubbing = bool(boom.friction_effects)
    pa, pb = cut.p_a.tolist(), cut.p_b.tolist()
    L = jd.L
    base = ph.Load(K_v=float(values["K_v"]), F_s=float(max(values["F_s"], values["F_d"])), F_d=float(values["F_d"]),
                   F_L=0.0, M=1.0)
    h = p.dt / SUBSTEPS
    weights = [(j + 0.5) / SUBSTEPS for j in range(SUBSTEPS)]
    last = len(F) - 1
    out = np.empty(len(F))
    step, stops = ph.slide_or_stick, ph.end_stops
    K_v, F_s, F_d = base.K_v, base.F_s, base.F_d
    for i0, i1, x, v in cut.episodes:
        for k in range(i0, i1):
            out[k] = x
            f0 = F[k]
            df = F[min(k + 1, last)] - f0
            ld = ph.Load(K_v, F_s, F_d, 0.0, M[k])          # (base with this sample's mass)
            c = scale[k]
            for w in weights:
                lk = boom.load_at(ld, v, pa[k], pb[k]) if rubbing else ld
                dx, v = step(v, f0 + w * df, c, h, lk)
                x, v = stops(x + dx, v, L)
    return out


def load_gap(cut: LoadCut, values: dict, effects: dict | None = None) -> float:
    """The load cut's gap: the NRMSE of the simulated position (:func:`simulate`, as the
    sensor reads it, ``compare.as_sensed``) against the measured one, over its range
    (at least :data:`X_SPAN_MIN`) and the samples it judges (``cut.judged``); inf where
    the simulation is not finite."""
    xs = simulate(cut, values, effects)
    if not np.all(np.isfinite(xs)):
        return math.inf
    m = cut.x
    e = m - as_sensed(m, xs)
    if cut.judged is not None:
        e = e[cut.judged]
    return float(np.sqrt(np.mean(e ** 2))) / cut.span


def load_spread(cut: LoadCut, values: dict, effects: dict | None = None) -> float:
    """How far the load's own uncertainty moves the load cut: the NRMSE (over the cut's
    range) between the position simulated with ``values`` and with its static friction
    at the nearer end of its 95 % interval (``values["F_s_ci95"]``, from
    :func:`identify_load`: the starts bound F_s and little else, and at a slow slide or a
    start F_s decides whether the joint moves at all).  ``attribute.baseline_spread``'s
    rule for the boom's whole model; 0 without an interval."""
    ci = values.get("F_s_ci95")
    if not ci:
        return 0.0
    F_s, F_d = float(values["F_s"]), float(values["F_d"])
    lo, hi = float(ci[0]), float(ci[1])
    step = min(abs(F_s - lo), abs(hi - F_s))
    if not (math.isfinite(step) and step > 0.0):
        return 0.0
    moved = dict(values, F_s=max(F_s + step if abs(hi - F_s) <= abs(F_s - lo) else F_s - step, F_d))
    a, b = simulate(cut, values, effects), simulate(cut, moved, effects)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return 0.0
    e = a - b if cut.judged is None else (a - b)[cut.judged]
    return float(np.sqrt(np.mean(e ** 2))) / cut.span


# ----------------------------------------------------------------------------- identify
_payloads: list = []     #: (joint or None, cuts' machines, payload or the machine's (value, lo, hi))


def _cached(key, machines, make):
    for k, seen, value in _payloads:
        if k == key and len(seen) == len(machines) and all(a is b for a, b in zip(seen, machines)):
            return value
    value = make()
    _payloads.append((key, machines, value))
    del _payloads[:-16]
    return value


def _machine_payload(cuts) -> tuple:
    """The payload [kg] from the whole machine's equation error over the cuts'
    recordings (``identify.joints.equation_error``): ``(value, lower, upper)``, its
    95 % interval (one per set of recordings, shared by its joints)."""
    machines = [c.machine for c in cuts]

    def make():
        est, _ = machine_equation_error(machines, n_boot=20)
        e = est["payload"]
        return float(e.value), float(e.ci95[0]), float(e.ci95[1])
    return _cached(None, machines, make)


def _payload(cuts) -> float:
    """The payload [kg] as this joint's load cut sees it, >= 0: the whole machine's
    equation error's (:func:`_machine_payload`), then the value that lets the joint's
    load (identified at it, :func:`identify_load`) leave the least gap on ``cuts``
    (a bounded scalar search over its 95 % interval widened by the interval's width on
    either side).  The equation error pins the payload only where the recordings move
    the joints against gravity in many postures; on slow ramps (an operator's joystick)
    its interval is wide and its value may be far off, and every joint's load, fitted
    at it, takes up the difference: the output error of the joint's own motion pins it."""
    machines = [c.machine for c in cuts]

    def make():
        from scipy.optimize import minimize_scalar
        value, lo, hi = _machine_payload(cuts)
        w = hi - lo
        a, b = max(lo - w, 0.0), max(hi + w, 0.0)
        start = min(max(value, 0.0), b)
        if not (math.isfinite(a) and math.isfinite(b)) or b - a <= 1e-6 * max(b, 1.0):
            return start

        def cost(P):
            try:
                values = identify_load(cuts, {}, payload=P)
                return float(np.mean([load_gap(c, values) for c in cuts]))
            except (ValueError, ArithmeticError):
                return math.inf
        res = minimize_scalar(cost, bounds=(a, b), method="bounded",
                              options={"xatol": PAYLOAD_TOLERANCE * (b - a), "maxiter": PAYLOAD_EVALUATIONS})
        return float(res.x) if math.isfinite(res.fun) and res.fun < cost(start) else start
    return _cached(cuts[0].joint, machines, make)


#: the payload's search (:func:`_payload`): its tolerance (a share of the searched range)
#: and its evaluations at most
PAYLOAD_TOLERANCE = 0.02
PAYLOAD_EVALUATIONS = 14


def _motion(cut: LoadCut, payload: float, c: float, law: str | None) -> Motion:
    """The equivalent cylinder's Motion (``identify.fit.motion`` of
    ``identify.joints.equivalent``) with the seals' friction of coefficient ``c``
    by ``law`` taken off the net force: against the motion while sliding, against the
    drive at rest (never beyond it)."""
    key = (round(payload, 9), c, law)
    if key in cut._cache:
        return cut._cache[key]
    jd = cut.data
    p = _equivalent(jd, payload)
    if c > 0.0:
        seal = _seal_force(cut, c, law)
        seal_f = lowpass(seal, p.fs, p.cutoff)
        d = jd.modes.direction
        P_atm = p.p_b_raw

        def held(F, S):
            return np.where(d != 0.0, F - d * S, np.sign(F) * np.maximum(np.abs(F) - S, 0.0))
        p = type(p)(**{**{f.name: getattr(p, f.name) for f in fields(p)},
                       "p_a_raw": held(p.p_a_raw - P_atm, seal) + P_atm,
                       "p_a": held(p.p_a - P_atm, seal_f) + P_atm})
    m = motion(p, _unit(cut), cut.ex.P_atm)
    cut._cache[key] = m
    if len(cut._cache) > 8:
        cut._cache.pop(next(iter(cut._cache)))
    return m


def _seal_force(cut: LoadCut, c: float, law: str) -> np.ndarray:
    """The seals' friction [N] at each sample: ``c`` times the seals' pressure by ``law``
    (``physics.effects.seal_pressure``, the joint's recorded pressures), times Eq. 9's
    scale (cos(phi) on the boom)."""
    return c * fx.seal_pressure(cut.p_a, cut.p_b, cut.ex.P_atm, law) * cut.data.scale


def _rows(cut: LoadCut):
    """The whole machine's equation-error rows of the cut's recording
    (``identify.joints.equation_rows``), this joint's usable ones: ``(X, y)``."""
    if "rows" not in cut._cache:
        X, y, use, which = machine_equation_rows(cut.machine)
        sel = use & (which == cut.index)
        cut._cache["rows"] = (X[sel], y[sel], np.flatnonzero(sel) - cut.index * len(cut.data.p.t))
    return cut._cache["rows"]


def _equation_error(cuts, payload: float, v_s: float, law: str | None, c: float) -> dict:
    """Stage 1 for one joint with the effect: ``identify.joints``'s rows of that joint
    (the linkage's terms known, the payload held), its friction column split along the
    Stribeck curve at the measured speed (``v_s`` > 0: F_d (1 - w) + F_s w, as
    ``identify.fit.equation_rows``) and the held seals' friction taken off; least
    squares for K_v, F_d (and F_s)."""
    Xs, ys = [], []
    i = cuts[0].index
    for cut in cuts:
        X, y, rows = _rows(cut)
        jd = cut.data
        G = lambda z: lowpass(z, jd.p.fs, EE_CUTOFF)
        friction = jd.modes.direction * jd.scale
        y = y - payload * X[:, 8]
        if c > 0.0:
            y = y - G(jd.modes.direction * _seal_force(cut, c, law))[rows]
        if v_s > 0.0:
            w = fx.stribeck_weight(jd.modes.v, v_s)
            cols = [X[:, i], G(friction * (1.0 - w))[rows], G(friction * w)[rows]]
        else:
            cols = [X[:, i], X[:, 4 + i]]
        Xs.append(np.column_stack(cols))
        ys.append(y)
    X, y = np.vstack(Xs), np.concatenate(ys)
    if len(y) < 50 or np.ptp(X[:, 1]) == 0.0:
        raise ValueError(f"{cuts[0].joint}'s load: the fit recordings hold almost no motion of the "
                         f"{cuts[0].joint}: its friction cannot be identified")
    scale = np.abs(X).max(axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    theta /= scale
    out = {"K_v": float(theta[0]), "F_d": float(theta[1])}
    if v_s > 0.0:
        out["F_s"] = float(theta[2])
    return out


def identify_load(fit_cuts, effects: dict | None = None, payload: float | None = None) -> dict:
    """The joint's load (``K_v``, ``F_s``, ``F_d`` [SI], and the ``payload`` [kg] as the
    joint sees it, :func:`_payload`, unless given) identified on its fit cuts with ``effects`` on (the friction stage's:
    stribeck_friction's v_s, a pressure_friction coefficient, held), by the stages of
    ``identify.joints`` (the equation error over every sample, the linkage's terms
    known) and ``identify.fit`` (the static friction from every start, on the
    equivalent cylinder with the joint's mass where each start happens).  ValueError
    where the cuts hold too little motion, or are of different joints."""
    cuts = list(fit_cuts)
    if not cuts:
        raise ValueError("identify_load needs at least one fit cut")
    effects = _friction_effects(effects)
    v_s = float(next(iter(_load_law_params(effects, "stribeck").values()), 0.0))
    law, c = _seal_term(effects)
    _check_motion(cuts)
    payload = _payload(cuts) if payload is None else max(float(payload), 0.0)
    joint = cuts[0].joint
    values = _equation_error(cuts, payload, v_s, law, c)
    for k in ("K_v", "F_d"):
        if not (math.isfinite(values[k]) and values[k] > 0.0):
            raise ValueError(f"{joint}'s load: the fit recordings give {k} = {values[k]:.4g}, not a physical "
                             f"value: too little motion of the {joint} in them")
    motions = [_motion(cut, payload, c, law) for cut in cuts]
    base = {"M": [cut.data.Mii0 + payload * cut.data.dMii for cut in cuts], "K_v": values["K_v"],
            "F_d": values["F_d"], "F_L": 0.0, "F_unsure": [cut.data.unsure for cut in cuts],
            "F_error": [cut.data.coupling_error for cut in cuts]}
    F_s, _, info = static_friction(motions, base, _unit(cuts[0]), cuts[0].ex.P_atm, v_s=v_s)
    interval = None
    if F_s is not None:
        values["F_s"] = F_s.value
        honest, _ = _honest_static(F_s, info or {})
        interval = (float(honest.ci95[0]), float(honest.ci95[1]))
    values["F_s"] = float(max(values.get("F_s", values["F_d"]), values["F_d"]))
    out = {"K_v": values["K_v"], "F_s": values["F_s"], "F_d": values["F_d"], "payload": payload}
    if interval is not None and all(math.isfinite(b) for b in interval):
        out["F_s_ci95"] = interval
    return out


def _check_motion(cuts) -> None:
    """ValueError where the cuts are of several joints, or hold less than MIN_MOTION of
    sliding (naming the joint, the motion held and the recordings)."""
    joints = sorted({c.joint for c in cuts})
    if len(joints) > 1:
        raise ValueError(f"a joint's load is identified on that joint's cuts only, got {', '.join(joints)}")
    moving = sum(float(np.count_nonzero(c.data.modes.sliding)) / c.data.p.fs for c in cuts)
    if moving < MIN_MOTION:
        paths = ", ".join(c.source for c in cuts if c.source)
        raise ValueError(f"{joints[0]}'s load: the fit recordings{f' ({paths})' if paths else ''} hold "
                         f"{moving:.3g} s of its motion, at least {MIN_MOTION:g} s are needed to identify its friction")


def _unit(cut: LoadCut) -> ph.Cylinder:
    a = cut.actuator
    return ph.Cylinder(A_a=1.0, A_b=1.0, L=cut.data.L, V_a0=a.V_a0, V_b0=a.V_b0)


def fit_load_effect(fit_cuts, name: str, form=None):
    """The friction effect ``name`` fitted on one joint's fit cuts, the load
    re-identified at every value of its parameter: ``(effect_params, values, fit_gap)``
    (``{parameter: value}``, the load identified with it, the fit cuts' mean gap).
    Every law of the effect (``form``: one of the catalogue's, as
    ``[(parameter, lower, upper, log)]``, to fit that one only) is screened and refined
    over the catalogue's bounds (``attribute.fit_effects``), the best kept."""
    if name not in EFFECTS or EFFECTS[name].stage not in STAGES:
        raise ValueError(f"{name!r} is not a friction effect of the catalogue "
                         f"({', '.join(n for n, e in EFFECTS.items() if e.stage in STAGES)})")
    cuts = list(fit_cuts)
    if not cuts:
        raise ValueError("fit_load_effect needs at least one fit cut")
    _check_motion(cuts)
    forms = [form] if form is not None else [[(p.name, p.lower, p.upper, p.log) for p in f]
                                             for f in EFFECTS[name].forms]
    seen = {}

    def fitted(effects):
        key = tuple(sorted((n, k, round(v, 12)) for n, q in effects.items() for k, v in q.items()))
        if key not in seen:
            try:
                values = identify_load(cuts, effects)
                gap = float(np.mean([load_gap(c, values, effects) for c in cuts]))
            except (ValueError, ArithmeticError):
                values, gap = None, math.inf
            seen[key] = (gap, values)
        return seen[key]
    best = None
    for f in forms:
        fxd, cost = fit_effects([name], {}, None, forms={name: f}, cost_of=lambda e: fitted(e)[0])
        gap, values = fitted(fxd)
        if values is not None and (best is None or gap < best[2]):
            best = (fxd[name], values, gap)
    if best is None:
        raise ValueError(f"{cuts[0].joint}'s load cannot be identified with {name} over its catalogue bounds")
    return best


#: the load's output-error refinement: Nelder-Mead's evaluations at most, and its first
#: steps (log10 of a factor on K_v, F_d, F_s)
LOAD_EVALUATIONS = 40
LOAD_STEP = 0.05


def refine_load(cuts, values: dict, effects: dict) -> tuple[dict, float]:
    """The joint's load ``values`` (K_v, F_d, F_s, identified by :func:`identify_load`'s equation
    and velocity errors) refined by the load cut's own output error on ``cuts`` with
    ``effects`` held: ``(values, mean gap)``.  The baseline and every friction candidate
    get the same refinement, so that a friction effect fitted by the cut's output error
    is not compared with a load that was not (it would take up the load's misfit: a
    Stribeck curve on an effect-free machine)."""
    from scipy.optimize import minimize

    def at(z):
        K_v, F_d = values["K_v"] * 10 ** z[0], values["F_d"] * 10 ** z[1]
        out = dict(values, K_v=K_v, F_d=F_d, F_s=max(values["F_s"] * 10 ** z[2], F_d))
        if values.get("F_s_ci95"):       # its interval moves with it (the same relative width)
            out["F_s_ci95"] = tuple(float(b) * 10 ** z[2] for b in values["F_s_ci95"])
        return out

    def cost(z):
        return float(np.mean([load_gap(c, at(z), effects) for c in cuts]))
    z0 = np.zeros(3)
    simplex = np.vstack([z0, *(LOAD_STEP * np.eye(3))])
    res = minimize(cost, z0, method="Nelder-Mead",
                   options={"maxfev": LOAD_EVALUATIONS, "initial_simplex": simplex, "xatol": 1e-3, "fatol": 1e-7})
    c0 = cost(z0)
    if not (res.fun < c0):
        return dict(values), c0
    return {k: (float(v) if k != "F_s_ci95" else v) for k, v in at(res.x).items()}, float(res.fun)


__all__ = ["refine_load", "LoadCut", "load_cut", "load_noise", "load_gap", "load_spread", "identify_load",
           "fit_load_effect", "simulate",
           "X_SPAN_MIN", "REST"]
