"""Issue 34, item 1: an effect is one entry of the catalogue, carrying how it is fitted
(the generic output-error fit with the baseline load re-identified, unless the entry
supplies a faster one), and no code outside the catalogue, the effects' forms and the
virtual rig's own forms dispatches on an effect's name.  The stage functions take one
type (``catalogue.StageContext``)."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi import physics as ph
from boomfmi.model import catalogue
from boomfmi.model.catalogue import Effect, Parameter

SRC = Path(__file__).resolve().parents[1] / "src" / "boomfmi"
C_V = 5e-3            #: [N s/(m Pa)]: K_v grows by 500 N s/m per bar of summed gauge pressure
NOISE = {"p_a": 400.0, "p_b": 400.0, "alpha": 2e-5}     #: the recordings' sensor noise (Pa, rad)


def _pressure_viscous(load, v, p_a, p_b, q, model: catalogue.StageContext):
    """The viscous coefficient growing with the chambers' summed gauge pressure (issue 34's
    example): ``K_v + c_v p_sum``; floats or arrays."""
    return load._replace(K_v=load.K_v + q["c_v"] * ph.effects.seal_pressure(p_a, p_b, model.P_atm, "sum"))


#: a friction-stage entry with no fit of its own and no load law: the generic path fits it
PRESSURE_VISCOUS = Effect(
    "pressure_viscous", "boom_load", "friction",
    ((Parameter("c_v", "N.s/(m.Pa)", 1e-3, 3e-2, True, "c_viscous",
                "pressure_viscous: rise of the viscous coefficient per pascal of summed gauge pressure; 0: off",
                no_max=catalogue.SIZE_UNBOUNDED),),),
    "K_v + c_v p_sum", _pressure_viscous)


@pytest.fixture
def viscous(monkeypatch):
    monkeypatch.setitem(catalogue.EFFECTS, PRESSURE_VISCOUS.name, PRESSURE_VISCOUS)
    return PRESSURE_VISCOUS


def _model_recording(path: Path, seed: int, duration: float, effects: dict):
    """The MODEL (the monolithic reference with ``effects``) on a random-steps command,
    with sensor noise, as a recording: the command and the start from a short rig run."""
    from boomfmi.compare import rig_model, simulate_recording
    from boomfmi.experiments import random_steps
    from boomfmi.recording import read_recording, write_recording
    cmd = random_steps(seed, duration=duration)
    t = np.round(np.arange(int(round(duration / 1e-3)) + 1) * 1e-3, 9)
    rest = float(ph.alpha_from_x(0.0, ph.Geometry()))
    template = pd.DataFrame({"t": t, "u": [float(cmd(s)["u"]) for s in t], "p_a": 0.0, "p_b": 0.0,
                             "alpha": rest + np.random.default_rng(seed).normal(0.0, NOISE["alpha"], len(t))})
    rec = read_recording(write_recording(path, template))
    sim = simulate_recording({}, rec, effects=effects, rtol=1e-6)
    rig = rig_model(rec)
    rng = np.random.default_rng(seed)
    data = rec.data.copy()
    data["p_a"] = sim["p_a"].to_numpy() + rng.normal(0.0, NOISE["p_a"], len(data))
    data["p_b"] = sim["p_b"].to_numpy() + rng.normal(0.0, NOISE["p_b"], len(data))
    data["alpha"] = ph.alpha_from_x(sim["x"].to_numpy(), rig.geometry) + rng.normal(0.0, NOISE["alpha"], len(data))
    data["x"] = sim["x"].to_numpy()
    return read_recording(write_recording(path, pd.DataFrame(data)))


@pytest.fixture
def viscous_recordings(viscous, tmp_path):
    effects = {viscous.name: {"c_v": C_V}}
    return (_model_recording(tmp_path / "fit.csv", 21, 4.0, effects),
            _model_recording(tmp_path / "hold.csv", 22, 3.0, effects))


def test_a_friction_entry_without_a_fit_is_fitted_with_its_load(viscous, viscous_recordings):
    """pressure_viscous has no fit of its own: the generic path re-identifies the load
    with its form in Eq. 8 and fits c_v by output error around it; c_v comes back within
    20 % (not a grid point: the old code took every friction effect's parameter for a
    Stribeck velocity), the holdout error falls and the load is re-identified."""
    from boomfmi.compare import simulate_recording, nrmse
    from boomfmi.diagnose.attribute import _fit_and_score, fit_cost, shrink
    from boomfmi.identify.fit import identify
    from boomfmi.identify.preprocess import prepare
    fit, hold = viscous_recordings
    preps = [prepare(fit, geometry=ph.Geometry())]
    plain = {k: v for k, v in identify(preps).values().items() if np.isfinite(v)}
    base_cost = fit_cost(plain, {}, [fit])
    name, fx, cost, after, joint, _ = _fit_and_score(("pressure_viscous", plain, [fit], [hold], None, base_cost))
    assert name == "pressure_viscous" and set(fx) == {name} and set(fx[name]) == {"c_v"}
    assert fx[name]["c_v"] == pytest.approx(C_V, rel=0.2)
    assert cost < 0.5 * base_cost
    before = nrmse(simulate_recording(plain, hold, rtol=1e-5), hold)
    assert shrink(before, after) > 0.3
    # the load re-identified with the effect: K_v back near the rig's own, not the
    # effect-free fit's (which took the pressure's viscous share as its own)
    assert joint["K_v"] == pytest.approx(ph.reference_rig.K_v, rel=0.2)
    assert plain["K_v"] > 1.3 * ph.reference_rig.K_v


# ----------------------------------------------------------------- entries the model cannot use
def _entry(name, stage, apply=None, integrator=""):
    return Effect(name, "valve", stage, ((Parameter("k", "1", 0.1, 1.0, False, "k_" + name, name + ": a size; 0: off",
                                                    no_max=catalogue.SIZE_UNBOUNDED),),),
                  "an effect the model cannot use", apply, integrator=integrator)


@pytest.mark.parametrize("entry, says", [
    (_entry("valve_warp", "warp", apply=lambda u, q, m: u), r"valve_warp.*warp"),
    (_entry("valve_wear", "spool"), r"valve_wear.*stateful.*integrator"),
    (_entry("valve_drift", "spool", integrator="spool_drift"), r"valve_drift.*spool_drift.*not an integrator"),
    (_entry("valve_pause", "command"), r"valve_pause.*no function to apply"),
])
def test_an_entry_the_model_cannot_step_is_refused_by_name(monkeypatch, entry, says):
    """An effect of an unknown stage, or of a stateful stage without an integrator the
    model has, or of a stateless stage without its function, is refused by the model
    (it used to be left out silently: the model ran without it) and by diagnosis,
    naming the effect; the catalogue's own effects still run."""
    from boomfmi.diagnose.attribute import _fit_and_score
    from boomfmi.model import Boom, Model
    monkeypatch.setitem(catalogue.EFFECTS, entry.name, entry)
    with pytest.raises(ValueError, match=says):
        Model(effects={entry.name: {"k": 0.5}}).check()
    with pytest.raises(ValueError, match=entry.name):
        Boom(Model(effects={entry.name: {"k": 0.5}}), check=False)
    with pytest.raises(ValueError, match=entry.name):
        catalogue.check_entry(entry)
    if entry.stage not in catalogue.STAGES:
        with pytest.raises(ValueError, match=rf"{entry.name}.*{entry.stage}"):
            _fit_and_score((entry.name, {}, [], [], None, 1.0))
    # nothing lost: the catalogue's stateful effects are stepped by their integrators
    boom = Boom(Model(effects={"valve_dynamics": {"tau": 0.01}, "heat_transfer": {"n": 1.2},
                               "sensor_lag": {"tau": 0.002, "delay": 0.001},
                               "end_cushioning": {"length": 0.01, "A_n": 1e-7, "V_p": 1e-6}}))
    assert (boom.tau_spool, boom.chamber_gas.k, boom.tau_sensor, boom.delay_sensor) == (0.01, 1.2, 0.002, 0.001)
    assert (boom.l_cushion, boom.V_port) == (0.01, 1e-6)


# ----------------------------------------------------------------- no dispatch on an effect's name
#: where an effect's name may be written: its entry, its form, and the virtual rig's own
#: forms and configuration (its names are the rig's, not the catalogue's)
NAMED_HERE = {"model/catalogue.py", "physics/effects.py", "rig/truth.py", "rig/plant.py", "rig/config.py"}


def _name_dispatches(tree: ast.AST, names: set) -> list:
    """(line, code) of each comparison with, call with (``.get``, ``.pop``, a reader), or
    subscript read by a string constant that is a catalogue name."""
    named = lambda n: isinstance(n, ast.Constant) and n.value in names
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare) and any(named(n) for n in [node.left, *node.comparators]):
            hits.append(node)
        elif isinstance(node, ast.Compare) and any(isinstance(n, (ast.Set, ast.Tuple, ast.List)) and
                                                   any(named(e) for e in n.elts) for n in node.comparators):
            hits.append(node)
        elif isinstance(node, ast.Call) and any(named(a) for a in node.args):    # .get(name), read(fx, name)
            hits.append(node)
        elif isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load) and named(node.slice):
            hits.append(node)
    return [(n.lineno, ast.unparse(n)) for n in hits]


def test_no_module_dispatches_on_an_effect_name():
    names = set(catalogue.EFFECTS)
    found = []
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel in NAMED_HERE or "node_modules" in rel:
            continue
        found += [f"{rel}:{line}: {code}" for line, code in _name_dispatches(ast.parse(path.read_text()), names)]
    assert not found, "dispatch on an effect's name (give the entry a field instead):\n" + "\n".join(found)


def test_the_name_check_sees_a_dispatch():
    code = ("if name == 'pressure_friction': pass\nq = fx.get('sensor_lag', {})\n"
            "only = set(e) == {'sensor_lag'}\nc = fx['pressure_friction']\nok = d.get('other')\n"
            "tau = _param(on, 'valve_dynamics', 'tau')\n")
    assert [line for line, _ in _name_dispatches(ast.parse(code), set(catalogue.EFFECTS))] == [1, 2, 3, 4, 6]
