"""The solver's longest step where a recorded command ramps (``compare.MAX_STEP``).

The bound keeps a state at rest from striding over the command's moves; it is long
enough that it no longer sets the diagnosis's time (``benchmarks/solver_step.py``).
"""
from __future__ import annotations

import numpy as np
import pytest

from boomfmi.compare import MAX_STEP, simulate_recording
from boomfmi.identify.preprocess import noise_floor
from boomfmi.recording import read_recording, write_recording
from boomfmi.rig.offline import run_offline


def _pulse(t: float) -> dict:
    """The valve closed at its centre for 2 s (the state at rest: nothing for the
    step-size control to see), then a short ramp open to 6.2 V and back (0.24 s)."""
    return {"u": float(np.interp(t, [0.0, 2.0, 2.12, 2.24, 5.0], [5.0, 5.0, 6.2, 5.0, 5.0]))}


_pulse.duration = 5.0
_pulse.breakpoints = []


@pytest.fixture(scope="module")
def rested(tmp_path_factory):
    path = tmp_path_factory.mktemp("pulse") / "pulse.csv"
    rec = read_recording(write_recording(path, run_offline({"seed": 3}, _pulse, _pulse.duration)))
    fine = simulate_recording({}, rec, rtol=1e-7, max_step=5e-4)
    return rec, fine, noise_floor(rec)


def _error_over_noise(sim, fine, floor, channel: str) -> float:
    return float(np.sqrt(np.mean((sim[channel] - fine[channel]) ** 2)) / np.ptp(fine[channel]) / floor[channel])


def test_the_bounded_step_follows_a_short_ramp_after_a_rest_within_a_tenth_of_the_noise(rested):
    rec, fine, floor = rested
    sim = simulate_recording({}, rec, rtol=1e-5)          # the scoring tolerance, the default bound
    assert 2.0 * float(np.median(np.diff(rec.data["t"]))) < MAX_STEP
    for channel in ("p_a", "p_b"):
        assert _error_over_noise(sim, fine, floor, channel) < 0.1, channel


def test_without_the_bound_the_solver_strides_over_the_ramp_from_rest(rested):
    """The reason for the bound: from rest the step grows past the 0.24 s the valve is
    open, and the chambers never see it."""
    rec, fine, floor = rested
    sim = simulate_recording({}, rec, rtol=1e-5, max_step=np.inf)
    assert _error_over_noise(sim, fine, floor, "p_b") > 10.0


def _step(t: float) -> dict:
    """The valve opened to extend at 0.1 s, on to the stop."""
    return {"u": 1.447 if t >= 0.1 else 5.0}


_step.duration = 0.5
_step.breakpoints = [0.1]
#: a load of a microgram: its mechanical time constant M/K_v is 0.2 ps
MICROGRAM = {"K_v": 4650.5, "F_s": 203.5, "F_d": 53.0, "F_L": 235.7, "M": 1e-9}


def test_a_model_too_stiff_to_integrate_is_a_solver_error_naming_its_time_constant():
    """A load of a microgram (what a velocity fit that cannot tell M may leave) makes
    the steps collapse: scipy's dense output refuses them with a ValueError; the
    reference says what failed and why, as a SolverError.  A milligram integrates."""
    from boomfmi.model.boom import Model
    from boomfmi.model.reference import SolverError, simulate_reference
    from boomfmi.physics.params import Load
    with pytest.raises(SolverError, match=r"M/K_v is 2\.15e-13 s"):
        simulate_reference(Model(load=Load(**MICROGRAM)), _step, 0.3, breakpoints=_step.breakpoints, rtol=1e-4)
    ok = simulate_reference(Model(load=Load(**dict(MICROGRAM, M=1e-6))), _step, 0.3,
                            breakpoints=_step.breakpoints, rtol=1e-4)
    assert np.isfinite(ok["x"]).all() and ok["x"].iloc[-1] > 0.01


def test_a_candidate_the_solver_cannot_integrate_explains_nothing(tmp_path):
    """In the diagnosis such a candidate's error is infinite on every channel (it ranks
    last), not a crash of the whole diagnosis (tests/test_effect_plugins.py's
    speed_drag case met it through pressure_friction's re-identified load)."""
    from boomfmi.diagnose.attribute import errors
    rec = read_recording(write_recording(tmp_path / "step.csv", run_offline({"seed": 3}, _step, _step.duration)))
    e = errors(MICROGRAM, {"pressure_friction": {"c_sum": 1e-7}}, rec, rtol=1e-4)
    assert set(e) >= {"p_a", "p_b", "x"} and all(v == np.inf for v in e.values())
    assert all(np.isfinite(v) for v in errors(dict(MICROGRAM, M=2.0), {}, rec, rtol=1e-4).values())
