"""Across dates: each parameter's trend with its intervals, each effect's size, and
the flags that say a machine has changed.

Plain functions on the cases' summaries (:func:`boomfmi.campaign.case.run_case`), one
machine at a time.  The *reference* is the machine's first date with a judged case
(as commissioned, or as first seen); every later date is compared with it:

* **a parameter** (K_v, F_s, F_d, F_L, M) moves when its 95 % interval on that date and
  its interval on the reference date do not overlap (the date's lower end above the
  reference's upper end, or the reverse): the two estimates differ by more than both
  uncertainties together, which for intervals of similar width is about 2.8 standard
  errors of the difference.  A date on which identification says the data cannot tell
  the parameter (F_s where no start places it, any other whose interval is wider than
  half its value: ``identify.fit``'s warnings) is shown but neither compared nor used
  as the reference: the parameter's reference is its first date that tells it;
* **an effect** moves when the diagnosis names it in that date's verdict and either
  did not name it on the reference date (it appeared: the seal that starts to leak),
  or its size moved beyond its interval.  An effect's *size* is the holdout error it
  removes (``gain``: the summed NRMSE of the baseline less that with the effect, the
  diagnosis's own scale), and its interval is the diagnosis's noise margin on that
  date (``gap_threshold``: the smallest gap it tells from the recordings' noise); an
  effect that was not fitted (no gap) has size 0;
* **unexplained**: a verdict ``["unexplained"]`` on a machine whose reference had none.

A move is a flag when it persists: the next date that can be compared shows it again,
the same way (a change of the machine stays; an estimate that strays once does not),
or when it is on the newest date, where it is a *provisional* flag until the next
date confirms or clears it (:func:`persistent`).  The flag names the first date of the
move, the date that confirmed it, and every date that shows it.  (On unchanged
machines of the virtual fleet, single dates stray beyond the reference's interval in
about 1 of 170 parameter comparisons, mostly F_s, whose intervals from a few starts
are the least sure: ``docs/campaign.md``.)
"""
from __future__ import annotations

import math

from ..identify.fit import PARAMS
from .manifest import date_key


def _interval(p: dict | None) -> tuple[float, float, float] | None:
    """(value, lo, hi) of a summary's parameter, None where any is unknown or where
    identification said the data cannot tell it (``identified`` false)."""
    if not p or p.get("value") is None or p.get("identified") is False:
        return None
    lo, hi = p.get("ci95") or (None, None)
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    return float(p["value"]), float(lo), float(hi)


def parameter_move(at: dict | None, ref: dict | None) -> int:
    """+1 where the parameter's interval ``at`` lies wholly above the reference's
    ``ref``, -1 wholly below, 0 where they overlap or either is unknown."""
    a, r = _interval(at), _interval(ref)
    if a is None or r is None:
        return 0
    if a[1] > r[2]:
        return 1
    if a[2] < r[1]:
        return -1
    return 0


def effect_size(summary: dict, name: str) -> tuple[float, float, bool]:
    """(size, its interval's half-width, named in the verdict) of ``name`` on a date."""
    e = (summary.get("effects") or {}).get(name)
    gain = float(e["gain"]) if e else 0.0
    margin = e.get("margin") if e else None           # an excavator's effect: its joint's threshold
    margin = float(summary.get("gap_threshold") or 0.0) if margin is None else float(margin)
    return gain, margin, name in (summary.get("verdict") or [])


def effect_move(at: dict, ref: dict, name: str) -> bool:
    """Whether effect ``name`` moved from the reference date's summary ``ref`` to
    ``at``'s: named in ``at``'s verdict, and not in ``ref``'s or grown beyond both
    intervals."""
    g, m, named = effect_size(at, name)
    g0, m0, named0 = effect_size(ref, name)
    return named and (not named0 or g - m > g0 + m0)


def persistent(moves: list[tuple[str, int]]) -> dict | None:
    """The flag of a series of ``(date, move)`` (move: +1, -1, 0; only the dates on which
    the quantity could be compared, oldest first): the first move that the next date
    shows again in the same direction (``confirmed`` by that date), or else a move on
    the newest date, which no later date can confirm yet (``provisional``).  A move the
    next date does not show is a single outlier, not a flag.  None where there is no
    flag; else ``{"date", "direction", "status", "confirmed_by", "dates"}`` with
    ``dates`` every date that moves that way."""
    for i, (d, mv) in enumerate(moves):
        if not mv:
            continue
        last = i == len(moves) - 1
        if last or moves[i + 1][1] == mv:
            return {"date": d, "direction": mv, "status": "provisional" if last else "confirmed",
                    "confirmed_by": None if last else moves[i + 1][0],
                    "dates": [e for e, m in moves[i:] if m == mv]}
    return None


def machine_trends(cases: list[dict]) -> dict:
    """One machine's trends and flags from its cases (dicts with ``date``, ``status``
    and, where done, ``summary``), in any order."""
    cases = sorted(cases, key=lambda c: date_key(c["date"]))
    judged = [c for c in cases if c.get("status") == "done" and (c.get("summary") or {}).get("judgeable")]
    out = {"dates": [c["date"] for c in cases], "reference": judged[0]["date"] if judged else None,
           "parameter_reference": {}, "parameters": {}, "effects": {}, "flags": []}
    if not judged:
        return out
    ref = judged[0]["summary"]
    names = [k for k in PARAMS if any(k in (c["summary"].get("params") or {}) for c in judged)]
    # the whole excavator's per-joint parameters (K_v_arm, ..., payload), in their summaries' order
    names += list(dict.fromkeys(k for c in judged for k in (c["summary"].get("params") or {}) if k not in PARAMS))
    for k in names:
        own = [(c["date"], (c["summary"].get("params") or {}).get(k) or {}) for c in judged]
        # the reference: the first date on which identification could tell the parameter
        ref_date, ref_p = next(((d, p) for d, p in own if _interval(p) is not None), (None, None))
        out["parameter_reference"][k] = ref_date
        series, moves = [], []
        for d_, p in own:
            d = parameter_move(p, ref_p) if ref_date is not None and d_ != ref_date else 0
            series.append({"date": d_, "value": p.get("value"), "ci95": p.get("ci95"),
                           "identified": p.get("identified", True), "move": d})
            if ref_date is not None and date_key(d_) > date_key(ref_date) and _interval(p) is not None:
                moves.append((d_, d))
        out["parameters"][k] = series
        flag = persistent(moves)
        if flag:
            r, v = _interval(ref_p), _interval(dict(own)[flag["date"]])
            how = "rises" if flag["direction"] > 0 else "falls"
            out["flags"].append(dict(
                flag, kind="parameter", name=k, direction=how,
                text=f"{k} {how} from {r[0]:.4g} [{r[1]:.4g}, {r[2]:.4g}] ({ref_date}) to {v[0]:.4g} "
                     f"[{v[1]:.4g}, {v[2]:.4g}] ({flag['date']})" + _status(flag)))
    effect_names = sorted({n for c in judged for n in (c["summary"].get("effects") or {}) if "+" not in n}
                          | {n for c in judged for n in c["summary"].get("verdict") or [] if n != "unexplained"})
    for n in effect_names:
        series = []
        for c in judged:
            g, m, named = effect_size(c["summary"], n)
            mv = c is not judged[0] and effect_move(c["summary"], ref, n)
            params = ((c["summary"].get("effects") or {}).get(n) or {}).get("params")
            series.append({"date": c["date"], "gain": round(g, 6), "margin": round(m, 6), "in_verdict": named,
                           "params": params, "move": int(mv)})
        out["effects"][n] = series
        flag = persistent([(s["date"], s["move"]) for s in series[1:]])
        if flag:
            first = next(s for s in series if s["date"] == flag["date"])
            was = series[0]
            how = "appears" if not was["in_verdict"] else "grows"
            out["flags"].append(dict(
                flag, kind="effect", name=n, direction=how,
                text=f"{n} {how} on {flag['date']}: it removes {100 * first['gain']:.2f} % of the holdout error "
                     f"(+-{100 * first['margin']:.2f} %) against {100 * was['gain']:.2f} % "
                     f"(+-{100 * was['margin']:.2f} %) on {out['reference']}"
                     + (f"; fitted {_params(first['params'])}" if first["params"] else "") + _status(flag)))
    if ref.get("verdict") != ["unexplained"]:
        flag = persistent([(c["date"], int(c["summary"].get("verdict") == ["unexplained"])) for c in judged[1:]])
        if flag:
            out["flags"].append(dict(flag, kind="unexplained", name="unexplained", direction="appears",
                                     text=f"a gap no candidate effect explains from {flag['date']} on"
                                          + _status(flag)))
    out["flags"].sort(key=lambda f: (date_key(f["date"]), f["kind"], f["name"]))
    return out


def _status(flag: dict) -> str:
    return (f"; confirmed on {flag['confirmed_by']}" if flag["status"] == "confirmed" else
            "; provisional: the newest date, not yet confirmed by a later one")


def _params(p: dict) -> str:
    return ", ".join(f"{k} = {v:.3g}" for k, v in p.items())


__all__ = ["parameter_move", "effect_size", "effect_move", "persistent", "machine_trends"]
