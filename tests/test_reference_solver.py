"""The reference's own stepping loop (``model.reference.solve_segment``) is scipy's
``solve_ivp`` with LSODA, terminal events and dense output, to the bit: the same steps,
the same event roots, the same solution on any times (only the generic loop's overhead
is gone)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import boomfmi.model.reference as reference
from boomfmi.experiments import paper_multistep
from boomfmi.model import Model

G = 9.81


def _by_solve_ivp(fun, t0, t1, y0, rtol, atol, events, max_step):
    sol = solve_ivp(fun, (t0, t1), y0, method="LSODA", rtol=rtol, atol=atol, events=events or None,
                    max_step=max_step, dense_output=True)
    return float(sol.t[-1]), sol.y[:, -1], sol.status, sol.message, sol.sol


def test_a_thrown_ball_lands_where_solve_ivp_and_the_closed_form_put_it():
    """y'' = -g from y = 0 at 5 m/s up: the landing (y = 0 falling) at 2 v0 / g."""
    fun = lambda t, y: np.array([y[1], -G])
    land = lambda t, y: y[0] + 1e-12 if t > 0.0 else 1.0
    land.terminal, land.direction = True, -1
    times = np.linspace(0.0, 1.2, 121)
    ours = reference.solve_segment(fun, 0.0, 5.0, np.array([0.0, 5.0]), 1e-9, 1e-12, [land], np.inf)
    theirs = _by_solve_ivp(fun, 0.0, 5.0, np.array([0.0, 5.0]), 1e-9, 1e-12, [land], np.inf)
    assert ours[2] == theirs[2] == 1
    assert ours[0] == theirs[0] and ours[0] == pytest.approx(2 * 5.0 / G, abs=1e-8)
    assert np.array_equal(ours[1], theirs[1])
    assert np.array_equal(ours[4](times), theirs[4](times))
    # without an event it runs to the end
    ours = reference.solve_segment(fun, 0.0, 0.3, np.array([0.0, 5.0]), 1e-9, 1e-12, [], np.inf)
    assert ours[2] == 0 and ours[0] == 0.3 and ours[1][1] == pytest.approx(5.0 - G * 0.3)


def test_an_event_that_is_not_terminal_is_refused():
    event = lambda t, y: y[0]
    with pytest.raises(ValueError, match="terminal"):
        reference.solve_segment(lambda t, y: -y, 0.0, 1.0, np.array([1.0]), 1e-6, 1e-9, [event], np.inf)


@pytest.mark.parametrize("effects", [{}, {"valve_deadband": {"width": 0.3}, "piston_leakage": {"C": 2e-11}},
                                     {"end_cushioning": {"length": 0.01, "A_n": 1e-7}, "heat_transfer": {"h": 50.0}}],
                         ids=["plain", "deadband+leak", "cushion+heat"])
def test_the_boom_s_reference_is_the_same_to_the_bit_as_through_solve_ivp(monkeypatch, effects):
    """The paper's experiment (sticks, slips, the stops' events): every sample of every
    channel the same as the segments solved by ``solve_ivp``."""
    prof = paper_multistep()
    bps = [b for b in prof.breakpoints if b < 3.0]
    ours = reference.simulate_reference(Model(effects=effects), prof, 3.0, breakpoints=bps, rtol=1e-6)
    monkeypatch.setattr(reference, "solve_segment", _by_solve_ivp)
    theirs = reference.simulate_reference(Model(effects=effects), prof, 3.0, breakpoints=bps, rtol=1e-6)
    for col in ("p_a", "p_b", "x", "v", "alpha"):
        assert np.array_equal(ours[col].to_numpy(), theirs[col].to_numpy(), equal_nan=True), col


def test_a_model_whose_arithmetic_fails_is_a_solver_error_naming_the_time(monkeypatch):
    """The right-hand side runs on Python floats: a division by zero raises where NumPy's
    scalars gave inf.  The solve then fails as any solve that cannot go on does."""
    from boomfmi import physics as ph

    def broken(*args):
        raise ZeroDivisionError("float division by zero")
    monkeypatch.setattr(ph, "sliding_acceleration", broken)
    prof = paper_multistep()
    with pytest.raises(reference.SolverError, match=r"failed at t = 1\.0.* s: .*\(ZeroDivisionError"):
        reference.simulate_reference(Model(), prof, 2.0, breakpoints=[b for b in prof.breakpoints if b < 2.0])
