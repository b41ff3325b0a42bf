"""Friction bench: fit the seal friction laws to friction tests, score them on held-out
tests, choose one.

A friction test (``physics.friction_laws``) records the rod's position x(t), the
chamber's gauge pressure p(t) and the rod force F(t).  The friction is
``F_f = F - p A_eff - F_0``; the effective area ``A_eff`` and the load cell's offset
``F_0`` are identified together with each law (the nominal area is only a check), by
least squares on the sliding samples (the force is linear in every parameter but
Stribeck's v_s, which is profiled): for eq9 and pressure those past each reversal's
breakaway window, where the friction has settled at its sliding level; for Stribeck
all, the low speeds after a reversal being its domain.  The velocity is a smoothed derivative of x
(``bench.signals``); a sample is at rest below the velocity's noise.

What force data can tell apart, and what not: a Coulomb level higher in one direction
by a constant moves F - p A like an offset, and one higher by ``c p`` like an area, so
``F_0 + (F_d+ - F_d-)/2`` and ``A_eff + (c_d+ - c_d-)/2`` are all the data determine.
Each law therefore has one Coulomb level for both directions, and ``F_0`` and ``A_eff``
carry what a direction difference of it would be; its direction asymmetry lies where
the data do tell the directions apart: the static levels (breakaway) and, for Stribeck,
the low-speed levels.  The viscous coefficient is one for both directions too: a
bench's speed is nearly constant in each direction, so a viscous coefficient per
direction would be a Coulomb level per direction in disguise.

The static levels of ``eq9`` and ``pressure`` come from the breakaways: at each reversal
the largest friction in the new direction within the first :data:`BREAKAWAY_TRAVEL` of
travel (their mean per direction, or their straight line in p).  Stribeck's are the
zero-speed end of its curve, fitted with the rest.

Intervals are 95 % percentile intervals of a wild cluster bootstrap (Webb's six-point
weights): each replicate multiplies the residuals of a whole cluster by one random
weight and refits, so the residuals' correlation within a cluster (a stroke's, and a
file's: a session's offset, a pressure level's scatter about the law) is kept.  The
clusters are the FIT files where there are at least four, else the strokes.

The law is chosen on the HOLD samples (never fitted on): the simplest law, ``eq9``,
unless a richer one (in order ``stribeck``, ``pressure``) lowers the holdout's squared
error by more than the stroke-to-stroke noise: the 95 % interval of the gain, from a
bootstrap over the holdout strokes, must lie above zero.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from ..foreign import check_time_scale, increasing_time, read_with
from ..physics import friction_laws as fl
from ..physics.effects import stribeck_level, stribeck_weight
from ..physics import reference_rig
from ..recording import RecordingError
from .signals import SMOOTH, running_median, stroke_ids, velocity

#: The laws, simplest first (the order of the choice).
LAWS = ("eq9", "stribeck", "pressure")
FORMULAS = {
    "eq9": "F_f = sign(v) F_d + K_v v sliding; at rest -F_s_neg <= F_f <= F_s_pos (Eq. 9)",
    "stribeck": "F_f = sign(v) [F_d + (F_s(dir) - F_d) exp(-|v|/v_s)] + K_v v sliding; at rest -F_s_neg <= F_f "
                "<= F_s_pos",
    "pressure": "F_f = sign(v) (F_d0 + c_d p) + K_v v sliding; at rest -(F_s0_neg + c_s_neg p) <= F_f <= "
                "F_s0_pos + c_s_pos p",
}
#: Each fitted parameter's unit, spelled as :data:`boomfmi.units.UNITS` spells it.
PARAMETER_UNITS = {"A_eff": "m2", "F_0": "N", "F_d": "N", "F_d0": "N", "c_d": "N/Pa", "K_v": "N.s/m", "F_s_pos": "N",
                   "F_s_neg": "N", "v_s": "m/s", "F_s0_pos": "N", "F_s0_neg": "N", "c_s_pos": "N/Pa", "c_s_neg": "N/Pa"}
#: Travel after a reversal within which the breakaway peak is sought [m]: a seal's
#: pre-sliding travel is a fraction of a millimetre.
BREAKAWAY_TRAVEL = 1e-3
#: The FIT files' median pressures must span this fraction of the largest for A_eff (and
#: the pressure law) to be identified; otherwise A_eff is the nominal area.
PRESSURE_SPAN = 0.2
#: Bootstrap replicates of the intervals.
N_BOOT = 200
#: Fewest samples a run needs (a few strokes at 100 Hz).
MIN_SAMPLES = 200
_LOWER = {"A_eff": 0.0, "F_d": 0.0, "F_d0": 0.0, "F_s_pos": 0.0, "F_s_neg": 0.0, "K_v": 0.0}
#: A friction test's plausible ranges: the DAQ's sample spacing [s] (``foreign.check_time_scale``), the rod's largest
#: speed [m/s] (a cylinder moves at most a few m/s), its travel [m] (more than a
#: breakaway window's, at most a long stroke).  Beyond them, the map's unit (or
#: column) of t or x is wrong, and :func:`check_plausible_run` names the entry.
DT_RANGE = (1e-6, 1.0)
MAX_SPEED = 5.0
TRAVEL_RANGE = (2.0 * BREAKAWAY_TRAVEL, 5.0)


@dataclass
class Run:
    """One friction test (or part of one) ready to fit: SI units, p gauge."""
    path: Path
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    p: np.ndarray
    F: np.ndarray
    rest: np.ndarray          #: |v| below the velocity's noise
    stroke: np.ndarray        #: stroke number of each sample
    v_rest: float
    lines: np.ndarray         #: line numbers in the file
    smooth: float = SMOOTH    #: the velocity's bandwidth [s]
    part: str = ""            #: "" (whole file), "first half", "second half" of the strokes
    digest: str = ""          #: the file's content hash (a holdout must not be a FIT file)

    @property
    def name(self) -> str:
        return self.path.name + (f" ({self.part} of the strokes)" if self.part else "")

    def subset(self, mask: np.ndarray, part: str) -> "Run":
        return replace(self, t=self.t[mask], x=self.x[mask], v=self.v[mask], p=self.p[mask], F=self.F[mask],
                       rest=self.rest[mask], stroke=self.stroke[mask], lines=self.lines[mask], part=part)


def load_run(path, opts: dict, smooth: float = SMOOTH, P_atm: float = reference_rig.P_atm) -> Run:
    """Read a friction test through the map options ``opts`` (``foreign.read_options``:
    it needs t, x, F and p_gauge or p_abs) and derive its velocity and strokes."""
    table = read_with(path, opts, P_atm)
    missing = [n for n in ("t", "x", "F") if not table.has(n)]
    if not (table.has("p_gauge") or table.has("p_abs")):
        missing.append("p_gauge (or p_abs)")
    if missing:
        raise RecordingError(table.path, f"a friction test needs t, x, p_gauge (or p_abs) and F; the column map "
                                         f"gives no {', '.join(missing)}")
    t = increasing_time(table)
    if len(t) < MIN_SAMPLES:
        raise RecordingError(table.path, f"{len(t)} samples: a friction test needs at least {MIN_SAMPLES}")
    x, F, p = table.columns["x"], table.columns["F"], table.gauge()
    check_time_scale(table, t, "friction test", DT_RANGE)
    v, v_rest = velocity(t, x, smooth)
    check_plausible_run(table, t, x, v)
    rest = np.abs(v) < v_rest
    if np.count_nonzero(v > v_rest) < 10 or np.count_nonzero(v < -v_rest) < 10:
        raise RecordingError(table.path, "the rod does not move both ways: a friction test needs strokes in "
                                         "both directions")
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return Run(Path(path), t, x, v, p, F, rest, stroke_ids(v, rest), v_rest, table.lines, smooth, digest=digest)


def check_plausible_run(table, t: np.ndarray, x: np.ndarray, v: np.ndarray) -> None:
    """RecordingError where the rod's motion cannot be a cylinder's: faster than
    :data:`MAX_SPEED` or a travel outside :data:`TRAVEL_RANGE` (x in m where the file
    has mm, or x and p swapped: a pressure taken for a position barely moves),
    naming the map entry of x and the option that fixes it."""
    label = next((e.label for e in table.entries if e.name == "x"), None)
    speed, travel = float(np.max(np.abs(v))), float(np.ptp(x))
    if speed > MAX_SPEED or travel > TRAVEL_RANGE[1]:
        raise RecordingError(table.path, f"the rod travels {travel:.3g} m at up to {speed:.3g} m/s: a cylinder's rod "
                                         f"moves at most a few m/s ({MAX_SPEED:g}) over a stroke of at most "
                                         f"{TRAVEL_RANGE[1]:g} m; is x in mm where the map says otherwise? Give its "
                                         f"unit in --map (map entry {table.entry_text('x')}, e.g. x=COLUMN:mm)",
                             column=label)
    if travel < TRAVEL_RANGE[0]:
        raise RecordingError(table.path, f"the rod travels {1e3 * travel:.3g} mm in all: a friction test strokes it "
                                         f"over more than {1e3 * TRAVEL_RANGE[0]:g} mm; does the map's x (map entry "
                                         f"{table.entry_text('x')}) name the position's column, not the pressure's "
                                         f"(x and p swapped?), and in its unit? Fix it in --map", column=label)


def check_friction_signs(fits: dict, runs: list) -> None:
    """ValueError where a fitted law gives a negative friction level (a Coulomb or
    static level below zero anywhere over the FIT files' pressures): no seal pushes
    the rod the way it moves, so the file's columns or units are not what the map says."""
    p = np.concatenate([r.p for r in runs])
    lo, hi = float(np.min(p)), float(np.max(p))
    bad = []
    for law, fit in fits.items():
        P = fit.params
        if law == "pressure":
            for name, c in (("F_d0", "c_d"), ("F_s0_pos", "c_s_pos"), ("F_s0_neg", "c_s_neg")):
                low = min(P[name] + P[c] * lo, P[name] + P[c] * hi)
                if low < 0:
                    bad.append(f"{law}: {name} + {c} p = {low:.3g} N at p = {(lo if P[c] > 0 else hi) / 1e5:.3g} bar")
        else:
            bad += [f"{law}: {k} = {P[k]:.3g} N" for k in ("F_d", "F_s_pos", "F_s_neg") if k in P and P[k] < 0]
    if bad:
        raise ValueError(f"negative friction ({'; '.join(bad)}): a friction cannot be negative (a seal never "
                         f"pushes the rod the way it moves); check the --map: the columns of x, p and F and "
                         f"their units (x in mm, p in bar, F in N), the pressure's reference (p_gauge or p_abs) and the force's sign (a load cell that reads a push as negative)")


def split_strokes(run: Run) -> tuple[Run, Run]:
    """The run's first and second half of its strokes."""
    n = int(run.stroke.max()) + 1
    if n < 4:
        raise RecordingError(run.path, f"{n} strokes: splitting into halves needs at least 4")
    first = run.stroke < n // 2
    return run.subset(first, "first half"), run.subset(~first, "second half")


@dataclass
class Data:
    """Runs side by side: their samples concatenated, with each sample's file and
    stroke (numbered across runs) and the breakaway windows."""
    runs: list[Run]
    p: np.ndarray
    v: np.ndarray
    F: np.ndarray
    rest: np.ndarray
    file: np.ndarray
    stroke: np.ndarray
    windows: list[tuple[np.ndarray, int]] = field(default_factory=list)   #: (indices, direction)
    turning: np.ndarray | None = None     #: within the velocity's reach (3 bandwidths) of a reversal

    @property
    def sliding(self) -> np.ndarray:
        return ~self.rest

    @cached_property
    def settled(self) -> np.ndarray:
        """Sliding samples outside every breakaway window and away from the reversals
        (friction at its sliding level, velocity not smeared across a turn)."""
        m = ~self.rest & ~self.turning
        for idx, _ in self.windows:
            m[idx] = False
        return m

    def __len__(self) -> int:
        return len(self.F)


def combine(runs: list[Run]) -> Data:
    """Concatenate runs, numbering strokes across them, and find every reversal's
    breakaway window."""
    offsets = np.cumsum([0] + [len(r.F) for r in runs])
    stroke_base = np.cumsum([0] + [int(r.stroke.max()) + 1 for r in runs])
    windows = []
    for k, r in enumerate(runs):
        windows += [(idx + offsets[k], d) for idx, d in _breakaway_windows(r)]
    return Data(runs, np.concatenate([r.p for r in runs]), np.concatenate([r.v for r in runs]),
                np.concatenate([r.F for r in runs]), np.concatenate([r.rest for r in runs]),
                np.concatenate([np.full(len(r.F), k) for k, r in enumerate(runs)]),
                np.concatenate([r.stroke + stroke_base[k] for k, r in enumerate(runs)]), windows,
                np.concatenate([_turning(r) for r in runs]))


def _turning(r: Run) -> np.ndarray:
    """Samples within three velocity bandwidths of a reversal (a stroke's change)."""
    turns = r.t[np.flatnonzero(np.diff(r.stroke)) + 1]
    if turns.size == 0:
        return np.zeros(len(r.t), dtype=bool)
    k = np.clip(np.searchsorted(turns, r.t), 1, len(turns) - 1) if len(turns) > 1 else np.zeros(len(r.t), int)
    near = np.minimum(np.abs(r.t - turns[k]), np.abs(r.t - turns[np.maximum(k - 1, 0)]))
    return near < 3.0 * r.smooth


def _breakaway_windows(r: Run):
    """Each reversal's samples from the turn until the rod has travelled
    BREAKAWAY_TRAVEL the new way, with the new direction."""
    xm = running_median(r.x)
    starts = np.flatnonzero(np.diff(r.stroke)) + 1
    out = []
    for s in starts:
        stop = s
        while stop < len(r.stroke) and r.stroke[stop] == r.stroke[s]:
            stop += 1
        d = 1 if np.median(r.v[s:stop]) > 0 else -1
        turn = s
        while turn > 0 and r.rest[turn - 1]:
            turn -= 1
        lo, hi = turn, s
        x0 = xm[turn - 1] if turn > 0 else xm[turn]
        while hi < stop and d * (xm[hi] - x0) <= BREAKAWAY_TRAVEL:
            hi += 1
        if hi - lo >= 2:
            out.append((np.arange(lo, hi), d))
    return out


# ---------------------------------------------------------------------------- fitting

@dataclass
class LawFit:
    law: str
    params: dict[str, float]
    rss: float = math.nan
    note: str = ""


def _mask(law: str, d: Data) -> np.ndarray:
    """The samples a law's sliding part is fitted on: Stribeck's all sliding ones (the
    low speeds after a reversal are its domain), the others' those past the breakaway
    windows (the Coulomb and viscous levels of settled sliding)."""
    return d.sliding if law == "stribeck" else d.settled


def _columns(law: str, d: Data):
    """The fitted samples' regressors of eq9 and pressure, by the parameter they carry."""
    m = _mask(law, d)
    v, p = d.v[m], d.p[m]
    s = np.sign(v)
    cols = {"A_eff": p, "F_0": np.ones_like(v)}
    if law == "eq9":
        cols["F_d"] = s
    elif law == "pressure":
        cols["F_d0"] = s
        cols["c_d"] = s * p
    else:
        raise ValueError(f"unknown friction law {law!r}: one of {', '.join(LAWS)}")
    cols["K_v"] = v
    return cols


def _solve(names: list[str], G: np.ndarray, b: np.ndarray, yy: float):
    """Bounded linear least squares from the normal equations ``G theta = b`` (``yy``:
    the target's sum of squares): (parameters, residual sum of squares)."""
    from scipy.optimize import lsq_linear
    scale = np.sqrt(np.diag(G))
    scale[scale == 0] = 1.0
    Gs = G / np.outer(scale, scale)
    bs = b / scale
    Gs[np.diag_indices_from(Gs)] *= 1.0 + 1e-12
    z = np.linalg.solve(Gs, bs)
    lower = np.array([_LOWER.get(n, -np.inf) for n in names])
    if np.any(z / scale < lower - 1e-12):
        L = np.linalg.cholesky(Gs)            # |L' z - L^-1 b|^2 is the objective less a constant
        z = lsq_linear(L.T, np.linalg.solve(L, bs), bounds=(lower * scale, np.full(len(names), np.inf)),
                       method="bvls").x
    rss = max(yy - 2.0 * float(z @ bs) + float(z @ Gs @ z), 0.0)
    return dict(zip(names, (float(v) for v in z / scale))), rss


def _linear_fit(cols: dict, y: np.ndarray, A_fixed: float | None):
    names = list(cols)
    if A_fixed is not None:
        y = y - A_fixed * cols["A_eff"]
        names.remove("A_eff")
    X = np.column_stack([cols[n] for n in names])
    params, rss = _solve(names, X.T @ X, X.T @ y, float(y @ y))
    return ({"A_eff": float(A_fixed), **params} if A_fixed is not None else params), rss


class _StribeckDesign:
    """Stribeck's normal equations at any v_s from products computed once: the columns
    p, 1, sign(v), v are fixed, and F_d's column sign(v) (1 - w) is sign(v) less the
    two directions' w columns."""
    NAMES = ["A_eff", "F_0", "F_d", "F_s_pos", "F_s_neg", "K_v"]

    def __init__(self, d: Data, y: np.ndarray, A_fixed: float | None):
        m = _mask("stribeck", d)
        v, p = d.v[m], d.p[m]
        self.v, self.s = v, np.sign(v)
        self.y = y[m] - (A_fixed * p if A_fixed is not None else 0.0)
        self.A_fixed = A_fixed
        self.F = np.column_stack([p, np.ones_like(v), self.s, v])
        self.GF = self.F.T @ self.F
        self.bF = self.F.T @ self.y
        self.yy = float(self.y @ self.y)
        # the final columns (NAMES' order) from [p, 1, s, v, w+, w-]
        T = np.zeros((6, 6))
        T[0, 0] = T[1, 1] = T[3, 5] = 1.0
        T[2, 2], T[4, 2], T[5, 2] = 1.0, -1.0, -1.0
        T[4, 3] = T[5, 4] = 1.0
        self.T = T

    def solve(self, v_s: float):
        w = self.s * stribeck_weight(self.v, v_s)          # sign(v) exp(-|v|/v_s)
        W = np.column_stack([np.where(self.v > 0, w, 0.0), np.where(self.v < 0, w, 0.0)])
        G = np.empty((6, 6))
        G[:4, :4] = self.GF
        G[4:, :4] = W.T @ self.F
        G[:4, 4:] = G[4:, :4].T
        G[4:, 4:] = W.T @ W
        b = np.concatenate([self.bF, W.T @ self.y])
        G, b = self.T.T @ G @ self.T, self.T.T @ b
        keep = [i for i, n in enumerate(self.NAMES) if not (n == "A_eff" and self.A_fixed is not None)]
        params, rss = _solve([self.NAMES[i] for i in keep], G[np.ix_(keep, keep)], b[keep], self.yy)
        if self.A_fixed is not None:
            params = {"A_eff": float(self.A_fixed), **params}
        return params, rss


def _fit_sliding(law: str, d: Data, F: np.ndarray, A_fixed: float | None, v_range: tuple[float, float]):
    if law != "stribeck":
        return _linear_fit(_columns(law, d), F[_mask(law, d)], A_fixed)
    from scipy.optimize import minimize_scalar
    design = _StribeckDesign(d, F, A_fixed)
    lo, hi = math.log10(v_range[0]), math.log10(v_range[1])

    def rss(logv):
        return design.solve(10.0 ** logv)[1]

    grid = np.linspace(lo, hi, 13)
    values = [rss(g) for g in grid]
    k = int(np.argmin(values))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    best = minimize_scalar(rss, bounds=(a, b), method="bounded", options={"xatol": 0.01}).x
    if values[k] < rss(best):
        best = grid[k]
    params, r = design.solve(10.0 ** best)
    params["v_s"] = float(10.0 ** best)
    return params, r


def _peaks(d: Data, F_f: np.ndarray):
    """Each breakaway's peak friction in its direction: (direction, p there, peak)."""
    out = []
    for idx, direction in d.windows:
        f = direction * F_f[idx]
        if len(f) >= 3:
            f = running_median(f, 3)
        k = int(np.argmax(f))
        out.append((direction, d.p[idx[k]], f[k]))
    return np.array(out).reshape(-1, 3)


def _static_levels(law: str, params: dict, d: Data, F: np.ndarray) -> str:
    """Set eq9's and pressure's static levels from the breakaways; a note where a
    direction has none (the static level is then the Coulomb level)."""
    peaks = _peaks(d, fl.measured_friction(F, d.p, params["A_eff"], params["F_0"]))
    note = ""
    for key, direction in (("pos", 1), ("neg", -1)):
        sel = peaks[peaks[:, 0] == direction] if len(peaks) else peaks
        if law == "eq9":
            if len(sel):
                params[f"F_s_{key}"] = float(np.mean(sel[:, 2]))
            else:
                params[f"F_s_{key}"] = params["F_d"]
                note += f"no breakaway in the {key} direction: F_s_{key} = F_d. "
        else:
            if len(sel) >= 3 and np.ptp(sel[:, 1]) > 0:
                c, level0 = np.polyfit(sel[:, 1], sel[:, 2], 1)
                params[f"F_s0_{key}"], params[f"c_s_{key}"] = float(level0), float(c)
            else:
                params[f"F_s0_{key}"], params[f"c_s_{key}"] = params["F_d0"], params["c_d"]
                note += f"too few breakaways in the {key} direction: its static level is the Coulomb level. "
    return note


def fit_law(law: str, d: Data, F: np.ndarray | None = None, A_fixed: float | None = None,
            v_range: tuple[float, float] | None = None) -> LawFit:
    """Fit one law (with A_eff unless ``A_fixed`` is given, and F_0) to the data's
    force ``F`` (default: the measured one)."""
    F = d.F if F is None else F
    if v_range is None:
        v_range = stribeck_range(d)
    params, rss = _fit_sliding(law, d, F, A_fixed, v_range)
    note = _static_levels(law, params, d, F) if law in ("eq9", "pressure") else ""
    return LawFit(law, params, rss, note)


def stribeck_range(d: Data) -> tuple[float, float]:
    """The range of Stribeck velocities a fit can resolve [m/s]: from the rest
    threshold to the median sliding speed."""
    v_rest = max(r.v_rest for r in d.runs)
    speed = float(np.median(np.abs(d.v[d.sliding])))
    return max(v_rest, 1e-6), max(speed, 2.0 * max(v_rest, 1e-6))


def levels(law: str, params: dict, v, p):
    """The law's (F_s_pos, F_s_neg, F_d_pos, F_d_neg) at velocity ``v`` and pressure ``p``."""
    if law == "eq9":
        return params["F_s_pos"], params["F_s_neg"], params["F_d"], params["F_d"]
    if law == "stribeck":
        return (params["F_s_pos"], params["F_s_neg"],
                stribeck_level(v, params["F_d"], params["F_s_pos"], params["v_s"]),
                stribeck_level(v, params["F_d"], params["F_s_neg"], params["v_s"]))
    F_d = fl.pressure_level(p, params["F_d0"], params["c_d"])
    return (fl.pressure_level(p, params["F_s0_pos"], params["c_s_pos"]),
            fl.pressure_level(p, params["F_s0_neg"], params["c_s_neg"]), F_d, F_d)


def friction(law: str, params: dict, v, p, F_drive):
    """The law's friction [N] at velocity ``v`` (0 at rest), pressure ``p``, drive
    ``F_drive`` (the friction the measured force shows, balanced at rest)."""
    F_s_pos, F_s_neg, F_d_pos, F_d_neg = levels(law, params, v, p)
    return fl.seal_friction(v, F_drive, F_s_pos, F_s_neg, F_d_pos, F_d_neg, params["K_v"], params["K_v"])


def predict(fit: LawFit, d: Data, F: np.ndarray | None = None) -> np.ndarray:
    """The rod force [N] the law predicts at every sample: p A_eff + F_0 + friction, the
    samples at rest taking Eq. 9's rule (friction balances the measured drive up to the
    static level)."""
    F = d.F if F is None else F
    P = fit.params
    drive = fl.measured_friction(F, d.p, P["A_eff"], P["F_0"])
    v = np.where(d.rest, 0.0, d.v)
    return d.p * P["A_eff"] + P["F_0"] + friction(fit.law, P, v, d.p, drive)


# ---------------------------------------------------------------------------- intervals

WEBB = np.array([-math.sqrt(1.5), -1.0, -math.sqrt(0.5), math.sqrt(0.5), 1.0, math.sqrt(1.5)])


def clusters(d: Data) -> tuple[np.ndarray, str]:
    """The bootstrap's clusters: the files where there are at least four, else strokes."""
    if len(d.runs) >= 4:
        return d.file, "files"
    return d.stroke, "strokes"


def bootstrap(fit: LawFit, d: Data, A_fixed: float | None, n_boot: int = N_BOOT, seed: int = 0) -> dict:
    """95 % intervals of every parameter by the wild cluster bootstrap."""
    rng = np.random.default_rng(seed)
    F_hat = predict(fit, d)
    resid = d.F - F_hat
    cl, _ = clusters(d)
    ids, inverse = np.unique(cl, return_inverse=True)
    v_range = stribeck_range(d)
    draws = {k: [] for k in fit.params}
    for _ in range(n_boot):
        w = rng.choice(WEBB, size=len(ids))
        F_star = F_hat + w[inverse] * resid
        f = fit_law(fit.law, d, F_star, A_fixed, v_range)
        for k in draws:
            draws[k].append(f.params.get(k, math.nan))
    return {k: [float(np.nanpercentile(v, 2.5)), float(np.nanpercentile(v, 97.5))] for k, v in draws.items()}


# ---------------------------------------------------------------------------- scoring, choice

def stroke_sse(fit: LawFit, d: Data) -> tuple[np.ndarray, np.ndarray]:
    """Each stroke's sum of squared force errors [N^2] and sample count."""
    r2 = (d.F - predict(fit, d)) ** 2
    ids, inverse = np.unique(d.stroke, return_inverse=True)
    return np.bincount(inverse, weights=r2), np.bincount(inverse).astype(float)


def compare(simple: LawFit, rich: LawFit, hold: Data, n_boot: int = 2000, seed: int = 1) -> dict:
    """How much the richer law lowers the holdout's mean squared error [N^2], with the
    95 % interval of a bootstrap over the holdout strokes; it beats the simpler where
    that interval lies above zero."""
    sse_s, n = stroke_sse(simple, hold)
    sse_r, _ = stroke_sse(rich, hold)
    gain = float((sse_s.sum() - sse_r.sum()) / n.sum())
    rng = np.random.default_rng(seed)
    k = rng.integers(0, len(n), size=(n_boot, len(n)))
    boot = (sse_s[k].sum(axis=1) - sse_r[k].sum(axis=1)) / n[k].sum(axis=1)
    lo, hi = float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))
    return {"simpler": simple.law, "richer": rich.law, "mse_gain_N2": gain, "ci95": [lo, hi], "beats": lo > 0}


def choose(fits: dict[str, LawFit], hold: Data) -> tuple[str, list[dict]]:
    """The simplest law unless a richer one beats it beyond noise (in LAWS' order)."""
    names = [n for n in LAWS if n in fits]
    chosen, steps = names[0], []
    for law in names[1:]:
        c = compare(fits[chosen], fits[law], hold)
        steps.append(c)
        if c["beats"]:
            chosen = law
    return chosen, steps


def rmse(fit: LawFit, d: Data) -> float:
    return float(np.sqrt(np.mean((d.F - predict(fit, d)) ** 2)))


# ---------------------------------------------------------------------------- the bench

def pressure_span(runs: list[Run]) -> float:
    """How far the runs' median pressures spread, as a fraction of the largest."""
    med = np.array([np.median(r.p) for r in runs])
    top = float(np.max(np.abs(med)))
    return float(np.ptp(med) / top) if top > 0 else 0.0


def check_distinct(fit_runs: list[Run], hold_runs: list[Run]) -> None:
    """ValueError where a holdout is a FIT file (by content; its other half of the
    strokes is not)."""
    for h in hold_runs:
        for f in fit_runs:
            if h.digest == f.digest and not (h.part and f.part and h.part != f.part):
                raise ValueError(f"holdout {h.path} holds the same samples as the fit file {f.path}: a holdout "
                                 f"must be data the laws are not fitted on")


def bench_friction(fit_paths, hold_paths, area: float, opts: dict, split: bool = False,
                   smooth: float = SMOOTH, n_boot: int = N_BOOT, progress=None) -> dict:
    """Fit every law on the FIT files, score on the HOLD files (and, with ``split``, fit
    on the first half of each FIT file's strokes and also score on the second), choose
    one.  Returns the friction.json document (without plots)."""
    say = progress or (lambda text: None)
    if not (area > 0 and math.isfinite(area)):
        raise ValueError(f"--area {area!r}: give the piston's nominal area [m^2] > 0")
    if not fit_paths:
        raise ValueError("give at least one FIT file")
    if n_boot < 10:
        raise ValueError(f"--n-boot {n_boot}: give at least 10 bootstrap replicates")
    if not hold_paths and not split:
        raise ValueError("give --holdout HOLD... or --split-strokes: every law is scored on data it is not fitted on")
    fit_runs, hold_runs = [], []
    for path in fit_paths:
        run = load_run(path, opts, smooth)
        if split:
            first, second = split_strokes(run)
            fit_runs.append(first)
            hold_runs.append(second)
        else:
            fit_runs.append(run)
    hold_runs += [load_run(path, opts, smooth) for path in hold_paths]
    check_distinct(fit_runs, hold_runs)
    fit_d, hold_d = combine(fit_runs), combine(hold_runs)
    warnings = []
    span = pressure_span(fit_runs)
    A_fixed = None
    if span < PRESSURE_SPAN:
        A_fixed = area
        warnings.append(f"the FIT files' pressures span {100 * span:.0f} % of the largest (under "
                        f"{100 * PRESSURE_SPAN:.0f} %): A_eff cannot be told from F_0 and is the nominal --area; the "
                        f"pressure law needs FIT files at two or more pressures and is not fitted")
    laws = [law for law in LAWS if not (law == "pressure" and A_fixed is not None)]
    fits, doc_laws = {}, {}
    _, cluster_kind = clusters(fit_d)
    for law in laws:
        say(f"fitting {law}")
        fit = fit_law(law, fit_d, A_fixed=A_fixed)
        check_friction_signs({law: fit}, fit_runs)
        fits[law] = fit
        say(f"bootstrap of {law} ({n_boot} replicates)")
        intervals = bootstrap(fit, fit_d, A_fixed, n_boot)
        if A_fixed is not None:
            intervals["A_eff"] = [A_fixed, A_fixed]
        doc_laws[law] = {
            "formula": FORMULAS[law],
            "parameters": fit.params,
            "intervals": intervals,
            "units": {k: PARAMETER_UNITS[k] for k in fit.params},
            "n_parameters": len(fit.params) - (1 if A_fixed is not None else 0),
            "rmse_fit_N": rmse(fit, fit_d),
            "rmse_holdout_N": rmse(fit, hold_d),
        }
        if fit.note:
            doc_laws[law]["note"] = fit.note.strip()
        if abs(fit.params["A_eff"] / area - 1.0) > 0.25:
            warnings.append(f"{law}: A_eff = {fit.params['A_eff']:.4g} m^2 is {fit.params['A_eff'] / area:.2f} "
                            f"times the nominal --area {area:.4g} m^2: check the area and the force and pressure "
                            f"units")
    chosen, steps = choose(fits, hold_d)
    return {
        "fit_files": [r.name for r in fit_runs],
        "holdout_files": [r.name for r in hold_runs],
        "area_nominal_m2": area,
        "samples": {"fit": len(fit_d), "holdout": len(hold_d)},
        "pressures_bar": {"fit": sorted({round(float(np.median(r.p)) / 1e5, 2) for r in fit_runs}),
                          "holdout": sorted({round(float(np.median(r.p)) / 1e5, 2) for r in hold_runs})},
        "v_rest_m_s": max(r.v_rest for r in fit_runs + hold_runs),
        "smooth_s": smooth,
        "laws": doc_laws,
        "chosen": chosen,
        "choice": {"rule": "the simplest law (eq9, then stribeck, then pressure) unless a richer one lowers the "
                           "holdout's mean squared force error with a 95 % interval (bootstrap over the holdout "
                           "strokes) above zero", "comparisons": steps},
        "interval_method": f"95 % percentile intervals, wild cluster bootstrap ({n_boot} replicates, Webb "
                           f"weights, clusters: {cluster_kind})",
        "identifiability": "one Coulomb level for both directions: a direction difference of it is not "
                           "separable from F_0 (constant part) and A_eff (part proportional to p)",
        "warnings": warnings,
        "_data": (fits, fit_d, hold_d),
    }


__all__ = ["LAWS", "FORMULAS", "PARAMETER_UNITS", "BREAKAWAY_TRAVEL", "PRESSURE_SPAN", "N_BOOT", "MIN_SAMPLES",
           "DT_RANGE", "MAX_SPEED", "TRAVEL_RANGE", "Run", "load_run", "check_plausible_run", "check_friction_signs",
           "split_strokes", "Data", "combine", "LawFit", "fit_law", "stribeck_range", "levels", "friction", "predict",
           "WEBB", "clusters", "bootstrap", "stroke_sse", "compare", "choose", "rmse", "pressure_span",
           "check_distinct", "bench_friction"]
