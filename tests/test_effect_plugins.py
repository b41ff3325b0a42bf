"""A user's own effects as a plug-in (issue 34, item 2): an installed package's entry
point ``boomfmi.effects`` (or ``--effects FILE``) adds one entry per effect; units are
pint's; the virtual rig simulates the same mechanisms in its own forms; an FMU built with
the plug-in carries its options and its module; the diagnosis names each effect.

The plug-in is ``tests/fixtures/boomfmi_effects_example`` (one effect in each stateless
stage), installed for this module only: its dist-info is written from its pyproject.toml
into a temporary folder put on sys.path (a wheel build takes seconds and needs the
``wheel`` package, which setuptools 65 here lacks), and taken out again afterwards.
"""
from __future__ import annotations

import importlib
import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

# imported before the plug-in is loaded: the diagnosis's module-level tables (its
# candidates) must not keep the plug-in's effects for the other tests of this worker
import boomfmi.diagnose.attribute  # noqa: F401
from boomfmi.model import catalogue
from boomfmi.model.boom import Boom, Model
from boomfmi.physics.params import Load
from boomfmi.rig import config as rig_config
from boomfmi.rig import truth
from boomfmi.units import UNITS, unit_definition, unit_problem

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "fixtures" / "boomfmi_effects_example"
MODULE = "boomfmi_effects_example"
#: the plug-in's effects, each with its rig configuration and the model parameter its
#: rig parameter is (the same mechanism: the same value)
PLUGGED = {
    "valve_offset": ("command", "null_shift", 0.3, "offset"),
    "port_restriction": ("port", "blocked", 0.4, "r"),
    "rod_seal_leak": ("seal", "G_rod", 3e-10, "C"),
    "speed_drag": ("friction", "k_drag", 20000.0, "c_q"),
}


def install(target: Path) -> None:
    """The fixture package installed into ``target``: its module and a dist-info with
    the entry points its pyproject.toml declares."""
    project = tomllib.loads((FIXTURE / "pyproject.toml").read_text())["project"]
    dist = target / f"{project['name'].replace('-', '_')}-{project['version']}.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\n"
                                   f"Version: {project['version']}\n")
    (dist / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items())
        for group, eps in project["entry-points"].items()))
    shutil.copy2(FIXTURE / f"{MODULE}.py", target / f"{MODULE}.py")


def _forget() -> None:
    if "example" in catalogue.PLUGINS:
        catalogue.remove_plugin("example")
    rig_config.plugin_effects()          # the rig's forms of a removed plug-in go too
    sys.modules.pop(MODULE, None)


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    target = tmp_path_factory.mktemp("site-packages")
    install(target)
    sys.path.insert(0, str(target))
    importlib.invalidate_caches()
    try:
        catalogue.load_plugins()
        rig_config.plugin_effects()
        yield catalogue.PLUGINS["example"]
    finally:
        sys.path.remove(str(target))
        _forget()


def test_an_installed_plugin_adds_one_effect_per_stateless_stage(plugin):
    assert plugin.effects == tuple(PLUGGED)
    assert plugin.source == str(Path(sys.modules[MODULE].__file__))
    for name, (stage, *_rest) in PLUGGED.items():
        e = catalogue.EFFECTS[name]
        assert (e.stage, e.fmu) == (stage, catalogue.STAGE_FMU[stage])
        assert name in rig_config.RIG_EFFECTS and truth.RIG_FORMS[name].stage == stage
    # the catalogue's own entries are all still there, and the FMUs' option tables hold the new ones
    assert {"piston_leakage", "end_cushioning", "valve_deadband", "pressure_friction"} <= set(catalogue.EFFECTS)
    assert [p.option for e in catalogue.of_fmu("cylinder") for p in e.parameters][-2:] == ["r_port_a", "C_rod_leak"]
    assert catalogue.load_plugins() and catalogue.PLUGINS["example"] is plugin     # loaded once


BAD = {
    "clash": ("E('piston_leakage', 'cylinder', 'seal', ((P('C', 'kg/(s.Pa)', 1e-12, 1e-9, True, 'C_x', 'd', "
              "no_max='s'),),), 's', f)", "effect 'piston_leakage': the name is taken by the catalogue's own entry"),
    "stateful": ("E('wall_heat', 'cylinder', 'heat', ((P('h', 'W/(m2.K)', 1, 10, True, 'h_x', 'd', no_max='s'),),),"
                 " 's', f)", "stage 'heat' is a stateful stage"),
    "unknown stage": ("E('x_lag', 'cylinder', 'plumbing', ((P('h', 's', 1, 10, True, 'h_x', 'd', no_max='s'),),),"
                      " 's', f)", "stage 'plumbing' is unknown stage"),
    "unit": ("E('x_leak', 'cylinder', 'seal', ((P('C', 'furlongs/fortnightz', 1, 10, True, 'C_x', 'd', "
             "no_max='s'),),), 's', f)", "effect 'x_leak', parameter 'C': unit 'furlongs/fortnightz': pint does "
                                        "not read it"),
    "option": ("E('x_leak', 'cylinder', 'seal', ((P('C', 'kg/(s.Pa)', 1e-12, 1e-9, True, 'C_leak', 'd', "
               "no_max='s'),),), 's', f)", "FMU option 'C_leak' is already piston_leakage's"),
}


@pytest.mark.parametrize("case", BAD)
def test_a_bad_plugin_is_refused_naming_it_and_its_entry_and_adds_nothing(case, tmp_path):
    entry, says = BAD[case]
    path = tmp_path / "mine.py"
    # a good entry first: a plug-in is taken whole or not at all
    path.write_text("def f(*a):\n    return a[0]\n\n"
                    "def effects(catalogue):\n    E, P = catalogue.Effect, catalogue.Parameter\n"
                    "    return [E('fine_leak', 'cylinder', 'seal', ((P('C', 'kg/(s.Pa)', 1e-12, 1e-9, True, "
                    f"'C_fine', 'd', no_max='s'),),), 's', f), {entry}]\n")
    before, plugins = dict(catalogue.EFFECTS), dict(catalogue.PLUGINS)
    with pytest.raises(catalogue.PluginError) as e:
        catalogue.load_file(path)
    assert str(e.value).startswith(f"effect plug-in {path}: ") and says in str(e.value)
    assert catalogue.EFFECTS == before and catalogue.PLUGINS == plugins


def test_the_cli_s_effects_file_is_loaded_first_and_a_bad_one_named(tmp_path, monkeypatch, capsys):
    from boomfmi import cli
    monkeypatch.setenv(catalogue.EFFECTS_ENV, "")        # (put back as it was after the test)
    bad = tmp_path / "broken.py"
    bad.write_text("def effects(catalogue):\n    return []\n")
    assert cli.main(["--effects", str(bad), "check", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err == f"boomfmi check: effect plug-in {bad}: effects(catalogue) returned no entry\n"
    assert os.environ[catalogue.EFFECTS_ENV] == str(bad)      # for the processes a command starts
    assert not any("broken" in p for p in catalogue.PLUGINS)


def test_a_process_started_with_the_effects_file_in_its_environment_loads_it(tmp_path):
    """How ``--effects FILE`` reaches the processes a command starts (Dask workers, FMU builds)."""
    env = {**os.environ, catalogue.EFFECTS_ENV: str(FIXTURE / f"{MODULE}.py")}
    code = ("from boomfmi.model.catalogue import PLUGINS\n"
            "print(sorted(n for p in PLUGINS.values() for n in p.effects))")
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"{sorted(PLUGGED)}"


def test_units_are_pint_s_and_the_fmu_s_definitions_come_from_its_si_dimensions():
    for unit, (exponents, display) in UNITS.items():
        assert unit_definition(unit) == (exponents, 1.0, display), unit
    assert unit_definition("N.s/(m.Pa)") == ({"m": 1, "s": 1}, 1.0, {})     # the unit: no list to extend
    assert unit_definition("bar")[:2] == ({"kg": 1, "m": -1, "s": -2}, 1e5)
    assert "pint does not read it" in unit_problem("furlongs/fortnightz")
    assert "has an offset" in unit_problem("degC")
    assert [(e.name, p.unit) for e in catalogue.EFFECTS.values() for p in e.parameters if unit_problem(p.unit)] == []


def test_the_rig_forms_are_the_model_s_mechanisms_written_apart(plugin):
    boom = Boom(Model(), check=False)
    site = truth.RigSite(boom.valve, boom.gas, boom.cylinder, boom.P_atm)
    p_a, p_b, x = 4.2e5, 2.7e5, 0.03
    flows = (2e-3, -1.5e-3, -4e-9, -3e-9)
    load = Load(2829.0, 120.0, 85.0, 0.0, 22.7)
    for name, (stage, rig_name, value, model_name) in PLUGGED.items():
        model_form, rig_form = catalogue.EFFECTS[name].apply, truth.RIG_FORMS[name].apply
        q, r = {model_name: value}, {rig_name: value}
        if stage == "command":
            for u in (1.0, 4.9, 5.2, 9.0):
                assert rig_form(u, r, site) == pytest.approx(model_form(u, q, boom), abs=1e-12)
        elif stage in ("port", "seal"):
            assert rig_form(*flows, p_a, p_b, x, r, site) == pytest.approx(
                model_form(*flows, p_a, p_b, x, q, boom), rel=1e-12)
        else:
            assert rig_form(load, 0.05, p_a, p_b, r, site) == pytest.approx(
                model_form(load, 0.05, p_a, p_b, q, boom), rel=1e-12)
            assert rig_form(load, 0.05, p_a, p_b, r, site).K_v > load.K_v
    # the rig's configuration checks them; a seal's flows carry no temperature for heat_transfer
    with pytest.raises(ValueError, match=r"effects\.port_restriction: blocked must lie in \[0, 1\)"):
        rig_config.load_config({"effects": {"port_restriction": {"blocked": 1.5}}})
    with pytest.raises(ValueError, match=r"effects\.rod_seal_leak: a plug-in's port or seal form cannot run"):
        rig_config.load_config({"effects": {"rod_seal_leak": True, "heat_transfer": True}})


RUN_FMU = """
import json, sys
from fmpy import simulate_fmu
out = {}
for C in (0.0, 1e-9):
    r = simulate_fmu(sys.argv[1], stop_time=0.2, output_interval=0.01, output=["p_b"],
                     start_values={"C_rod_leak": C, "p_b0": 6e5, "x": 0.03})
    out[str(C)] = float(r["p_b"][-1])
try:
    import boomfmi_effects_example
    out["host"] = True
except ImportError:
    out["host"] = False
print(json.dumps(out))
"""


def test_an_fmu_built_with_the_plugin_carries_its_options_and_its_module(plugin, tmp_path):
    from fmpy.validation import validate_fmu
    from boomfmi.fmubuild import build_fmu
    fmu = build_fmu(ROOT / "fmus" / "cylinder", tmp_path)
    assert validate_fmu(str(fmu)) == []
    with zipfile.ZipFile(fmu) as z:
        xml = z.read("modelDescription.xml").decode()
        carried = z.read(f"resources/boomfmi_cylinder_lib/effect_plugins/{MODULE}.py")
    assert carried == (FIXTURE / f"{MODULE}.py").read_bytes()
    assert 'name="r_port_a"' in xml and 'name="C_rod_leak"' in xml and "u_offset" not in xml   # the valve's
    # run where the plug-in is not installed: the FMU loads it from its own resources
    proc = subprocess.run([sys.executable, "-c", RUN_FMU, str(fmu)], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["host"] is False
    assert out["0.0"] == pytest.approx(6e5) and out["1e-09"] < 0.8 * out["0.0"]     # the rod seal leaks


@pytest.mark.slow
@pytest.mark.parametrize("name", list(PLUGGED))
def test_the_diagnosis_names_each_plugin_effect_the_rig_has(plugin, name, tmp_path):
    from boomfmi.diagnose.attribute import attribute
    from boomfmi.experiments import random_steps
    from boomfmi.identify import identify_recordings
    from boomfmi.recording import read_recording, write_recording
    from boomfmi.rig.offline import run_offline
    stage, rig_name, value, model_name = PLUGGED[name]
    cfg = {"seed": 5, "effects": {name: {rig_name: value}}}
    fit, hold = random_steps(3, duration=3.0), random_steps(4, duration=3.0)
    write_recording(tmp_path / "fit.csv", run_offline(cfg, fit, fit.duration))
    write_recording(tmp_path / "hold.csv", run_offline(dict(cfg, seed=6), hold, hold.duration))
    result, _, _ = identify_recordings([tmp_path / "fit.csv"], "fit")
    # the candidates: the plug-in's effect and the catalogue's own of its stage
    rivals = [n for n, e in catalogue.EFFECTS.items() if e.stage == stage and n not in PLUGGED][:2]
    assert rivals
    att = attribute(result.values(), [read_recording(tmp_path / "fit.csv")], [read_recording(tmp_path / "hold.csv")],
                    names=[name, *rivals], workers=1, intervals={k: e.ci95 for k, e in result.params.items()})
    assert att.verdict == [name]
    best = att.candidates[0]
    assert best.name == name and best.shrink > 0.0
    assert best.params[model_name] == pytest.approx(value, rel=0.2)
