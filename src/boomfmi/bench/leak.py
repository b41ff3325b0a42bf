"""Leak-down bench: fit a closed chamber's pressure decay with the leak laws, with and
without the thermal relaxation of freshly charged air, and say which law fits.

Each run is fitted on its own from the moment the chamber was closed (``start``, or
found: where a record begins on the supply's plateau, the last sample before the
fall; otherwise its first sample) with four laws (``physics.leak_laws``):

- ``laminar``, ``orifice``: isothermal (T = T_amb), parameters the start pressure p0 and
  the leak's size (conductance C [kg/(s Pa)], or effective area A [m^2]);
- ``laminar_thermal``, ``orifice_thermal``: the air starts ``dT0`` [K] above ambient
  and relaxes with time constant ``tau`` [s] (and cools as it expands while it leaks).
  ``tau`` is at most a third of the run: a relaxation that has not largely ended
  within the record cannot be told from a leak (both are slow exponentials).

Only ``size / V`` shows in a pressure curve, so the chamber volume ``V`` is an input.

Which law fits is decided by an information criterion that accounts for the residuals'
correlation: ``BIC = n_eff ln(RSS / n) + k ln n_eff``, with ``n_eff`` the independent
samples' worth of the best fit's residuals (``n / (1 + 2 sum rho_k)`` up to the lag where
their autocorrelation dies out), so a thermal variant (two parameters more) must lower
the residual variance by more than its parameters' worth, and a misfit's slow wiggles do
not count as thousands of independent points.  Each law's RMSE is also given against the
file's own noise (half the variance of its sample-to-sample differences, at least a
quantisation step's ``q^2/12``): ``rmse_over_noise`` near 1 is a fit down to the noise.
The laminar and orifice families are called indistinguishable where their best members'
criteria differ by less than :data:`DISTINCT` (on a decay of a few per cent the two laws
are the same exponential), and the laminar one is then taken.  A law whose fit ends on a
bound of p0, dT0 or tau (the optimiser pressing a parameter to its limit to make up for
a misfit) is not chosen.  Intervals are 95 % intervals from the Jacobian with the
residuals' correlation accounted for (a Newey-West sandwich whose lag reaches where the
residuals' autocorrelation has died out), so a fit's systematic misfit widens them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..foreign import check_time_scale, increasing_time, read_with, units
from ..physics import leak_laws as ll
from ..physics import reference_rig
from ..physics.params import Gas
from ..recording import RecordingError
from .signals import local_slope, running_median

LAWS = ("laminar", "orifice", "laminar_thermal", "orifice_thermal")
#: BIC difference below which the laminar and orifice families are not told apart.
DISTINCT = 10.0
#: Bandwidth of the decay rate that finds the closing [s].
CLOSING_SMOOTH = 0.5
#: Fewest samples after the chamber was closed.
MIN_SAMPLES = 30
#: Each fitted parameter's unit, spelled as :data:`boomfmi.units.UNITS` spells it.
PARAMETER_UNITS = {"p0": "Pa", "C": "kg/(s.Pa)", "A": "m2", "dT0": "K", "tau": "s"}
#: A leak-down run's plausible sample spacing and length [s] (a DAQ's rate; a second to
#: a week): beyond them the map's unit of t is not the file's (``foreign.check_time_scale``).
SPACING = (1e-6, 60.0)
DURATION = (1.0, 7 * 86400.0)


@dataclass
class LeakRun:
    path: Path
    name: str
    t: np.ndarray          #: time since the chamber was closed [s]
    p: np.ndarray          #: absolute pressure [Pa]
    start: float           #: the closing time in the file's own time [s]
    lines: np.ndarray


def parse_pressure(text: str) -> float:
    """A gauge pressure with its unit (``7.5 bar``, ``750 kPa``) in Pa, by pint."""
    import pint
    try:
        q = units().Quantity(text)
        return float(q.to("Pa").magnitude)
    except (pint.errors.PintError, ValueError, AttributeError, TypeError, AssertionError) as e:
        raise ValueError(f"--p-start {text!r}: give a pressure with its unit, e.g. '7.5 bar' ({e})") from None


def load_leak_run(path, opts: dict, P_atm: float = reference_rig.P_atm, p_start: float | None = None,
                  start: float | None = None) -> LeakRun:
    """Read a leak-down run (the map gives t and p_gauge, p_abs, or dp with
    ``p_start``, the gauge pressure [Pa] at the first sample) and cut it at the
    closing."""
    table = read_with(path, opts, P_atm)
    t = increasing_time(table)
    check_time_scale(table, t, "leak-down run", SPACING, DURATION)
    if table.has("p_gauge") or table.has("p_abs"):
        if p_start is not None:
            raise ValueError("--p-start is for a map with dp (a pressure change); this map gives the pressure itself")
        p = table.gauge() + P_atm
    elif table.has("dp"):
        if p_start is None:
            raise RecordingError(table.path, "the map gives dp, a pressure change: give --p-start, the gauge "
                                             "pressure at the first sample (e.g. '7.5 bar')")
        p = table.columns["dp"] - table.columns["dp"][0] + p_start + P_atm
    else:
        raise RecordingError(table.path, "a leak-down run needs t and p_gauge, p_abs or dp (with --p-start); "
                                         "the column map gives none of them")
    if start is None:
        i0 = closing(t, p)
    else:
        if not t[0] <= start < t[-1]:
            raise ValueError(f"--start {start} s lies outside the run {path} ({t[0]:g} to {t[-1]:g} s)")
        i0 = int(np.searchsorted(t, start))
    if len(t) - i0 < MIN_SAMPLES:
        raise RecordingError(table.path, f"{len(t) - i0} samples after the chamber was closed (line "
                                         f"{table.lines[i0]}): a leak-down fit needs at least {MIN_SAMPLES}")
    return LeakRun(Path(path), Path(path).name, t[i0:] - t[i0], p[i0:], float(t[i0]), table.lines[i0:])


def closing(t: np.ndarray, p: np.ndarray) -> int:
    """The sample at which the chamber was closed: where a record begins on the supply
    (a plateau, then a fall much steeper than the plateau's drift), the last sample
    before the fall; otherwise the first sample (the record begins closed)."""
    slope, gain = local_slope(t, running_median(p), CLOSING_SMOOTH)
    rate = -slope
    k = int(np.argmax(rate))
    r_max = float(rate[k])
    sigma = noise(p)
    before = t < t[k] - 4.0 * CLOSING_SMOOTH
    if r_max < 20.0 * sigma * float(np.median(gain)) or not np.any(before):
        return 0                              # no fall stands out of the rate's noise
    if float(np.mean(np.abs(rate[before]))) >= 0.1 * r_max:
        return 0                              # it falls from the start: closed before the record
    quiet = np.flatnonzero(rate[:k] < 0.05 * r_max)
    q = int(quiet[-1]) if quiet.size else 0
    plateau = float(np.median(p[np.flatnonzero(before)[-1] - min(20, int(np.sum(before)) - 1):q + 1]))
    held = np.flatnonzero(p[:k + 1] >= plateau - 3.0 * sigma)
    return int(held[-1]) if held.size else q


def noise(p: np.ndarray) -> float:
    """The pressure's white-noise standard deviation [Pa], from its differences."""
    d = np.diff(p)
    steps = np.abs(d[d != 0])
    q = float(steps.min()) if steps.size else 0.0
    return max(float(np.std(d)) / math.sqrt(2.0), q / math.sqrt(12.0), 1e-9 * float(np.mean(p)))


def simulate(law: str, theta: dict, t: np.ndarray, V: float, gas: Gas, P_atm: float) -> np.ndarray:
    """The law's absolute pressure [Pa] at times ``t`` [s] from p0 at t = 0."""
    from scipy.integrate import solve_ivp
    base = law.replace("_thermal", "")
    thermal = law.endswith("_thermal")
    T_amb, R, k = gas.T, gas.R, gas.k
    size = theta["C"] if base == "laminar" else theta["A"]
    T0 = T_amb + (theta["dT0"] if thermal else 0.0)
    tau = theta["tau"] if thermal else 0.0
    m0 = ll.air_mass(theta["p0"], T0, V, R)

    def rhs(_, y):
        m, T = y
        p = ll.chamber_pressure(m, T, V, R)
        mdot = ll.leak_flow(base, size, p, T, P_atm, gas)
        return ll.leakdown_rates(m, T, mdot, tau, T_amb, k)

    sol = solve_ivp(rhs, (0.0, float(t[-1])), [m0, T0], method="LSODA", t_eval=t, rtol=1e-8,
                    atol=[m0 * 1e-11, 1e-8])
    if not sol.success or sol.y.shape[1] != len(t):
        raise RuntimeError(f"the {law} leak-down did not integrate: {sol.message}")
    return ll.chamber_pressure(sol.y[0], sol.y[1], V, R)


def _size_guess(law: str, run: LeakRun, V: float, gas: Gas, P_atm: float) -> float:
    """The leak's size from the mean decay rate over the run."""
    rate = max(-(run.p[-1] - run.p[0]) / max(run.t[-1], 1e-9), 1e-9 * run.p[0])
    if law.startswith("laminar"):
        return rate * V / (gas.R * gas.T * max(run.p[0] - P_atm, 1.0))
    mdot = ll.leak_flow("orifice", 1.0, run.p[0], gas.T, P_atm, gas)       # per unit area
    return rate * V / (gas.R * gas.T) / max(mdot, 1e-30)


def _names(law: str) -> list[str]:
    size = "C" if law.startswith("laminar") else "A"
    return ["p0", size] + (["dT0", "tau"] if law.endswith("_thermal") else [])


def _theta(law: str, z: np.ndarray, size0: float) -> dict:
    """Parameters from the optimiser's vector: p0, size / size0, (dT0, log tau)."""
    names = _names(law)
    out = {"p0": float(z[0]), names[1]: float(z[1] * size0)}
    if len(z) > 2:
        out["dT0"], out["tau"] = float(z[2]), float(math.exp(z[3]))
    return out


def fit_run(law: str, run: LeakRun, V: float, gas: Gas, P_atm: float, sigma: float,
            start_from: dict | None = None) -> dict:
    """Least squares of one law on one run, with intervals; a thermal law also starts
    from its isothermal fit ``start_from`` (so it never fits worse)."""
    from scipy.optimize import least_squares
    size_name = _names(law)[1]
    size0 = _size_guess(law, run, V, gas, P_atm)
    span = float(run.t[-1])
    dt = float(np.median(np.diff(run.t)))
    z0s = [[run.p[0], 1.0]]
    lo = [run.p[0] - 1e5, 0.0]
    hi = [run.p[0] + 1e5, 1e4]
    if law.endswith("_thermal"):
        tau_max = span / 3.0
        z0s = [z0s[0] + [5.0, math.log(tau_max / 5.0)]]
        if start_from is not None:
            z0s.append([start_from["p0"], start_from[size_name] / size0, 0.0, math.log(2.0 * dt)])
        else:
            z0s.append(z0s[0][:2] + [1.0, math.log(tau_max / 30.0)])
        lo += [-30.0, math.log(dt)]
        hi += [150.0, math.log(tau_max)]

    def resid(z):
        return (simulate(law, _theta(law, z, size0), run.t, V, gas, P_atm) - run.p) / sigma

    best = None
    for z0 in z0s:
        z0 = np.clip(z0, np.array(lo) + 1e-9, np.array(hi) - 1e-9)
        r = least_squares(resid, z0, bounds=(lo, hi), x_scale="jac", diff_step=1e-6)
        if best is None or r.cost < best.cost:
            best = r
    theta = _theta(law, best.x, size0)
    res = best.fun * sigma
    rss = float(np.sum(res ** 2))
    n, k = len(run.t), len(best.x)
    ci = _intervals(law, best.x, best.jac * sigma, res, lo, hi, size0)
    names = _names(law)
    at_bound = [names[i] for i in range(len(best.x)) if i != 1 and
                min(best.x[i] - lo[i], hi[i] - best.x[i]) <= 1e-3 * (hi[i] - lo[i])]
    return {"parameters": theta, "intervals": ci, "units": {p: PARAMETER_UNITS[p] for p in theta}, "at_bound": at_bound,
            "rss_Pa2": rss, "rmse_Pa": math.sqrt(rss / n), "n_parameters": k, "_fit": run.p + res, "_resid": res}


def decorrelation_lag(res: np.ndarray) -> int:
    """The first lag at which the residuals' autocorrelation falls below 0.05 (at most
    a quarter of the run)."""
    r = res - res.mean()
    denom = float(r @ r) or 1.0
    for k in range(1, len(r) // 4):
        if float(r[:-k] @ r[k:]) / denom < 0.05:
            return k
    return len(r) // 4


def effective_samples(res: np.ndarray) -> float:
    """Independent samples' worth of correlated residuals: n / (1 + 2 sum rho_k) up to
    their decorrelation lag."""
    r = res - res.mean()
    denom = float(r @ r) or 1.0
    lag = decorrelation_lag(res)
    rho = sum(float(r[:-k] @ r[k:]) / denom for k in range(1, lag + 1))
    return float(min(len(r), max(2.0, len(r) / max(1.0 + 2.0 * rho, 1.0))))


def bic(rss: float, n: int, n_eff: float, k: int, sigma: float) -> float:
    """Bayesian information criterion of a fit with residual sum of squares ``rss``
    over ``n`` correlated samples worth ``n_eff`` independent ones; the residual
    variance is at least the file's own noise ``sigma^2``."""
    return n_eff * math.log(max(rss / n, sigma ** 2 * 1e-6)) + k * math.log(n_eff)


def _intervals(law, z, J, res, lo, hi, size0) -> dict:
    """95 % intervals from a Newey-West sandwich of the Jacobian (parameters at a
    bound: the interval reaches the bound)."""
    lag = decorrelation_lag(res)
    bread = np.linalg.pinv(J.T @ J)
    S = J * res[:, None]
    meat = S.T @ S
    for k in range(1, lag + 1):
        w = 1.0 - k / (lag + 1.0)
        G = S[k:].T @ S[:-k]
        meat += w * (G + G.T)
    cov = bread @ meat @ bread
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    names = _names(law)
    out = {}
    for i, name in enumerate(names):
        a, b = max(z[i] - 1.96 * se[i], lo[i]), min(z[i] + 1.96 * se[i], hi[i])
        if name == "tau":
            out[name] = [float(math.exp(a)), float(math.exp(b))]
        elif name in ("C", "A"):
            out[name] = [float(a * size0), float(b * size0)]
        else:
            out[name] = [float(a), float(b)]
    return out


def bench_leak(paths, V: float, opts: dict, P_atm: float = reference_rig.P_atm, gas: Gas = Gas(),
               p_start: float | None = None, start: float | None = None, progress=None) -> dict:
    """Fit every law to every run; the leak.json document (with ``_curves`` for the plot)."""
    say = progress or (lambda text: None)
    if not (V > 0 and math.isfinite(V)):
        raise ValueError(f"--volume {V!r}: give the chamber's volume [m^3] > 0")
    if not paths:
        raise ValueError("give at least one leak-down run")
    runs, curves = [], []
    for path in paths:
        run = load_leak_run(path, opts, P_atm, p_start, start)
        sigma = noise(run.p)
        laws = {}
        for law in LAWS:
            say(f"{run.name}: fitting {law}")
            base = laws.get(law.replace("_thermal", ""))
            laws[law] = fit_run(law, run, V, gas, P_atm, sigma, base["parameters"] if base else None)
        n_eff = effective_samples(min(laws.values(), key=lambda f: f["rss_Pa2"])["_resid"])
        for law, f in laws.items():
            f["rmse_over_noise"] = f["rmse_Pa"] / sigma
            f["bic"] = bic(f["rss_Pa2"], len(run.t), n_eff, f["n_parameters"], sigma)
            f.pop("_resid")
        eligible = [law for law in LAWS if not laws[law]["at_bound"]] or ["laminar", "orifice"]
        family = {f: min((law for law in eligible if law.startswith(f)), key=lambda law: laws[law]["bic"])
                  for f in ("laminar", "orifice")}
        gap = abs(laws[family["laminar"]]["bic"] - laws[family["orifice"]]["bic"])
        # told apart: the least criterion; not: the laminar law (linear, the model's piston_leakage)
        chosen = min(family.values(), key=lambda law: laws[law]["bic"]) if gap >= DISTINCT else family["laminar"]
        size_name = "C" if chosen.startswith("laminar") else "A"
        P = laws[chosen]["parameters"]
        mdot0 = ll.leak_flow(chosen.replace("_thermal", ""), P[size_name], P["p0"], gas.T, P_atm, gas)
        curves.append({"t": run.t, "p": run.p, "fits": {law: laws[law].pop("_fit") for law in LAWS}})
        runs.append({
            "file": run.name, "start_s": run.start, "samples": len(run.t), "duration_s": float(run.t[-1]),
            "p_start_bar_gauge": float((run.p[0] - P_atm) / 1e5),
            "drop_bar": float((run.p[0] - run.p[-1]) / 1e5), "noise_Pa": sigma, "effective_samples": n_eff,
            "laws": laws, "chosen": chosen,
            "delta_bic": {law: laws[law]["bic"] - laws[chosen]["bic"] for law in LAWS},
            "laminar_vs_orifice": ("indistinguishable" if gap < DISTINCT else
                                   ("laminar" if laws[family["laminar"]]["bic"] < laws[family["orifice"]]["bic"]
                                    else "orifice")),
            "thermal": chosen.endswith("_thermal"),
            "size": {"name": size_name, "value": P[size_name], "ci95": laws[chosen]["intervals"][size_name],
                     "unit": PARAMETER_UNITS[size_name]},
            "leak_flow_start_kg_s": float(mdot0),
        })
        if size_name == "A":
            runs[-1]["size"]["diameter_m"] = math.sqrt(4.0 * P["A"] / math.pi)
    return {"volume_m3": V, "P_atm_Pa": P_atm, "T_amb_K": gas.T, "runs": runs,
            "rule": f"least BIC = RSS/sigma^2 + k ln n with sigma the file's own noise, among the laws whose "
                    f"parameters (but the leak's size) lie within their bounds; laminar and orifice "
                    f"indistinguishable where their best variants' BIC differ by less than {DISTINCT:g}",
            "interval_method": "95 %, Jacobian sandwich with Newey-West weights up to the residuals' "
                               "decorrelation lag",
            "_curves": curves}


__all__ = ["LAWS", "DISTINCT", "CLOSING_SMOOTH", "MIN_SAMPLES", "PARAMETER_UNITS", "SPACING", "DURATION", "LeakRun",
           "parse_pressure", "load_leak_run", "closing", "noise", "simulate", "fit_run", "decorrelation_lag",
           "effective_samples", "bic", "bench_leak"]
