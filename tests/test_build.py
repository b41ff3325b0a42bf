"""build_fmus.py from a clean tree: every FMU validates, and all four run together in a
process whose environment has numpy and fmpy but not boomfmi."""
from __future__ import annotations

import subprocess
import sys
import sysconfig
import textwrap
from pathlib import Path

import pytest
from fmpy.validation import validate_fmu

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("valve", "cylinder", "boom_load", "force_estimator")


@pytest.fixture(scope="module")
def clean_build(tmp_path_factory):
    """Copy the tracked tree (no build/, no .venv) and run build_fmus.py in it."""
    tree = tmp_path_factory.mktemp("clean") / "boomfmi"
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    for rel in files:
        src = ROOT / rel
        if src.is_file():
            dst = tree / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_bytes(src.read_bytes())
    assert not (tree / "build").exists()
    out = subprocess.run([sys.executable, "build_fmus.py", "--out", str(tree / "build")], cwd=tree,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return tree / "build" / "fmus"


def test_every_fmu_validates_with_no_message(clean_build):
    for name in NAMES:
        assert validate_fmu(str(clean_build / f"{name}.fmu")) == [], name


def test_model_descriptions_declare_units_and_dependencies(clean_build):
    from fmpy import read_model_description
    for name in NAMES:
        md = read_model_description(str(clean_build / f"{name}.fmu"))
        units = {u.name for u in md.unitDefinitions}
        for v in md.modelVariables:
            assert v.description, (name, v.name)
            if v.type == "Real":
                assert v.unit in units, (name, v.name)
        assert md.initialUnknowns, name
        assert len(md.outputs) == sum(v.causality == "output" for v in md.modelVariables)
    valve = read_model_description(str(clean_build / "valve.fmu"))
    assert {d.name for d in valve.outputs[0].dependencies} == {"u", "p_a", "p_b"}
    boom = read_model_description(str(clean_build / "boom_load.fmu"))
    assert all(o.dependencies == [] for o in boom.outputs)


def _site_without_boomfmi(tmp: Path) -> Path:
    """A folder of links to this environment's packages, less boomfmi and every .pth."""
    site = Path(sysconfig.get_paths()["purelib"])
    farm = tmp / "site"
    farm.mkdir()
    for entry in site.iterdir():
        low = entry.name.lower()
        if "boomfmi" in low or low.endswith(".pth") or low.startswith("__editable__"):
            continue
        (farm / entry.name).symlink_to(entry)
    return farm


def test_all_four_run_together_without_boomfmi(clean_build, tmp_path):
    farm = _site_without_boomfmi(tmp_path)
    code = textwrap.dedent(f"""
        import importlib.util, sys
        sys.path.insert(0, {str(farm)!r})
        assert importlib.util.find_spec("boomfmi") is None, "boomfmi must not be importable here"
        import numpy, fmpy
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        def load(name, strings={{}}, reals={{}}):
            path = {str(clean_build)!r} + "/" + name + ".fmu"
            md = read_model_description(path)
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path),
                            modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
            vr = {{v.name: v.valueReference for v in md.modelVariables}}
            fmu.instantiate()
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            for n, value in strings.items():
                fmu.setString([vr[n]], [value])
            for n, value in reals.items():
                fmu.setReal([vr[n]], [value])
            fmu.exitInitializationMode()
            return fmu, vr

        valve, vv = load("valve"); cyl, cv = load("cylinder")
        boom, bv = load("boom_load")
        est, ev = load("force_estimator", {{"method": "position_error"}}, {{"K_p": 2e4, "D": 0.0, "tau_est": 0.0}})
        for mod in ("valve", "cylinder", "boom_load", "force_estimator"):
            assert "boomfmi_" + mod + "_lib" in sys.modules, mod
        assert "boomfmi" not in sys.modules

        # extend the boom with u = 1 V for 1 s, explicit coupling at 0.1 ms
        t, dt = 0.0, 1e-4
        p_a, p_b = cyl.getReal([cv["p_a"], cv["p_b"]])
        x, v = boom.getReal([bv["x"], bv["v"]])
        for _ in range(10000):
            valve.setReal([vv["u"], vv["p_a"], vv["p_b"]], [1.0, p_a, p_b])
            mdot_a, mdot_b = valve.getReal([vv["mdot_a"], vv["mdot_b"]])
            cyl.setReal([cv["mdot_a"], cv["mdot_b"], cv["x"], cv["v"]], [mdot_a, mdot_b, x, v])
            boom.setReal([bv["p_a"], bv["p_b"]], [p_a, p_b])
            for f in (valve, cyl, boom, est):
                f.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
            t += dt
            p_a, p_b = cyl.getReal([cv["p_a"], cv["p_b"]])
            x, v = boom.getReal([bv["x"], bv["v"]])
        est.setReal([ev["x_model"], ev["x_measured"], ev["v_model"]], [x, x - 1e-3, 0.0])
        est.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
        f_est = est.getReal([ev["f_est"]])[0]
        print(x, p_a - 101325.0, f_est)
        for f in (valve, cyl, boom, est):
            f.terminate(); f.freeInstance()
    """)
    proc = subprocess.run([sys.executable, "-I", "-S", "-c", code], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    x, p_a_gauge, f_est = map(float, proc.stdout.split())
    assert x == pytest.approx(0.06)                      # reached the end of the stroke
    assert p_a_gauge == pytest.approx(6.0e5, rel=0.01)   # chamber A at supply
    assert f_est == pytest.approx(20.0, rel=1e-9)        # K_p * 1 mm


def test_fmus_use_their_own_physics_even_with_boomfmi_installed(fmu):
    """In this process boomfmi is importable; the FMUs must still load their bundles."""
    import boomfmi  # noqa: F401
    from boomfmi.system import FmuInstance
    with FmuInstance(fmu("valve")) as inst:
        inst.initialize()
        module = sys.modules["boomfmi_valve_lib.physics.orifice"]
        assert "boomfmi_valve_lib" in module.__file__
        assert not Path(module.__file__).is_relative_to(ROOT / "src")


def test_rebuilding_one_fmu_repacks_the_ssps_that_carry_it(clean_build, tmp_path):
    """An SSP holds copies of its FMUs: rebuilding the bridge alone must re-pack
    teleoperation.ssp (which carries it) and leave excavator_boom.ssp (which does not)
    alone; into an empty folder, the SSP is not packed and the output says why."""
    import zipfile
    tree, build = clean_build.parents[1], clean_build.parent
    boom_before = (build / "excavator_boom.ssp").stat().st_mtime_ns
    out = subprocess.run([sys.executable, "build_fmus.py", "hardware_bridge", "--out", str(build)],
                         cwd=tree, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert f"packed {build / 'teleoperation.ssp'}" in out.stdout
    with zipfile.ZipFile(build / "teleoperation.ssp") as z:
        assert z.read("resources/hardware_bridge.fmu") == (clean_build / "hardware_bridge.fmu").read_bytes()
    assert (build / "excavator_boom.ssp").stat().st_mtime_ns == boom_before

    alone = subprocess.run([sys.executable, "build_fmus.py", "hardware_bridge", "--out", str(tmp_path)],
                           cwd=tree, capture_output=True, text=True)
    assert alone.returncode == 0, alone.stderr
    assert not (tmp_path / "teleoperation.ssp").exists()
    assert "not packed" in alone.stdout and "boom_load, cylinder, force_estimator, valve not built yet" in alone.stdout


def test_a_build_after_an_fmu_ran_in_this_process_uses_the_installed_pythonfmu(fmu_dir, tmp_path):
    """An FMU instantiated in this process puts its own resources/ (with its copy of the
    pythonfmu package and its bundle) first on sys.path: a build after it packed no
    binary ("pythonfmu wrote no binaries/linux64/valve.so"). It builds, and the running
    FMU's modules are left to it."""
    import sys

    from fmpy import simulate_fmu

    from boomfmi.fmubuild import build_fmu
    simulate_fmu(str(fmu_dir / "valve.fmu"), stop_time=0.002, step_size=1e-3)
    before = {m: id(sys.modules[m]) for m in sys.modules if m.startswith(("pythonfmu", "boomfmi_valve"))}
    built = build_fmu(Path(__file__).resolve().parents[1] / "fmus" / "valve", tmp_path)
    assert built.is_file()
    assert {m: id(sys.modules[m]) for m in sys.modules if m.startswith(("pythonfmu", "boomfmi_valve"))} == before
    simulate_fmu(str(built), stop_time=0.002, step_size=1e-3)
