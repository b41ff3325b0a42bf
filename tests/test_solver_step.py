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
