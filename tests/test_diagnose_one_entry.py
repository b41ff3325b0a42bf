"""One diagnosis entry for one joint or four (issue 32, item 1, step 8).

``diagnose.report.diagnose`` reads the machine from the recordings: the boom rig's are
judged whole, the whole excavator's joint by joint (``diagnose.joints``), with one report
writer; the options the per-joint path cannot honour are refused naming them; and the
catalogue is read when a diagnosis runs, so a plug-in's effect loaded after import is a
candidate on a joint's cut as it is on the boom.
"""
from pathlib import Path

import pytest

from boomfmi import experiments as E
from boomfmi.diagnose import joints as dj
from boomfmi.diagnose.report import action_sentence, diagnose
from boomfmi.model import catalogue
from boomfmi.physics import linkage as exc
from boomfmi.recording import read_recording, write_recording
from boomfmi.rig import run_excavator_offline

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = ROOT / "tests" / "fixtures" / "boomfmi_effects_example" / "boomfmi_effects_example.py"


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """A short excavator run (1.5 s of the digging cycle) as a fit and a holdout recording."""
    d = tmp_path_factory.mktemp("one_entry")
    out = []
    for name, seed in (("fit.csv", 1), ("hold.csv", 2)):
        frame = run_excavator_offline({"machine": "excavator", "seed": seed}, E.digging_cycle(pace=0.5), 1.5)
        out.append(write_recording(d / name, frame.drop(columns=[c for c in frame if c.startswith(("x_", "v_"))])))
    return d, *out


@pytest.mark.parametrize("option, value", [("ssp", "build/excavator_boom.ssp"), ("propose", "next.csv")])
def test_the_boom_s_options_are_refused_for_the_excavator_naming_them(recordings, option, value):
    d, fit, hold = recordings
    out = d / f"out_{option}"
    with pytest.raises(ValueError, match=f"--{option} ") as err:
        diagnose([fit], [hold], out, **{option: d / value})
    assert "excavator" in str(err.value) and "joint by joint" in str(err.value)
    assert not out.exists() and not (d / value).exists()           # nothing written, nothing lost
    assert fit.is_file() and hold.is_file()


def test_the_cli_refuses_them_without_a_traceback(recordings, capsys):
    from boomfmi import cli
    d, fit, hold = recordings
    code = cli.main(["diagnose", str(fit), "--holdout", str(hold), "--out", str(d / "cli_out"),
                     "--propose", str(d / "next.csv")])
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith("boomfmi diagnose: ") and "--propose" in err and "Traceback" not in err
    assert not (d / "cli_out").exists() and not (d / "next.csv").exists()


def test_the_cli_and_the_campaign_call_only_the_one_entry():
    """No second dispatch for the excavator left beside ``diagnose.report.diagnose``."""
    from boomfmi import cli
    from boomfmi.campaign import case
    import boomfmi.diagnose as package
    for module in (cli, case):
        assert not [n for n in vars(module) if "excavator" in n and "diagnose" in n], module.__name__
    names = {p.stem for p in Path(package.__file__).parent.glob("*.py")}
    assert "joints" in names and not {n for n in names if n.startswith("excavator")}


def test_the_action_sentence_names_each_effect_on_its_joint_and_the_joints_nothing_explains():
    doc = {"kind": "excavator", "judgeable": True,
           "verdict": ["piston_leakage@arm", "unexplained@bucket"],
           "effects": [{"name": "piston_leakage", "joint": "arm", "named": True, "shrink": 0.93},
                       {"name": "piston_leakage", "joint": "boom", "named": False, "shrink": 0.1}],
           "where": [{"joint": "bucket", "channel": "p_b_bucket", "subsystem": "valve_bucket, cylinder_bucket"}]}
    text = action_sentence(doc)
    assert "piston_leakage on the arm (it removes 93 % of that joint's gap" in text
    assert catalogue.EFFECTS["piston_leakage"].advice in text
    assert "on the bucket that none of its candidate effects explains, mostly in p_b_bucket" in text
    assert "unexplained@" not in text and "Most likely cause: unexplained" not in text


@pytest.fixture
def plugin():
    """The fixture's plug-in, loaded after boomfmi.diagnose was imported (as ``--effects``)."""
    loaded = catalogue.load_file(PLUGIN)
    yield loaded
    catalogue.remove_plugin(loaded.name)


def test_a_plugin_s_pneumatic_effect_is_offered_and_fitted_on_a_joint_s_cut(recordings, plugin):
    d, fit, hold = recordings
    assert "rod_seal_leak" in dj.candidates(dj.PNEUMATIC_STAGES)
    ex = exc.Excavator()
    truth = {"rod_seal_leak": {"C": 2e-10}}
    cuts = []
    for path in (fit, hold):                 # the arm's recorded pressures as the cut with the plug-in's leak
        cut = dj.joint_cut(read_recording(path), "arm", ex)
        cut.p_a_raw, cut.p_b_raw = dj.joint_pressures(cut, "arm", ex, truth)
        cuts.append(cut)
    before = dj.joint_gap(cuts[0], "arm", ex)
    assert before > 0.01                     # the leak shows on the arm's cut
    name, fx, cost, hold_gaps, told = dj._fit_single(("arm", "rod_seal_leak", ex, cuts[:1], cuts[1:], before, []))
    assert name == "rod_seal_leak" and cost < 0.2 * before and hold_gaps[0] < 0.2 * dj.joint_gap(cuts[1], "arm", ex)
    assert fx["rod_seal_leak"]["C"] == pytest.approx(2e-10, rel=0.2) and told == []    # (its one law: nothing to tell)
    # gone with the plug-in: read when the diagnosis runs, not when it was imported
    catalogue.remove_plugin(plugin.name)
    assert "rod_seal_leak" not in dj.candidates(dj.PNEUMATIC_STAGES)
    with pytest.raises(KeyError):
        dj.joint_forms("rod_seal_leak", "arm", ex)
    catalogue.load_file(PLUGIN)              # for the fixture's own removal
