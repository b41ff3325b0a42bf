"""The command designs of issue 35's calibration benchmark (``experiments``): pseudo-random
steps (a maximum-length binary sequence, or multi-level) and an operator's joystick
(band-limited noise through a second-order low-pass, the stick's stops, its spring back
to the centre detent).  Each: within 0 .. 10 V, the same for the same seed, and the
property that makes it the design it is."""
from __future__ import annotations

import numpy as np
import pytest

from boomfmi.experiments import joystick, mls, pseudo_random_steps

T = np.arange(0.0, 12.0, 0.001)       # a DAQ's 1 kHz over the designs' 12 s


def sample(profile, ts=T):
    return np.array([profile(float(t))["u"] for t in ts])


@pytest.mark.parametrize("n", [5, 7, 9])
def test_mls_is_a_maximum_length_sequence(n):
    bits = mls(n, seed=11)
    period = 2 ** n - 1
    assert len(bits) == period and int(bits.sum()) == 2 ** (n - 1)       # balanced
    x = 2 * bits - 1
    off_peak = {int(np.dot(x, np.roll(x, k))) for k in range(1, period)}
    assert off_peak == {-1}                                              # white: two-valued
    assert not np.array_equal(mls(n, seed=12), bits)                     # another start
    with pytest.raises(ValueError, match="no maximum-length taps for a 8-bit"):
        mls(8)


def test_prbs_steps_are_binary_on_the_clock_and_deterministic():
    p = pseudo_random_steps(3, clock=0.12)
    u = sample(p)
    assert np.array_equal(u, sample(pseudo_random_steps(3, clock=0.12)))
    assert not np.array_equal(u, sample(pseudo_random_steps(4, clock=0.12)))
    levels = sorted(set(u))
    assert len(levels) == 2 and levels[0] + levels[1] == pytest.approx(10.0)
    assert 0.0 <= levels[0] and levels[1] <= 10.0 and 1.2 <= levels[1] - 5.0 <= 3.0
    changes = T[1:][np.diff(u) != 0]
    clocks = changes / 0.12
    assert np.allclose(clocks, np.round(clocks), atol=0.01)               # only on the clock
    assert np.allclose(changes, p.breakpoints, atol=1.5e-3)
    # the bits, one per clock, are a stretch of the 9-bit maximum-length sequence
    bits = (sample(p, np.arange(0.06, 12.0, 0.12)) < 5.0).astype(int)
    period = np.concatenate([mls(9, 0)] * 2)
    assert any(np.array_equal(period[k:k + len(bits)], bits) for k in range(511))


def test_multilevel_steps_use_every_level_within_bounds():
    u = sample(pseudo_random_steps(5, levels=5, amplitude=(4.0, 4.5)))
    levels = np.array(sorted(set(u)))
    assert len(levels) == 5 and np.allclose(np.diff(levels), np.diff(levels)[0])
    assert levels[2] == pytest.approx(5.0) and 0.0 <= levels[0] and levels[-1] <= 10.0
    with pytest.raises(ValueError, match="levels is a whole number >= 2"):
        pseudo_random_steps(levels=1)
    with pytest.raises(ValueError, match=r"amplitude \[V\] is a range within \(0, 5\]"):
        pseudo_random_steps(amplitude=(1.0, 6.0))


def test_joystick_is_band_limited_saturates_and_returns_to_centre():
    j = joystick(4, gain=0.9)
    u = sample(j)
    assert np.array_equal(u, sample(joystick(4, gain=0.9)))
    assert not np.array_equal(u, sample(joystick(5, gain=0.9)))
    assert u.min() >= 0.5 - 1e-12 and u.max() <= 9.5 + 1e-12          # 5 -+ 5 gain
    assert np.mean(np.abs(u - 5.0) > 4.5 - 1e-9) > 0.01                 # held at the stick's stops
    # the controller's 50 Hz staircase: changes only every 20 ms
    changes = T[1:][np.diff(u) != 0] / 0.02
    assert np.allclose(changes, np.round(changes), atol=0.01)
    # let go, the spring brings it back to the detent: stretches of exactly 5 V over 0.2 s
    centre = np.concatenate(([0], (u == 5.0).astype(int), [0]))
    runs = np.diff(np.flatnonzero(np.diff(centre)))[::2] * 1e-3
    assert len(runs) >= 2 and runs.max() > 0.2
    # band-limited: nearly all the power below 3 Hz (corner 0.4 to 1.2 Hz), little above 6
    spec = np.abs(np.fft.rfft(u - u.mean())) ** 2
    f = np.fft.rfftfreq(len(u), 1e-3)
    assert spec[f < 3.0].sum() > 0.9 * spec.sum() and spec[f > 6.0].sum() < 0.02 * spec.sum()
    with pytest.raises(ValueError, match="joystick needs step > 0 s, 0 < gain <= 1"):
        joystick(gain=1.5)


# ----------------------------------------------------------------------------- the calibration benchmark
# (benchmarks/diagnosis_blind.py and the hybrid rig's effect variants it draws)
import hashlib  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def blind():
    spec = importlib.util.spec_from_file_location("diagnosis_blind", ROOT / "benchmarks" / "diagnosis_blind.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("diagnosis_blind", mod)
    spec.loader.exec_module(mod)
    return mod


def _digest(cases) -> str:
    def plain(v):
        if isinstance(v, float):
            return f"{v:.9g}"
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v
    return hashlib.sha256(json.dumps([plain(c) for c in cases], sort_keys=True).encode()).hexdigest()


#: the blind suite's first 60 cases (seed 16) as they were drawn before the calibration suite
BLIND_60 = "a50f377f00691696116a5cc4499ec53838b4716f45baca7c10aaf046735366e1"


def test_the_blind_cases_stay_and_the_calibration_cases_span_every_variant(blind):
    assert _digest([blind.draw_case(i, 16) for i in range(60)]) == BLIND_60
    cal = [blind.draw_calibration_case(i, 16) for i in range(60, 120)]
    assert {(n, e["form"]) for c in cal for n, e in c["effects"].items()} == set(blind.VARIANTS)
    assert {"slow_ramps", "prbs", "multilevel", "joystick"} <= {c["fit_design"] for c in cal}
    assert all(c["fit_design"] != c["hold_design"] for c in cal)
    with pytest.raises(ValueError, match="calibration suite's own cases begin at 60"):
        blind.draw_calibration_case(59, 16)


def test_brier_and_reliability_table(blind):
    probs = blind.sets_of({"valve_deadband + piston_leakage": 0.7, "none": 0.1, "unexplained": 0.2})
    assert probs[("piston_leakage", "valve_deadband")] == 0.7 and probs[()] == 0.1
    assert blind.brier(probs, ("piston_leakage", "valve_deadband")) == pytest.approx(0.09 + 0.01 + 0.04)
    assert blind.brier(probs, ("sensor_lag",)) == pytest.approx(0.49 + 0.01 + 0.04 + 1.0)   # not listed
    rows = [{"p_verdict": 0.95, "correct": k < 7} for k in range(10)] + [{"p_verdict": 0.6, "correct": True}]
    table = blind.reliability(rows)
    top = table[-1]
    assert top["n"] == 10 and top["share_correct"] == 0.7 and top["gap_points"] == pytest.approx(-25.0)
    assert top["fails"] and not table[1]["fails"] and table[1]["n"] == 1            # a bin of 1 never fails
    assert blind.calibration_summary([{"p_verdict": None, "correct": True}]) is None  # "not reported"


def test_hybrid_rig_cushion_and_deadband_variants(blind):
    H = blind.hr
    from boomfmi.experiments import held
    prof = held([(1.0, 9.0), (1.5, 2.5)])

    def run(eff):
        return H.simulate(H.Plant(effects=eff, sensors=H.IDEAL_SENSORS), prof)
    same = run({"valve_deadband": {"form": "asymmetric", "d_ext": 0.3, "d_ret": 0.3, "w": 0.0}})
    assert np.array_equal(same.p_a_true, run({"valve_deadband": {"form": "overlap", "d": 0.3}}).p_a_true)
    # without the check valve the piston leaving the end draws its air through the needle
    x = {form: run({"end_cushioning": {"form": form, "l_c": 0.015, "A_n": 3e-7}}).x_true.to_numpy()
         for form in ("needle", "no_check")}
    i = int(1.4 * 1000)
    assert x["no_check"][i] < x["needle"][i] - 0.005
