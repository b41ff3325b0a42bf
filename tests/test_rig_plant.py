"""The virtual rig's plant (boomfmi.rig): baseline agreement with the monolithic
reference, reproducible noise, 12-bit quantisation, each effect of effects.md in its
documented direction, the contact model, and configuration errors that name the key."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from boomfmi import physics as ph
from boomfmi.experiments import paper_multistep
from boomfmi.model import Model
from boomfmi.model.reference import simulate_reference
from boomfmi.rig import RigConfig, Sample, VirtualRig, load_config
from boomfmi.rig import truth as rt
from boomfmi.rig.config import RIG_EFFECTS as EFFECTS
from boomfmi.rig.plant import ALPHA_LSB, P_LSB

ROOT = Path(__file__).resolve().parents[1]
QUIET = {"p_sigma": 0.0, "alpha_sigma": 0.0, "quantise": False}
P_ATM = ph.reference_rig.P_atm
L = ph.reference_rig.L


def run(cmd, duration, effects=None, noise=QUIET, **extra):
    """Step a rig ``duration`` [s] at 1 kHz under ``cmd(t)``; columns of samples and truth."""
    rig = VirtualRig(load_config({"effects": effects or {}, "noise": noise, **extra}))
    rows = []
    for k in range(int(round(duration * 1000))):
        s = rig.step(cmd(k * 1e-3))
        tr = rig.truth
        rows.append((s.t, s.p_a, s.p_b, s.alpha, s.f_ext, tr["p_a"] - P_ATM, tr["p_b"] - P_ATM,
                     tr["x"], tr["v"], tr["alpha"]))
    cols = "t p_a p_b alpha f_ext true_p_a true_p_b x v true_alpha".split()
    return dict(zip(cols, np.array(rows).T))


def const(u):
    return lambda t: u


# ------------------------------------------------------------------ baseline
def test_baseline_agrees_with_reference():
    profile = paper_multistep()
    ref = simulate_reference(Model(), profile, profile.duration, breakpoints=[1, 3, 4, 6, 7])
    rig = VirtualRig(load_config({"noise": QUIET}))
    tr = rig.truth
    got = {"x": [tr["x"]], "p_a": [tr["p_a"]], "p_b": [tr["p_b"]]}
    for k in range(len(ref) - 1):
        rig.step(profile(k * 1e-3)["u"])
        tr = rig.truth
        for name in got:
            got[name].append(tr[name])
    assert rig.t == pytest.approx(profile.duration)
    for name, values in got.items():
        r = ref[name].to_numpy()
        nrmse = np.sqrt(np.mean((np.array(values) - r) ** 2)) / (r.max() - r.min())
        assert nrmse < 0.01, f"{name}: NRMSE {nrmse:.4%}"
        assert nrmse < 0.001, f"{name}: NRMSE {nrmse:.4%} (expected ~0.01 %)"


def test_sample_fields_and_command_clipping():
    rig = VirtualRig()
    s0 = rig.measure()
    assert isinstance(s0, Sample) and s0.t == 0.0 and s0.x == 0.0
    s = rig.step(12.0)
    assert s.u_applied == 10.0 and s.t == pytest.approx(1e-3)
    assert rig.step(-3.0).u_applied == 0.0
    rig.step(2.0, dt=2e-3)
    assert rig.t == pytest.approx(4e-3)
    assert set(rig.truth) == {"p_a", "p_b", "x", "v", "alpha", "f_ext"}
    with pytest.raises(ValueError):
        rig.step(float("nan"))
    with pytest.raises(ValueError):
        rig.step(5.0, dt=0.0)


def test_step_size_independent():
    a = run(const(1.0), 0.3)
    rig = VirtualRig(load_config({"noise": QUIET}))
    for _ in range(150):
        rig.step(1.0, dt=2e-3)
    assert rig.truth["x"] == pytest.approx(a["x"][-1], abs=2e-5)


# --------------------------------------------------------------------- noise
def test_seed_reproducible():
    def samples(seed, n=300):
        rig = VirtualRig(load_config({"seed": seed}))
        return [rig.step(10.0 if k < 100 else 2.0) for k in range(n)]
    assert samples(3) == samples(3)
    assert samples(3) != samples(4)
    rig = VirtualRig(load_config({"seed": 3}))
    first = [rig.step(2.0) for _ in range(50)]
    rig.reset()
    assert [rig.step(2.0) for _ in range(50)] == first


def test_quantisation_steps_and_noise_level():
    assert P_LSB == pytest.approx(1e6 / 4096) and ALPHA_LSB == pytest.approx(math.pi / 4096)
    d = run(const(10.0), 1.0, noise={"p_sigma": 500.0, "alpha_sigma": 2e-4, "quantise": True})
    for name, lsb in (("p_a", P_LSB), ("p_b", P_LSB), ("alpha", ALPHA_LSB)):
        codes = d[name] / lsb
        np.testing.assert_allclose(codes, np.round(codes), atol=1e-6)
    held = d["p_b"][500:]               # chamber B filled, piston at its stop: constant truth
    assert np.ptp(d["true_p_b"][500:]) < 1.0
    assert np.std(held) == pytest.approx(math.hypot(500.0, P_LSB / math.sqrt(12)), rel=0.15)
    assert np.all(d["p_a"] >= 0.0)      # the 0 .. 10 bar gauge sensor saturates at 0
    raw = run(const(10.0), 0.2, noise={"p_sigma": 500.0, "alpha_sigma": 2e-4, "quantise": False})
    assert not np.allclose(raw["p_b"] / P_LSB, np.round(raw["p_b"] / P_LSB))


# ------------------------------------------------------------------- effects
def test_piston_leakage_pressures_creep_together():
    cmd = lambda t: 1.0 if t < 1.5 else 5.0
    base, leak = run(cmd, 3.0), run(cmd, 3.0, {"piston_leakage": {}})
    i, j = 1499, 2999                     # valve centred from 1.5 s
    gap = lambda d, k: d["true_p_a"][k] - d["true_p_b"][k]
    assert abs(gap(base, j) - gap(base, i)) < 100.0
    assert gap(leak, i) - gap(leak, j) > 1e5
    assert leak["true_p_b"][j] > leak["true_p_b"][i] + 1e5
    assert leak["x"][i] - leak["x"][j] > 1e-3 and base["x"][j] == base["x"][i]


def test_heat_transfer_pressure_drifts_after_valve_closes():
    cmd = lambda t: 10.0 if t < 0.08 else 5.0      # fill B quickly at the stop, then close
    base, heat = run(cmd, 1.0), run(cmd, 1.0, {"heat_transfer": {}})
    assert np.all(heat["x"] == 0.0)
    assert abs(base["true_p_b"][-1] - base["true_p_b"][99]) < 100.0
    drop = heat["true_p_b"][99] - heat["true_p_b"][-1]
    assert drop > 5e4                                 # the hot air cools at the walls
    assert np.all(np.diff(heat["true_p_b"][99:]) <= 1e-6)
    weak = run(cmd, 1.0, {"heat_transfer": {"h_w": 10.0}})
    assert 0.0 < weak["true_p_b"][99] - weak["true_p_b"][-1] < drop


def test_valve_dynamics_delays_pressure_rise():
    base, spool = run(const(1.0), 0.05), run(const(1.0), 0.05, {"valve_dynamics": {}})
    for k in (1, 2):                                # 2 and 3 ms after the step
        assert spool["true_p_a"][k] < 0.5 * base["true_p_a"][k]
    slow = run(const(1.0), 0.05, {"valve_dynamics": {"f_n": 60.0}})
    assert slow["true_p_a"][3] < spool["true_p_a"][3]
    assert spool["true_p_a"][-1] == pytest.approx(base["true_p_a"][-1], rel=0.1)


def test_valve_deadband_small_command_gives_no_motion():
    cmd = lambda t: 1.0 if t < 0.3 else 5.3
    base, dead = run(cmd, 1.6), run(cmd, 1.6, {"valve_deadband": {}})
    assert base["x"][-1] == 0.0                     # 5.3 V retracts the paper's valve
    assert dead["x"][-1] > 0.02
    assert np.ptp(dead["x"][1000:]) < 1e-5          # ... but not the overlapped spool
    assert rt.overlap_command(5.3, 0.4, 0.15) == pytest.approx(5.0, abs=0.01)


def test_stribeck_breakaway_then_lower_sliding_friction():
    base, stri = run(const(4.0), 0.6), run(const(4.0), 0.6, {"stribeck_friction": {}})
    i_b, i_s = np.argmax(base["x"] > 0.0), np.argmax(stri["x"] > 0.0)
    assert i_s > i_b                                  # higher breakaway: later start
    assert stri["true_p_a"][i_s] > base["true_p_a"][i_b] + 2e4
    # once sliding well above v_s, friction is back at the Coulomb level
    assert stri["v"][i_s + 250] == pytest.approx(base["v"][i_b + 250], rel=0.03)
    assert rt.stribeck_level(0.0, 140.0, 85.0, 0.01) == 140.0
    assert rt.stribeck_level(0.1, 140.0, 85.0, 0.01) == pytest.approx(85.0, abs=1.0)


def test_end_cushioning_exhaust_pressure_peaks_near_stroke_end():
    base, cush = run(const(1.0), 1.0), run(const(1.0), 1.0, {"end_cushioning": {}})
    near = lambda d: d["x"] > L - 0.012
    assert base["true_p_b"][near(base)].max() < 5e3
    assert cush["true_p_b"][near(cush)].max() > 3e4
    at = lambda d: np.argmax(d["x"] >= L - 0.001)
    assert cush["v"][at(cush)] < 0.9 * base["v"][at(base)]   # decelerated in the last mm
    # retracting: chamber A's exhaust is cushioned near x = 0
    cmd = lambda t: 1.0 if t < 1.0 else 10.0
    back = run(cmd, 1.6, {"end_cushioning": {}})
    k = np.argmax((back["t"] > 1.0) & (back["x"] == 0.0))
    assert back["true_p_a"][k] > 5e4


def test_sensor_lag_delays_every_channel():
    base, lag = run(const(1.0), 0.5), run(const(1.0), 0.5, {"sensor_lag": {}})
    np.testing.assert_array_equal(base["x"], lag["x"])        # the physics is untouched
    sl = slice(200, 450)                                      # steady extension
    assert np.all(lag["alpha"][sl] < lag["true_alpha"][sl])
    errors = [np.abs(lag["alpha"][sl] - lag["true_alpha"][sl.start - s:sl.stop - s]).mean()
              for s in range(0, 20)]
    assert int(np.argmin(errors)) == 8                        # delay 3 ms + tau 5 ms
    assert lag["p_a"][2] < 0.2 * base["p_a"][2]               # pressure rise seen later


def test_every_effect_together_runs():
    d = run(lambda t: 10.0 if t < 0.3 else (1.0 if t < 1.3 else 4.5), 2.0,
            {name: {} for name in EFFECTS})
    assert np.all(np.isfinite(d["x"])) and d["x"].max() > 0.05


# ------------------------------------------------------------------- contact
@pytest.mark.parametrize("stiffness, damping", [(2e4, 500.0), (5e5, 2000.0)])
def test_spring_contact_pushes_out_only_below_x_contact(stiffness, damping):
    x_c = 0.03
    contact = {"type": "spring", "x_contact": x_c, "stiffness": stiffness, "damping": damping}
    d = run(lambda t: 1.0 if t < 0.8 else 10.0, 3.0, contact=contact)
    below = d["x"] < x_c
    assert below.any() and (~below).any()
    assert np.all(d["f_ext"][below] < 0.0) and np.all(d["f_ext"][~below] == 0.0)
    assert np.all(d["x"] > 0.0)                               # the ground holds the boom
    # settled on the ground (no contact chatter), in the friction band of Eq. 9
    assert np.abs(d["v"][-200:]).max() < 1e-4
    rig = VirtualRig(load_config({"noise": QUIET, "contact": contact}))
    for k in range(3000):
        rig.step(1.0 if k < 800 else 10.0)
    tr = rig.truth
    phi = ph.phi_from_x(tr["x"])
    drive = ph.drive_force(tr["p_a"], tr["p_b"], phi, tr["f_ext"])
    assert abs(drive) <= ph.reference_rig.F_s * math.cos(phi) + 1e-6
    if stiffness > 1e5:
        assert x_c - tr["x"] < 2e-3                           # hard ground: little sinkage


def test_ramp_and_vibration_forces():
    ramp = {"type": "ramp", "start": 0.2, "rate": 1000.0, "max": 300.0, "sign": 1}
    d = run(const(5.0), 0.8, contact=ramp)
    assert np.all(d["f_ext"][d["t"] <= 0.2] == 0.0)
    assert d["f_ext"][399] == pytest.approx(200.0)            # t = 0.4 s
    assert d["f_ext"][-1] == pytest.approx(300.0)
    d = run(const(5.0), 0.5, contact={**ramp, "sign": -1})
    assert d["f_ext"][-1] == pytest.approx(-300.0)
    vib = {"type": "vibration", "amplitude": 20.0, "frequency": 25.0}
    d = run(const(5.0), 0.2, disturbance=vib)
    np.testing.assert_allclose(d["f_ext"], 20.0 * np.sin(2 * np.pi * 25.0 * d["t"]), atol=1e-9)


# ---------------------------------------------------------------- config
@pytest.mark.parametrize("config, key", [
    ({"efects": {}}, "efects"),
    ({"params": {"K_w": 1.0}}, "params.K_w"),
    ({"params": {"M": -1.0}}, "params.M"),
    ({"params": {"P_s": "high"}}, "params.P_s"),
    ({"effects": {"valve_dynamic": {}}}, "effects.valve_dynamic"),
    ({"effects": {"valve_dynamics": {"omega": 1.0}}}, "effects.valve_dynamics.omega"),
    ({"effects": {"valve_dynamics": {"f_n": -5.0}}}, "effects.valve_dynamics.f_n"),
    ({"effects": {"stribeck_friction": {"F_brk": 10.0}}}, "effects.stribeck_friction.F_brk"),
    ({"noise": {"sigma": 1.0}}, "noise.sigma"),
    ({"noise": {"quantise": "yes"}}, "noise.quantise"),
    ({"contact": {"type": "wall"}}, "contact.type"),
    ({"contact": {"type": "spring", "x_contact": 0.03}}, "contact.stiffness"),
    ({"contact": {"type": "spring", "x_contact": 0.03, "stiffness": 1e4, "k": 1}}, "contact.k"),
    ({"disturbance": {"type": "vibration", "amplitude": 1.0}}, "disturbance.frequency"),
    ({"seed": -1}, "seed"),
    ({"x0": 0.5}, "x0"),
])
def test_config_errors_name_the_key(config, key):
    with pytest.raises(ValueError, match=key.replace(".", r"\.")):
        load_config(config)


def test_config_sources_and_defaults(tmp_path):
    cfg = load_config(None)
    assert cfg == RigConfig() and cfg.effects == {} and cfg.contact is None
    assert 300.0 <= cfg.noise["p_sigma"] <= 800.0 and cfg.noise["quantise"] is True
    cfg = load_config({"effects": {"sensor_lag": {"tau": 0.004}, "valve_deadband": True,
                                   "heat_transfer": None}})
    assert cfg.effects["sensor_lag"] == {"delay": 0.003, "tau": 0.004}
    assert cfg.effects["valve_deadband"] == EFFECTS["valve_deadband"]
    assert "heat_transfer" not in cfg.effects
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"effects": {"piston_leak": {}}}))
    with pytest.raises(ValueError, match="effects.piston_leak"):
        load_config(path)
    assert VirtualRig(RigConfig(params={"M": 30.0})).config.params == {"M": 30.0}
    with pytest.raises(ValueError, match="params.M"):
        VirtualRig(RigConfig(params={"M": 0.0}))


def test_example_configs_load():
    files = sorted(f for f in (ROOT / "examples" / "rig").glob("*.json")
                   if not f.stem.startswith("excavator_"))    # the excavator's: tests/test_excavator_rig.py
    names = {f.stem for f in files}
    assert {"none", "contact_soft", "contact_hard", "contact_ramp", *EFFECTS} <= names
    for f in files:
        cfg = load_config(f)
        if f.stem in EFFECTS:
            assert set(cfg.effects) == {f.stem}
        rig = VirtualRig(cfg)
        for _ in range(20):
            rig.step(2.0)
        assert math.isfinite(rig.truth["x"])


# --------------------------------------------------------------- truth forms
@pytest.mark.parametrize("zeta", [0.5, 0.7, 1.0, 1.5])
def test_spool_transition_is_exact(zeta):
    from scipy.integrate import solve_ivp
    w = 2 * math.pi * 100.0
    sol = solve_ivp(lambda t, s: [s[1], w * w * (1.0 - s[0]) - 2 * zeta * w * s[1]],
                    (0, 2.5e-4), [5.0, 30.0], rtol=1e-11, atol=1e-12)
    y, yd = rt.spool_step(5.0, 30.0, 1.0, rt.spool_transition(100.0, zeta, 2.5e-4))
    assert y == pytest.approx(sol.y[0, -1], abs=1e-8)
    assert yd == pytest.approx(sol.y[1, -1], rel=1e-7)


def test_overlap_and_cushion_forms_are_continuous():
    d, w = 0.4, 0.15
    e = np.linspace(0.0, 2.0, 2001)
    o = np.array([rt.overlap_opening(v, d, w) for v in e])
    assert np.all(o[e <= d - w] == 0.0) and np.allclose(o[e >= d + w], e[e >= d + w] - d)
    assert np.all(np.diff(o) >= 0.0) and np.max(np.abs(np.diff(o, 2))) < 1e-5
    assert rt.overlap_command(10.0, d, w) == 10.0 and rt.overlap_command(0.0, d, w) == 0.0
    g = [rt.cushion_engagement(s, 0.012, 0.001) for s in (0.0, 0.0105, 0.0115, 0.012, 0.02)]
    assert g[0] == g[1] == 1.0 and 0.0 < g[2] < 1.0 and g[3] == g[4] == 0.0
    assert rt.cushion_exhaust_area(4e-6, 5e-8, 0.0) == 4e-6
    assert rt.cushion_exhaust_area(4e-6, 5e-8, 1.0) == pytest.approx(5e-8, rel=1e-3)
