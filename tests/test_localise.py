"""Localisation: where the baseline model and a recording disagree."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from boomfmi.compare import simulate_recording
from boomfmi.diagnose import REGIMES, regimes
from boomfmi.diagnose.localise import localise
from boomfmi.experiments import paper_multistep
from boomfmi.model import Model
from boomfmi.identify.preprocess import prepare
from boomfmi.recording import Recording
from boomfmi.rig.offline import run_offline


def localised(effect):
    cfg = {"seed": 4, "effects": {effect: {}} if effect else {}}
    prof = paper_multistep()
    rec = Recording(Path(f"{effect}.csv"), run_offline(cfg, prof, prof.duration))
    p = prepare(rec)
    sim = simulate_recording({}, rec)                 # the baseline at the rig's true parameters
    sim["p_a"] += rec.P_atm
    sim["p_b"] += rec.P_atm
    return p, localise(p, sim, Model())


def test_regimes_cover_the_experiment():
    p, _ = localised(None)
    reg = regimes(p, 0.06)
    assert set(reg) <= set(REGIMES)
    t = p.t
    assert reg[np.searchsorted(t, 1.0) + 5] == "valve_step"          # the step to 1 V at 1 s
    assert "steady_motion" in reg[(t > 1.3) & (t < 1.6)]
    assert reg[np.searchsorted(t, 2.8)] == "stroke_end"             # at x = L, valve pushing there


@pytest.mark.parametrize("effect, subsystem, channel_regimes", [
    ("valve_dynamics", "valve", {"valve_step"}),
    ("piston_leakage", "cylinder", {"steady_motion", "hold", "stroke_end"}),
    ("stribeck_friction", "boom_load", {"steady_motion", "breakaway", "stroke_end"}),
])
def test_the_gap_is_found_in_the_right_subsystem(effect, subsystem, channel_regimes):
    _, base = localised(None)
    _, loc = localised(effect)
    assert sum(loc.nrmse.values()) > 2 * sum(base.nrmse.values())     # a gap beyond the baseline's
    assert max(loc.subsystem_share, key=loc.subsystem_share.get) == subsystem
    top = loc.where[0]
    assert top["subsystem"] == subsystem and top["regime"] in channel_regimes
    assert top["windows"] and all(a < b for a, b in top["windows"])
    assert sum(w["share"] for w in loc.where) <= 1.0 + 1e-9
