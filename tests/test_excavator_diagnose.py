"""Diagnosis per joint of excavator recordings (``diagnose/joints.py``: fitted on a fit
recording, scored on a holdout)."""
import json
from pathlib import Path

import numpy as np
import pytest

from boomfmi import experiments as E
from boomfmi.diagnose.joints import diagnose_joints
from boomfmi.rig import run_excavator_offline

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "rig"
SECONDS = 5.5        # the digging cycle up to the bucket's curl: every joint has moved


def _record(name):
    """A fit recording (excavator_excitation, 6 s) and a holdout (the digging cycle, another
    noise draw) of the rig ``examples/rig/<name>.json``."""
    cfg = json.loads((EXAMPLES / f"{name}.json").read_text())
    fit = run_excavator_offline(cfg, E.excavator_excitation(seed=1, duration=6.0), 6.0)
    hold = run_excavator_offline(dict(cfg, seed=cfg.get("seed", 0) + 1), E.digging_cycle(), SECONDS)
    return fit, hold


# (a leak on the arm named with its joint: tests/test_machine_diagnosis.py's pair across joints)


def test_effect_free_recording_gives_no_finding():
    """(The bucket's rod side falls a little below the atmosphere, where the rig's
    0 .. 10 bar gauge sensor reads 0: compared as sensed, not as a gap.)"""
    assert diagnose_joints(*_record("excavator_none")).verdict == []


def test_a_sensor_rail_is_no_gap_and_noise_is_no_rail():
    from boomfmi.compare import as_sensed
    rng = np.random.default_rng(0)
    model = np.linspace(-2e3, 5e4, 1000)
    measured = np.maximum(model, 0.0)                    # a gauge sensor's floor at 0 Pa
    assert np.array_equal(as_sensed(measured, model), measured)
    noisy = model + rng.normal(0.0, 300.0, model.size)   # noise does not repeat its extreme
    assert np.array_equal(as_sensed(noisy, model), model)
    top = np.minimum(model, 4e4)                         # and a rail at the top of the range
    assert np.array_equal(as_sensed(top, model), top)


# (the tip force where the informative joints determine it, on the soils: tests/test_excavator_identify_force.py)
