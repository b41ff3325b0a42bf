"""The bench: friction laws and leak-down laws fitted to synthetic tests with known
parameters (recovered within 5 %), the choice of law, and a few of the real files."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from boomfmi.bench import run_friction
from boomfmi.bench.friction import bench_friction
from boomfmi.bench.leak import bench_leak, closing
from boomfmi.cli import main
from boomfmi.physics import effects as fx
from boomfmi.foreign import read_options
from boomfmi.physics import friction_laws as fl
from boomfmi.physics import leak_laws as ll
from boomfmi.physics.params import Gas

REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "cylinder-friction-leak"
needs_real = pytest.mark.skipif(not REAL.is_dir(), reason=f"the real data are not at {REAL}")
PRESET = read_options("zillen2021")
AREA = 4.909e-4
TRUE_PRESSURE = {"A_eff": 4.95e-4, "F_0": 1.5, "F_d0": 2.0, "c_d": 1.2e-5, "K_v": 200.0}
TRUE_EQ9 = {"A_eff": 4.95e-4, "F_0": 1.5, "F_d": 4.0, "K_v": 200.0}


def friction_test(path: Path, p_bar: float, law: dict, seed: int, strokes: int = 8) -> Path:
    """A synthetic friction test in the zillen2021 layout: a rod driven back and forth
    over 35 mm at a speed that changes from stroke to stroke, reversing within 0.1 s,
    the chamber at ``p_bar`` (sagging a little while the rod moves out), the rod force
    the pressure force, the offset and Eq. 9's sliding friction of ``law`` plus noise."""
    rng = np.random.default_rng(seed)
    dt, v_parts = 0.01, []
    v_prev = -0.01
    for k in range(strokes):
        direction = 1 if k % 2 == 0 else -1
        speed = rng.uniform(0.005, 0.016)
        ramp = np.linspace(v_prev, direction * speed, 11)[1:]
        hold = np.full(int((0.035 - 0.05 * abs(direction * speed)) / speed / dt), direction * speed)
        v_parts += [ramp, hold]
        v_prev = direction * speed
    v = np.concatenate(v_parts)
    n = len(v) + 15
    v = np.concatenate([np.zeros(15), v])
    t = np.arange(n) * dt + rng.uniform(-0.001, 0.001, n) * (np.arange(n) > 0)
    x = np.cumsum(v) * dt + 0.001
    p = p_bar * 1e5 - 3e3 * np.sign(v) + rng.normal(0, 200.0, n)
    F_d = law.get("F_d", 0.0) + law.get("F_d0", 0.0) + law.get("c_d", 0.0) * p
    F = p * law["A_eff"] + law["F_0"] + np.sign(v) * F_d + law["K_v"] * v + rng.normal(0, 0.3, n)
    x_meas = x + rng.normal(0, 1.5e-5, n)
    cols = np.column_stack([1e3 * t, np.full(n, 3.5), np.full(n, 1.5), np.full(n, 3.2), 1e3 * x_meas, p / 1e5, F])
    path.write_text("\n".join("\t".join(f"{c:.5f}" for c in row) for row in cols) + "\n")
    return path


def _tests_at(tmp_path, law, pressures, seed0):
    return [friction_test(tmp_path / f"s{seed0}_{p}bar.csv", p, law, seed0 + i) for i, p in enumerate(pressures)]


def within(value, true, rel=0.05):
    return abs(value - true) <= rel * abs(true)


def test_seal_friction_is_eq9_with_a_level_for_each_direction():
    v = np.array([0.0, 0.0, 0.0, 0.01, -0.01])
    drive = np.array([3.0, -6.5, 9.0, 0.0, 0.0])
    f = fl.seal_friction(v, drive, 5.0, 7.0, 4.0, 6.0, 100.0, 200.0)
    # at rest within -F_s_neg..F_s_pos the drive is balanced; beyond it, the Coulomb level
    assert f.tolist() == pytest.approx([3.0, -6.5, 4.0, 4.0 + 1.0, -6.0 - 2.0])
    assert fx.stribeck_level(0.0, 4.0, 6.0, 0.002) == 6.0
    assert fx.stribeck_level(0.002, 4.0, 6.0, 0.002) == pytest.approx(4.0 + 2.0 / math.e)
    assert fl.pressure_level(5e5, 2.0, 1.2e-5) == pytest.approx(8.0)
    assert fl.measured_friction(160.0, 3e5, 5e-4, 1.0) == pytest.approx(9.0)


def test_pressure_law_recovered_and_chosen(tmp_path):
    fit = _tests_at(tmp_path, TRUE_PRESSURE, (1, 3, 5, 7), 10)
    hold = _tests_at(tmp_path, TRUE_PRESSURE, (2, 4, 6), 20)
    doc = run_friction(fit, hold, AREA, PRESET, tmp_path / "out", n_boot=20)
    P = doc["laws"]["pressure"]["parameters"]
    for name, true in TRUE_PRESSURE.items():
        assert within(P[name], true), (name, P[name], true)
    assert doc["chosen"] == "pressure"
    assert doc["laws"]["pressure"]["rmse_holdout_N"] < 0.5 * doc["laws"]["eq9"]["rmse_holdout_N"]
    lo, hi = doc["laws"]["pressure"]["intervals"]["c_d"]
    assert lo <= P["c_d"] <= hi
    saved = json.loads((tmp_path / "out" / "friction.json").read_text())
    assert set(saved["laws"]) == {"eq9", "stribeck", "pressure"} and saved["chosen"] == "pressure"
    assert all("rmse_holdout_N" in L and "intervals" in L for L in saved["laws"].values())
    page = (tmp_path / "out" / "friction.html").read_text()
    assert "data:image/png;base64," in page and "Chosen law: pressure" in page
    assert (tmp_path / "out" / "friction_velocity.png").stat().st_size > 10_000


def test_eq9_law_recovered_and_a_richer_law_not_chosen(tmp_path):
    fit = _tests_at(tmp_path, TRUE_EQ9, (1, 4, 7), 30)
    doc = bench_friction(fit, [], AREA, PRESET, split=True, n_boot=10)
    P = doc["laws"]["eq9"]["parameters"]
    for name, true in TRUE_EQ9.items():
        assert within(P[name], true), (name, P[name], true)
    assert doc["chosen"] == "eq9"
    assert doc["laws"]["pressure"]["parameters"]["c_d"] * 7e5 < 0.2        # no pressure growth found


def test_friction_refuses_a_holdout_that_is_a_fit_file(tmp_path):
    fit = _tests_at(tmp_path, TRUE_EQ9, (1, 4), 40)
    copy = tmp_path / "copy.csv"
    copy.write_bytes(fit[0].read_bytes())
    with pytest.raises(ValueError, match="holds the same samples as the fit file"):
        bench_friction(fit, [copy], AREA, PRESET, n_boot=10)
    with pytest.raises(ValueError, match="give --holdout HOLD... or --split-strokes"):
        bench_friction(fit, [], AREA, PRESET, n_boot=10)


def leak_run(path: Path, law: str, size: float, V: float, p0_bar: float, seconds: float, dT0=0.0, tau=0.0,
             seed=0, plateau=0.0) -> Path:
    """A synthetic leak-down in the zillen2021-leak layout (ms with '.' grouping, bar
    gauge with 1 mbar steps), integrated with the physics' own leak laws."""
    from scipy.integrate import solve_ivp
    gas, P_atm = Gas(), 101325.0
    t = np.arange(0.0, seconds, 0.1)
    T0 = gas.T + dT0
    m0 = ll.air_mass(p0_bar * 1e5 + P_atm, T0, V, gas.R)

    def rhs(_, y):
        p = ll.chamber_pressure(y[0], y[1], V, gas.R)
        mdot = ll.leak_flow(law, size, p, y[1], P_atm, gas)
        return ll.leakdown_rates(y[0], y[1], mdot, tau, gas.T, gas.k)

    sol = solve_ivp(rhs, (0, t[-1]), [m0, T0], t_eval=t, rtol=1e-10, atol=[m0 * 1e-13, 1e-10])
    p = ll.chamber_pressure(sol.y[0], sol.y[1], V, gas.R) - P_atm
    if plateau:
        t = np.concatenate([np.arange(0.0, plateau, 0.1), t + plateau])
        p = np.concatenate([np.full(int(round(plateau / 0.1)), p[0]), p])
    rng = np.random.default_rng(seed)
    bar = np.round((p / 1e5 + rng.normal(0, 0.0015, len(p))) * 1000) / 1000
    rows = [f"{int(round(tk * 1e6)):,}".replace(",", ".") + f";3.7;{b:.3f}" for tk, b in zip(t, bar)]
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("law,size,dT0,tau,want", [
    ("laminar", 2.0e-10, 0.0, 0.0, "laminar"),
    ("orifice", 6.0e-8, 0.0, 0.0, "orifice"),
    ("laminar", 2.0e-11, 3.0, 4.0, "laminar_thermal"),
])
def test_leak_laws_recovered_and_chosen(tmp_path, law, size, dT0, tau, want):
    V = 1e-4
    path = leak_run(tmp_path / "run.csv", law, size, V, 7.5, 40.0, dT0, tau, plateau=3.0)
    doc = bench_leak([path], V, read_options("zillen2021-leak"))
    r = doc["runs"][0]
    assert abs(r["start_s"] - 2.9) < 0.25                  # the plateau's end found
    assert r["chosen"] == want
    assert within(r["size"]["value"], size), (r["size"], size)
    lo, hi = r["size"]["ci95"]
    assert lo <= r["size"]["value"] <= hi
    if tau:
        P = r["laws"][want]["parameters"]
        assert within(P["tau"], tau, 0.2) and within(P["dT0"], dT0, 0.2)


def test_leak_cli_writes_json_and_plot(tmp_path, capsys):
    path = leak_run(tmp_path / "run.csv", "laminar", 2.0e-10, 1e-4, 7.5, 20.0)
    assert main(["bench", "leak", str(path), "--volume", "0.1 L", "--preset", "zillen2021-leak",
                 "--out", str(tmp_path / "o")]) == 0
    assert "run.csv: laminar" in capsys.readouterr().out
    doc = json.loads((tmp_path / "o" / "leak.json").read_text())
    assert doc["volume_m3"] == pytest.approx(1e-4) and (tmp_path / "o" / "leak.png").stat().st_size > 5000
    assert main(["bench", "leak", str(path), "--volume", "0.1 bar", "--preset", "zillen2021-leak",
                 "--out", str(tmp_path / "o")]) == 1
    assert "--volume '0.1 bar': give a number in m**3" in capsys.readouterr().err


@needs_real
def test_real_seal_friction_grows_with_pressure(tmp_path):
    """NAPN, fitted on the first half of the strokes at 1, 3, 5, 7 bar and scored on
    the second: the pressure law wins, its Coulomb level rising by about 1.4 N per bar."""
    files = [REAL / "friction" / f"NAPN_{p}bar.csv" for p in (1, 3, 5, 7)]
    doc = bench_friction(files, [], AREA, PRESET, split=True, n_boot=10)
    assert doc["chosen"] == "pressure"
    P = doc["laws"]["pressure"]["parameters"]
    assert 1.0e-5 < P["c_d"] < 1.8e-5
    assert 0.98 < P["A_eff"] / AREA < 1.04
    assert doc["laws"]["pressure"]["rmse_holdout_N"] < 0.6 * doc["laws"]["eq9"]["rmse_holdout_N"]


@needs_real
def test_real_leak_down_closing_found():
    from boomfmi.foreign import read_with
    fast = read_with(REAL / "airchamber_leakage" / "Ultimaker_020.csv", read_options("zillen2021-leak"))
    i = closing(fast.columns["t"], fast.columns["p_gauge"])
    assert 4.6 < fast.columns["t"][i] < 5.0           # the supply's plateau ends at about 4.9 s
    slow = read_with(REAL / "airchamber_leakage" / "Aluminium.csv", read_options("zillen2021-leak"))
    assert closing(slow.columns["t"], slow.columns["p_gauge"]) == 0       # closed before the record
