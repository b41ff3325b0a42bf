"""Names read from files never become paths (issue 31, case 1).

An SSP's component names and sources, an FMU's model identifier, a manifest's machine
and its recordings' names are data.  Each test gives one a hostile value and asserts
the clear refusal (naming the element at fault) and that nothing was written or read
outside the place meant for it, and nothing lost.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest

from boomfmi.campaign.case import case_spec
from boomfmi.campaign.manifest import Case, Entry, slug
from boomfmi.names import MAX_NAME, member_problem, name_problem
from boomfmi.simulate import run_experiment
from boomfmi.system.instance import model_description
from boomfmi.system.ssp import read_ssp
from boomfmi.system.ssv import SspError
from conftest import rewrite_ssp

ROOT = Path(__file__).resolve().parents[1]
PRECIOUS = b"a file the SSP must not touch"


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def renamed(ssp_path: Path, dst: Path, name: str) -> Path:
    """The boom's SSP with its valve component called ``name`` everywhere."""
    return rewrite_ssp(ssp_path, dst, edit=lambda s: s.replace('name="valve"', f'name="{name}"')
                       .replace('Element="valve"', f'Element="{name}"'))


def test_a_component_named_by_an_absolute_path_is_refused_and_nothing_is_written_there(ssp_path, tmp_path):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "valve.fmu").write_bytes(PRECIOUS)
    (tmp_path / "out.csv").write_bytes(PRECIOUS)
    for name in (str(victim / "valve"), str(victim / "new")):
        bad = renamed(ssp_path, tmp_path / "abs.ssp", name)
        proc = cli("simulate", bad, "--out", "out.csv", cwd=tmp_path)
        assert proc.returncode == 1, proc.stdout + proc.stderr
        assert f"component '{name}' is refused: it is an absolute path" in proc.stderr
        assert "Traceback" not in proc.stderr
    assert sorted(p.name for p in victim.iterdir()) == ["valve.fmu"]
    assert (victim / "valve.fmu").read_bytes() == PRECIOUS
    assert (tmp_path / "out.csv").read_bytes() == PRECIOUS


def test_a_component_name_that_climbs_out_is_refused_and_nothing_is_written_there(ssp_path, tmp_path, monkeypatch):
    # the master's temporary folder is tmp_path/t/boomfmi_ssp_*: ../../victim/x is tmp_path/victim/x
    (tmp_path / "t").mkdir()
    (tmp_path / "victim").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "t"))
    for name in ("../../victim/valve", "..", "valve/../../../victim/x"):
        bad = renamed(ssp_path, tmp_path / "up.ssp", name)
        with pytest.raises(SspError, match=rf"component {name!r} is refused: it climbs out of its folder"):
            run_experiment(bad, stop_time=0.01)
    assert list((tmp_path / "victim").iterdir()) == []
    assert list((tmp_path / "t").iterdir()) == []          # the temporary folder is gone too


@pytest.mark.parametrize("name, why", [("valve.x", "it holds '.'"), ("my valve", "it holds ' '"),
                                       ("valve\\x", "it is a path"), ("-v", "it starts with '-'"),
                                       ("v" * (MAX_NAME + 1), f"it has {MAX_NAME + 1} characters")])
def test_a_component_name_that_is_not_plain_is_refused_naming_it(ssp_path, tmp_path, name, why):
    bad = renamed(ssp_path, tmp_path / "odd.ssp", name)
    with pytest.raises(SspError, match=rf"component {name!r} is refused: {why}".replace("\\", "\\\\")):
        read_ssp(bad)


def test_two_components_of_one_name_are_refused_not_one_dropped(ssp_path, tmp_path):
    def twice(ssd: str) -> str:          # the valve's element, then a copy of it
        start = ssd.index('<ssd:Component name="valve"')
        end = ssd.index("</ssd:Component>", start) + len("</ssd:Component>")
        return ssd[:end] + ssd[start:end] + ssd[end:]
    bad = rewrite_ssp(ssp_path, tmp_path / "twice.ssp", edit=twice)
    with pytest.raises(SspError, match=r"two components are named 'valve'"):
        read_ssp(bad)


def _folder_ssp(ssp_path: Path, folder: Path) -> Path:
    with zipfile.ZipFile(ssp_path) as z:
        z.extractall(folder)
    return folder


def test_a_source_outside_the_ssp_is_refused_and_not_read(ssp_path, tmp_path):
    """A component's or a binding's ``source`` is a file inside the SSP: an absolute
    path or one with ``..`` would read any file of the disk (a folder SSP reads
    ``folder / source``)."""
    system = _folder_ssp(ssp_path, tmp_path / "system")
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.copy(system / "resources" / "valve.fmu", outside / "valve.fmu")
    ssv = (system / "resources" / "reference_rig_valve.ssv").read_text()
    (outside / "set.ssv").write_text(ssv.replace('name="A_max"', 'name="T"', 1))  # read: a clash
    ssd = (system / "SystemStructure.ssd").read_text()
    cases = {f'source="{outside / "valve.fmu"}"': ("component valve: source", "it is an absolute path"),
             'source="resources/../../outside/valve.fmu"': ("component valve: source", "it climbs out"),
             'source="file:///etc/passwd"': ("component valve: source", "its part 'file:' is not a plain file name")}
    for source, (what, why) in cases.items():
        (system / "SystemStructure.ssd").write_text(ssd.replace('source="resources/valve.fmu"', source))
        with pytest.raises(SspError, match=rf"{what} .* is refused: {why}"):
            read_ssp(system)
    binding = 'source="resources/../../outside/set.ssv"'
    (system / "SystemStructure.ssd").write_text(ssd.replace('source="resources/reference_rig_valve.ssv"', binding))
    with pytest.raises(SspError, match=r"the parameter binding of valve: source .* is refused: it climbs out"):
        read_ssp(system)
    with pytest.raises(SspError, match=r"refers to '/etc/passwd': it is an absolute path"):
        read_ssp(ssp_path).read("/etc/passwd")
    assert (outside / "valve.fmu").read_bytes() == (system / "resources" / "valve.fmu").read_bytes()


def test_an_fmu_whose_model_identifier_is_a_path_is_refused(fmu, tmp_path):
    """fmpy loads ``binaries/<platform>/<modelIdentifier>.so``: an identifier such as
    ``../../../x`` would load a library from anywhere."""
    good = fmu("valve")
    for identifier in ("../../../../tmp/evil", "/tmp/evil"):
        bad = tmp_path / "valve.fmu"
        with zipfile.ZipFile(good) as zin, zipfile.ZipFile(bad, "w") as zout:
            for item in zin.infolist():
                data = zin.read(item.filename)
                if item.filename == "modelDescription.xml":
                    data = data.replace(b'modelIdentifier="valve"', f'modelIdentifier="{identifier}"'.encode())
                zout.writestr(item, data)
        with pytest.raises(ValueError, match=rf"valve\.fmu: not a valid FMU: its coSimulation modelIdentifier "
                                             rf"'{identifier}' is refused"):
            model_description(bad)
        proc = cli("describe", bad)
        assert proc.returncode == 1 and "modelIdentifier" in proc.stderr and "Traceback" not in proc.stderr
    assert model_description(good).coSimulation.modelIdentifier == "valve"


def test_packing_refuses_a_source_outside_the_fmu_folder(fmu_dir, tmp_path):
    from boomfmi.fmubuild import BuildError
    from boomfmi.fmubuild.ssp import pack_ssp, parameters_ssv
    from boomfmi.model.boom import Model
    from boomfmi.model.machine import boom_machine
    (tmp_path / "secret.fmu").write_bytes(PRECIOUS)
    fmus = tmp_path / "build" / "fmus"           # fmus / "../../secret.fmu" is the secret
    fmus.mkdir(parents=True)
    ssd_text = (ROOT / "ssp" / "SystemStructure.ssd").read_text().replace(
        'source="resources/valve.fmu"', 'source="resources/../../secret.fmu"')
    ssd = tmp_path / "src" / "SystemStructure.ssd"
    ssd.parent.mkdir()
    ssd.write_text(ssd_text)
    with pytest.raises(BuildError, match=r"source 'resources/\.\./\.\./secret\.fmu' must lie under resources/: "
                                         r"it climbs out"):
        pack_ssp(ssd, fmus, tmp_path / "out.ssp")
    assert not (tmp_path / "out.ssp").exists() and not (tmp_path / "out.tmp").exists()
    with pytest.raises(BuildError, match=r"component 'valve': source .* it climbs out"):
        parameters_ssv(boom_machine(Model()), [ssd], fmus, tmp_path / "ref.ssv")
    assert not (tmp_path / "ref.ssv").exists()
    assert (tmp_path / "secret.fmu").read_bytes() == PRECIOUS


def test_a_machine_name_too_long_for_a_folder_gets_a_folder_all_the_same(tmp_path):
    """A manifest's machine is any text: its folder (``cases/<machine>/<date>``) and its
    trend plot (``trend_<machine>.png``) are named by ``slug``, which a 300-character
    name used to pass through whole (the file system refuses over 255 bytes)."""
    machines = ("m" * 300, "m" * 299 + "n", "../../etc", "/abs")
    folders = [Case(m, "2025-03-10").folder for m in machines]
    assert len(set(folders)) == len(machines)
    for m, f in zip(machines, folders):
        assert all(len(part) <= MAX_NAME and part not in (".", "..") for part in f.parts)
        (tmp_path / "cases" / f).mkdir(parents=True)
        (tmp_path / f"trend_{slug(m)}.png").write_bytes(b"")
    assert all(p.resolve().is_relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert slug("machine-1") == "machine-1" and slug("a" * MAX_NAME) == "a" * MAX_NAME


def test_recordings_of_one_name_from_three_folders_keep_three_files_in_a_case(tmp_path):
    """A case's recordings are written into one temporary folder by name; a recording
    called ``2_a.csv`` used to share its name with the second ``a.csv`` (one lost)."""
    paths = [tmp_path / "d1" / "a.csv", tmp_path / "d2" / "2_a.csv", tmp_path / "d3" / "a.csv",
             tmp_path / "d4" / "1_a.csv", tmp_path / "d5" / "a.csv"]
    for i, p in enumerate(paths):
        p.parent.mkdir()
        p.write_bytes(f"recording {i}".encode())
    case = Case("m", "2025-03-10", [Entry(i + 2, "m", "2025-03-10", "fit", p, None) for i, p in enumerate(paths)])
    files = case_spec(case)["files"]
    names = [f["name"] for f in files]
    assert len(set(names)) == len(paths), names
    assert all(name_problem(n.removesuffix(".csv")) is None for n in names)
    assert sorted(f["csv"] for f in files) == sorted(p.read_bytes() for p in paths)     # nothing lost


def test_the_rules_of_a_plain_name_and_of_a_place_in_an_archive():
    assert name_problem("valve_boom") is None and name_problem("cylinder-2") is None
    for bad in ("", None, ".", "..", "a.b", "a/b", "/a", "C:a", "a\x00", "é"):
        assert name_problem(bad), bad
    assert member_problem("resources/valve.fmu") is None and member_problem("resources/set_v1+2.ssv") is None
    for bad in ("", "/etc/passwd", "../x", "resources/../../x", "resources//x", "resources/./x",
                "resources/.hidden", "a\\b", "C:/x", "file:///x", "resources/a\x00"):
        assert member_problem(bad), bad
