"""Issue 33, build items 4 and 5: the excavator's run file from one command
(``boomfmi view --replay RECORDING --model params.json [--write-run RUN.csv]``: the
identified machine beside the machine, ``f_tip_est`` and its interval, which the view
draws), ``--export``'s plots with their past before ``--start``, and every command's
default FMU or SSP path from any working directory (``boomfmi.paths``)."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from boomfmi import experiments as E
from boomfmi.cli import main
from boomfmi.identify.joints import JOINTS, true_values
from boomfmi.physics.force_estimation import F_BOUND
from boomfmi.recording import read_recording, write_recording
from boomfmi.rig import run_excavator_offline
from boomfmi.view.frames import load_run

ROOT = Path(__file__).resolve().parents[1]
PAYLOAD = 0.5
SECONDS = 1.5


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A short excavator recording with a push on the tip, and the params.json of its
    machine (the rig's own values, in the form `boomfmi identify` writes)."""
    d = tmp_path_factory.mktemp("run_file")
    cfg = json.loads((ROOT / "examples" / "rig" / "excavator_contact_push.json").read_text())
    frame = run_excavator_offline({**cfg, "payload": PAYLOAD}, E.digging_cycle(pace=0.4), SECONDS)
    rec = write_recording(d / "dig.csv", frame.drop(columns=[c for c in frame if c.startswith(("x_", "v_"))]))
    values = true_values(payload=PAYLOAD)
    params = {"kind": "excavator", "params": {k: {"value": v, "ssv_value": v} for k, v in values.items()}}
    (d / "params.json").write_text(json.dumps(params))
    return {"dir": d, "rec": rec, "params": d / "params.json"}


def _bytes(*paths):
    return {p: p.read_bytes() for p in paths if p.exists()}


def test_view_model_writes_the_run_file_with_the_estimate_and_its_interval(files, capsys):
    """One command writes the run file the README describes: the model beside the
    machine (whose columns are the recording's own), f_tip_est and its interval; the
    view reads it with the model's ghost and sends the interval per axis."""
    out = files["dir"] / "run.csv"
    before = _bytes(files["rec"], files["params"])
    assert main(["view", "--replay", str(files["rec"]), "--model", str(files["params"]),
                 "--write-run", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    assert _bytes(files["rec"], files["params"]) == before                  # the inputs untouched
    run, rec = read_recording(out).data, read_recording(files["rec"]).data
    for j in JOINTS:
        for q in ("angle", "p_a", "p_b"):
            np.testing.assert_allclose(run[f"{q}_{j}_measured"], rec[f"{q}_{j}"], rtol=1e-9, atol=1e-9)
            assert np.all(np.isfinite(run[f"{q}_{j}"]))
        # the identified machine follows the machine it was identified on
        assert np.sqrt(np.mean((run[f"angle_{j}"] - rec[f"angle_{j}"]) ** 2)) < 0.05
    lo = run[[f"f_tip_lo_{a}" for a in "xyz"]].to_numpy()
    hi = run[[f"f_tip_hi_{a}" for a in "xyz"]].to_numpy()
    est = run[[f"f_tip_est_{a}" for a in "xyz"]].to_numpy()
    assert np.all(lo <= hi) and np.all(np.isfinite(est))
    assert np.any(hi - lo < 2 * F_BOUND), "no sample bounded on any axis: the interval is not there"
    view = load_run(out)
    assert view.model is not None and {"f_tip_est", "f_tip", "f_tip_lo", "f_tip_hi"} <= set(view.forces)
    frame = view.frame(float(view.t[-1]))
    assert len(frame["f_tip_lo"]) == 3 and len(frame["f_tip_hi"]) == 3
    for lo_k, hi_k in zip(frame["f_tip_lo"], frame["f_tip_hi"]):   # an open side is None, never +-F_BOUND
        assert lo_k is None or abs(lo_k) < F_BOUND
        assert hi_k is None or abs(hi_k) < F_BOUND


def test_view_model_refuses_a_boom_params_and_leaves_the_old_run_file(files, capsys):
    out = files["dir"] / "kept.csv"
    out.write_text("old run\n")
    boom = files["dir"] / "boom_params.json"
    boom.write_text(json.dumps({"method": "fit", "params": {"K_v": {"value": 10.0}}}))
    assert main(["view", "--replay", str(files["rec"]), "--model", str(boom), "--write-run", str(out)]) == 1
    err = capsys.readouterr().err
    assert "boom_params.json: not the whole excavator's params.json" in err and "Traceback" not in err
    assert out.read_text() == "old run\n"
    assert not out.with_suffix(".json").exists()


def test_view_model_refuses_the_recording_or_its_sidecar_as_the_run_file(files, capsys):
    before = _bytes(files["rec"], files["rec"].with_suffix(".json"), files["params"])
    for target in (files["rec"], files["params"].with_suffix(".csv")):   # run.csv's sidecar = params.json
        assert main(["view", "--replay", str(files["rec"]), "--model", str(files["params"]),
                     "--write-run", str(target)]) == 1
        assert "boomfmi view:" in capsys.readouterr().err
    assert _bytes(files["rec"], files["rec"].with_suffix(".json"), files["params"]) == before
    assert main(["view", "--replay", str(files["rec"]), "--write-run", str(files["dir"] / "x.csv")]) == 1
    assert "give --model params.json" in capsys.readouterr().err


def test_export_plots_include_the_history_before_start(files, monkeypatch):
    """``--export --start`` draws the plots' past before the start (default the page's
    10 s window; ``--history S`` chooses), not a plot that begins at the start."""
    from boomfmi.view import export as ex
    seen = []
    original = ex.Drawing._update_plots
    monkeypatch.setattr(ex.Drawing, "_update_plots", lambda self, f: (seen.append(f["t"]), original(self, f)))
    path, n = ex.export(files["rec"], files["dir"] / "v.gif", fps=5, start=1.0, stop=1.2, size="320x200",
                        history=0.6)
    assert n == 2 and path.stat().st_size > 0
    assert min(seen) == pytest.approx(0.4) and sum(t < 1.0 for t in seen) == 3
    with pytest.raises(ValueError, match="--history"):
        ex.export(files["rec"], files["dir"] / "w.gif", fps=5, start=1.0, history=-1)
    assert not (files["dir"] / "w.gif").exists()


# -- item 5: the default paths from any working directory ------------------------------------
def _cli(*args, cwd, env=None):
    return subprocess.run([sys.executable, "-m", "boomfmi.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT / "src"), **(env or {})})


def test_record_finds_its_default_bridge_from_another_directory(tmp_path):
    """Run outside the checkout, `record`'s default bridge FMU is the checkout's: it gets
    as far as the link (no key here), not "build/fmus/excavator_bridge.fmu: no such FMU"."""
    if not (ROOT / "build" / "fmus" / "excavator_bridge.fmu").is_file():
        pytest.skip("the excavator bridge is not built (python build_fmus.py excavator_bridge)")
    env = {"BOOMFMI_LINK_KEY": "", "BOOMFMI_BUILD": ""}
    r = _cli("record", "--experiment", "digging_cycle", "--rig", "udp://127.0.0.1:9", "--out", "r.csv",
             cwd=tmp_path, env=env)
    assert r.returncode == 1 and "no such FMU" not in r.stderr, r.stderr
    assert "key" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "r.csv").exists()


def test_a_missing_default_fmu_names_where_it_looked_and_how_to_build(tmp_path):
    empty = tmp_path / "nobuild"
    empty.mkdir()
    r = _cli("record", "--experiment", "digging_cycle", "--rig", "udp://127.0.0.1:9", "--out", "r.csv",
             cwd=tmp_path, env={"BOOMFMI_BUILD": str(empty)})
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert f"{empty}/fmus/excavator_bridge.fmu: no such FMU" in r.stderr
    assert "python build_fmus.py excavator_bridge" in r.stderr and "--fmu" in r.stderr and "$BOOMFMI_BUILD" in r.stderr
    assert not (tmp_path / "r.csv").exists()


def test_check_replays_the_references_from_another_directory(tmp_path):
    """`check`'s default references are the checkout's fmus/, not ./fmus: from another
    directory it still replays each FMU's reference result (it skipped them silently)."""
    fmu = ROOT / "build" / "fmus" / "linkage.fmu"
    if not fmu.is_file():
        pytest.skip("the linkage FMU is not built")
    (tmp_path / "fmus").mkdir()
    shutil.copy(fmu, tmp_path / "fmus")
    r = _cli("check", "fmus", cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "linkage.fmu" in r.stdout and "reference result max rel. error" in r.stdout
    r = _cli("check", "fmus", "--references", "nowhere", cwd=tmp_path)
    assert r.returncode == 1 and "--references nowhere: no such folder" in r.stderr


# -- the page: the interval, the legends, titles clear of the plot above ----------------------
from test_view import CHROMIUM, CHROMEDRIVER, View, _severe, _wait, driver  # noqa: E402,F401  (one browser set-up)

browser = pytest.mark.skipif(not (CHROMIUM and CHROMEDRIVER), reason="chromium and chromedriver are not installed")

#: the plots' boxes: each plot's title, its canvas (the chart with its axes and their
#: labels, drawn in the canvas) and its legend, and the labels of each legend
_BOXES = """
const box = (e) => { const r = e.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; };
return [...document.querySelectorAll('#plots .plot')].map((div) => ({
  plot: box(div), title: box(div.querySelector('.u-title')), chart: box(div.querySelector('.u-wrap')),
  legend: box(div.querySelector('.u-legend')),
  labels: [...div.querySelectorAll('.u-legend .u-series')].filter((e) => e.offsetParent !== null)
          .map((e) => e.textContent.trim()),
  colours: [...div.querySelectorAll('.u-legend .u-series')].filter((e) => e.offsetParent !== null)
           .map((e) => getComputedStyle(e.querySelector('.u-marker')).borderColor)}));
"""


@browser
def test_the_page_draws_the_interval_with_legends_and_no_title_over_the_plot_above(files, driver):
    out = files["dir"] / "page_run.csv"
    assert main(["view", "--replay", str(files["rec"]), "--model", str(files["params"]), "--write-run",
                 str(out)]) == 0
    run = load_run(out)
    lo, hi = run.forces["f_tip_lo"], run.forces["f_tip_hi"]
    bounded = np.flatnonzero(np.isfinite(lo).any(axis=1) & np.isfinite(hi).any(axis=1)
                             & (np.linalg.norm(run.forces["f_tip_est"], axis=1) > 1.0))
    assert bounded.size, "no sample with a bounded interval and an arrow"
    t_b = float(run.t[bounded[len(bounded) // 2]])
    view = View("--replay", str(out))
    try:
        for size in ((1280, 800), (1920, 1080)):
            driver.set_window_size(*size)
            inner = driver.execute_script("return [window.innerWidth, window.innerHeight]")
            driver.set_window_size(2 * size[0] - inner[0], 2 * size[1] - inner[1])   # the viewport at size
            driver.get(view.url)
            _wait(driver, "return window.boomView && window.boomView.framesReceived > 5")
            driver.execute_script(f"window.boomView.pause(); window.boomView.seek({t_b});")
            s = _wait(driver, f"const s = window.boomView.state(); return s && !s.playing && "
                              f"Math.abs(s.t - {t_b}) < 1e-6 && s.intervalBox.visible && s")
            assert driver.execute_script("return [window.innerWidth, window.innerHeight]") == list(size)
            box, f = s["intervalBox"], np.array(s["fTipEst"])
            assert s["fTipLo"] is not None and s["fTipHi"] is not None
            scale = driver.execute_script("return window.boomView.hello.scene.force_scale")
            head = np.array(s["arrowEst"]["head"])
            tail = head - f * scale              # the estimate's own tail (at the page's scale) lies in the box
            assert np.all(np.array(box["min"]) <= tail + 1e-9) and np.all(tail <= np.array(box["max"]) + 1e-9)
            drawn = 0
            for k in range(3):                   # a side the run bounds (within the drawn reach) where it bounds it
                for side, value, corner, sign in ((1, s["fTipHi"][k], box["min"][k], 1), (0, s["fTipLo"][k],
                                                                                           box["max"][k], -1)):
                    if value is not None and abs(value - f[k]) < 100:
                        assert not box["open"][k][side]
                        assert corner == pytest.approx(head[k] - value * scale, abs=1e-9)
                        drawn += 1
                    else:
                        assert box["open"][k][side]
            assert drawn, "no bounded side drawn"
            assert driver.execute_script("return !document.querySelector('#legend .band').hidden")  # named too
            plots = driver.execute_script(_BOXES)
            assert len(plots) == 4
            want = [{f"{j}" for j in JOINTS} | {f"{j} model" for j in JOINTS}] * 3 + [
                {f"{w} {a}" for a in "xyz" for w in ("est", "truth")} | {f"{a} {w}" for a in "xyz" for w in ("low", "high")}]
            for p, labels in zip(plots, want):
                assert set(p["labels"]) == labels, p["labels"]           # every colour named
                for part in ("title", "chart", "legend"):                # each inside its own box
                    r = p[part]
                    assert r[1] >= p["plot"][1] - 0.5 and r[3] <= p["plot"][3] + 0.5, (size, part, p)
                    assert r[3] <= size[1] + 0.5, (size, part, p)
                assert p["title"][3] <= p["chart"][1] + 0.5 and p["chart"][3] <= p["legend"][1] + 0.5
                assert p["chart"][3] - p["chart"][1] >= 40, (size, p)
            for above, below in zip(plots, plots[1:]):                   # no title over the plot above
                assert below["title"][1] >= above["chart"][3] - 0.5, (size, above, below)
                assert below["title"][1] >= above["legend"][3] - 0.5, (size, above, below)
            ARTIFACTS = ROOT / "build" / "test-artifacts"
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            driver.save_screenshot(str(ARTIFACTS / f"excavator_run_{size[0]}x{size[1]}.png"))
        assert _severe(driver) == []
    finally:
        view.stop()
