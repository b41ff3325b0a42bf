"""An effect's laws in diagnosis (``diagnose.attribute._fit_and_score``): which law is
kept.  The model's runs are replaced by closed forms of the parameters, so that only
the choice is tested (the laws themselves are tested against their ODEs in
test_effects.py and through the valve FMU in test_effect_options.py)."""
from __future__ import annotations

import math

import pytest

from boomfmi.diagnose import attribute as at

TAU, RATE = 0.005, 250.0


def _spool(effects):
    q = effects.get("valve_dynamics", {})
    return q.get("tau", 0.0), q.get("rate", 0.0)


def _install(monkeypatch, fit, hold):
    monkeypatch.setattr(at, "fit_cost", lambda values, effects, recs: fit(*_spool(effects)))
    monkeypatch.setattr(at, "mean_errors", lambda values, effects, recs, rtol=at.RTOL:
                        dict(zip(("x", "p_a", "p_b"), (hold(*_spool(effects)),) * 3)))


def test_a_speed_limit_is_found_where_the_lag_alone_bends_away_from_it(monkeypatch):
    """The truth is a slow spool with a speed limit (tau 5 ms, 250 V/s).  The lag alone
    fits best at a much slower tau (it mimics the limit), and a limit screened beside
    that lag finds nothing; the wider law screened afresh finds the truth's valley."""
    def fit(tau, rate):
        if tau <= 0.0:
            return 1.0
        if rate <= 0.0:                               # the lag alone: best near 14 ms
            return 0.02 + (math.log(tau / 0.014)) ** 2
        return (math.log(tau / TAU)) ** 2 + (math.log(rate / RATE)) ** 2 + 1e-4
    _install(monkeypatch, fit, lambda tau, rate: fit(tau, rate))
    name, fx, cost, after, _, told = at._fit_and_score(("valve_dynamics", {}, [None], [None], None, 1.0))
    q = fx["valve_dynamics"]
    assert q["rate"] == pytest.approx(RATE, rel=0.15) and q["tau"] == pytest.approx(TAU, rel=0.15)
    assert cost < 0.01


def test_a_wider_law_the_holdout_does_not_bear_out_is_not_kept(monkeypatch):
    """Slow ramps never reach the spool's speed limit: a limit fitted on them bends to
    whatever else they miss (a slightly lower fit error), and on a holdout of steps it
    is far worse than the lag alone.  The lag alone is kept."""
    def fit(tau, rate):
        base = (math.log(max(tau, 1e-9) / TAU)) ** 2 + 1e-3
        return base - (5e-4 if 0.0 < rate < 60.0 else 0.0)     # a low limit bends to a misfit
    def hold(tau, rate):
        return 0.01 + (math.log(max(tau, 1e-9) / TAU)) ** 2 + (0.3 if 0.0 < rate < 100.0 else 0.0)
    _install(monkeypatch, fit, hold)
    name, fx, cost, after, _, told = at._fit_and_score(("valve_dynamics", {}, [None], [None], None, 1.0))
    assert set(fx["valve_dynamics"]) == {"tau"}
    assert after["p_a"] < 0.05


def test_a_wider_law_the_holdout_bears_out_is_kept(monkeypatch):
    """Where the holdout is predicted better with the limit, the limit stays."""
    def fit(tau, rate):
        return (math.log(max(tau, 1e-9) / TAU)) ** 2 + (0.0 if 0.0 < rate < 400.0 else 1e-2) + 1e-4
    _install(monkeypatch, fit, fit)
    name, fx, cost, after, _, told = at._fit_and_score(("valve_dynamics", {}, [None], [None], None, 1.0))
    assert set(fx["valve_dynamics"]) == {"tau", "rate"}


def test_a_wider_law_is_grown_where_only_its_further_parameter_shows_something(monkeypatch):
    """A cushion without a check valve slows the return, which the needle's own law never
    touches: that law removes nothing, the check valve's area screened beside it removes
    most of the error, so the wider law is grown (and kept: the holdout bears it out)."""
    def cost(effects):
        q = effects.get("end_cushioning", {})
        if q.get("length", 0.0) <= 0.0:
            return 1.0
        a_c = q.get("A_c", 0.0)
        return 1.0 if a_c <= 0.0 else 0.1 + (math.log10(a_c / 1e-8)) ** 2 / 100.0
    monkeypatch.setattr(at, "fit_cost", lambda values, effects, recs: cost(effects))
    monkeypatch.setattr(at, "mean_errors", lambda values, effects, recs, rtol=at.RTOL:
                        dict.fromkeys(("x", "p_a", "p_b"), cost(effects)))
    name, fx, c, after, _, _ = at._fit_and_score(("end_cushioning", {}, [None], [None], None, 1.0))
    assert "A_c" in fx["end_cushioning"] and fx["end_cushioning"]["A_c"] < 1e-7
    assert c < 0.2


def test_a_speed_limit_the_fit_recordings_cannot_tell_is_told_by_the_holdout(monkeypatch):
    """Calibration case 64: slow ramps never reach the spool's speed limit, so the fit
    recordings' error is the same at every limit (not even a misfit to bend to); the
    holdout's steps show it.  The limit is told by the holdout, within what the fit
    recordings allow, and the candidate says so."""
    def fit(tau, rate):
        return (math.log(max(tau, 1e-9) / TAU)) ** 2 + 1e-4
    def hold(tau, rate):
        limit = (math.log(rate / RATE)) ** 2 if rate > 0.0 else 1.0
        return 0.002 + (math.log(max(tau, 1e-9) / TAU)) ** 2 + 0.05 * min(limit, 1.0)
    _install(monkeypatch, fit, hold)
    name, fx, cost, after, _, told = at._fit_and_score(("valve_dynamics", {}, [None], [None], None, 1.0))
    assert told == ["rate"]
    assert fx["valve_dynamics"]["rate"] == pytest.approx(RATE, rel=0.1)
    assert fx["valve_dynamics"]["tau"] == pytest.approx(TAU, rel=0.15)
    assert after["p_a"] < 0.01


def test_a_further_parameter_the_holdout_does_not_need_is_not_told(monkeypatch):
    """Where neither the fit recordings nor the holdout tell the limit (no step reaches
    it), the lag alone stays: a further parameter is told only where it removes GROW of
    what the narrower law leaves on the holdout."""
    def fit(tau, rate):
        return (math.log(max(tau, 1e-9) / TAU)) ** 2 + 1e-4
    def hold(tau, rate):
        return 0.01 + (math.log(max(tau, 1e-9) / TAU)) ** 2 + (0.3 if 0.0 < rate < 30.0 else 0.0)
    _install(monkeypatch, fit, hold)
    name, fx, cost, after, _, told = at._fit_and_score(("valve_dynamics", {}, [None], [None], None, 1.0))
    assert told == [] and set(fx["valve_dynamics"]) == {"tau"}


def test_a_value_the_fit_recordings_refuse_is_not_told(monkeypatch):
    """The holdout prefers a limit the fit recordings refuse (their error beyond SCREEN
    of the lag's there, though the limit screened over its range shows nothing at its
    points): it is not taken."""
    def fit(tau, rate):
        return (math.log(max(tau, 1e-9) / TAU)) ** 2 + 1e-4 + (1e-3 if 120.0 < rate < 180.0 else 0.0)
    def hold(tau, rate):
        limit = (math.log(rate / 150.0)) ** 2 if rate > 0.0 else 1.0
        return 0.002 + (math.log(max(tau, 1e-9) / TAU)) ** 2 + 0.05 * min(limit, 1.0)
    _install(monkeypatch, fit, hold)
    name, fx, cost, after, _, told = at._fit_and_score(("valve_dynamics", {}, [None], [None], None, 1.0))
    assert not 120.0 < fx["valve_dynamics"].get("rate", 0.0) < 180.0
    assert cost < 2e-4
