"""Reference results next to each FMU, in the manner of the Modelica Reference-FMUs.

``fmus/<name>/<name>_in.csv`` holds a small input table (``time`` and the FMU's
inputs); ``fmus/<name>/<name>_ref.csv`` the outputs the built FMU gives for it, as
:func:`boomfmi.system.instance.run_table` replays it.  The tests replay every pair
through the built ``.fmu``; ``python build_fmus.py --write-references`` rewrites the
``_ref.csv`` files after a deliberate change of the physics, at a fixed precision
(:data:`FLOAT_FORMAT`), leaving a file whose table only floating-point noise changed
as it is (:data:`NOISE`): a rebuild on a clean clone changes nothing.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd

from ..physics import reference_rig
from ..system.instance import run_table


def _valve() -> pd.DataFrame:
    u = np.array([5.0, 4.0, 2.5, 1.0, 0.0, 6.0, 7.5, 9.0, 10.0, 5.0, 3.0, 8.0])
    p_a = np.array([1.0, 2.0, 3.0, 5.0, 7.0, 7.0, 4.0, 2.0, 1.2, 3.0, 6.9, 1.1]) * 1e5 + reference_rig.P_atm
    p_b = np.array([1.0, 6.0, 4.0, 0.5, 0.0, 0.2, 3.0, 5.5, 6.5, 3.0, 0.1, 6.9]) * 1e5 + reference_rig.P_atm
    return pd.DataFrame({"time": np.arange(len(u)) * 1e-3, "u": u, "p_a": p_a, "p_b": p_b})


def _cylinder() -> pd.DataFrame:
    t = np.arange(0.0, 0.1001, 1e-3)
    x = 0.03 + 0.02 * np.sin(2 * np.pi * 5 * t)
    v = 0.02 * 2 * np.pi * 5 * np.cos(2 * np.pi * 5 * t)
    return pd.DataFrame({"time": t, "mdot_a": np.where(t < 0.05, 1e-3, -5e-4),
                         "mdot_b": np.where(t < 0.05, -1e-4, 1e-3), "x": x, "v": v})


def _boom_load() -> pd.DataFrame:
    t = np.arange(0.0, 1.5001, 5e-3)
    p_a = reference_rig.P_atm + np.interp(t, [0, 0.2, 0.8, 0.9, 1.5], [0, 6e5, 6e5, 0, 0])
    p_b = reference_rig.P_atm + np.interp(t, [0, 0.8, 0.9, 1.0, 1.5], [0, 0, 6e5, 6e5, 6e5])
    f_ext = np.where((t > 0.4) & (t < 0.5), 150.0, 0.0)
    return pd.DataFrame({"time": t, "p_a": p_a, "p_b": p_b, "f_ext": f_ext})


def _force_estimator() -> pd.DataFrame:
    """The machine extending at 50 mm/s as its chamber A pressure rises (the default
    observer method), the model drawing ahead of it."""
    t = np.arange(0.0, 0.2001, 1e-3)
    x_measured = 0.02 + 0.05 * t
    return pd.DataFrame({"time": t, "x_model": x_measured + 0.01 * t, "v_model": np.full_like(t, 0.06),
                         "p_a_model": 4e5 + 2e5 * t, "p_b_model": np.full_like(t, 2e5),
                         "x_measured": x_measured, "p_a_measured": 3e5 + 2e5 * t,
                         "p_b_measured": np.full_like(t, 1e5)})


def _linkage() -> pd.DataFrame:
    """The four joints from mid-stroke: boom raised, arm and bucket driven, a swing
    pulse, and a tip force (down and back) from 0.3 to 0.4 s."""
    t = np.arange(0.0, 0.5001, 5e-3)
    P = reference_rig.P_atm
    on = (t > 0.3) & (t < 0.4)
    return pd.DataFrame({
        "time": t,
        "p_a_swing": P + np.where((t > 0.1) & (t < 0.25), 2e5, 0.0), "p_b_swing": np.full_like(t, P),
        "p_a_boom": P + np.interp(t, [0, 0.1, 0.5], [2.5e5, 4e5, 4e5]), "p_b_boom": np.full_like(t, P + 1e5),
        "p_a_arm": np.full_like(t, P + 2e5), "p_b_arm": P + np.interp(t, [0, 0.2, 0.5], [3e5, 0.0, 0.0]),
        "p_a_bucket": np.full_like(t, P + 1.5e5), "p_b_bucket": np.full_like(t, P + 1e5),
        "f_tip_x": np.where(on, -30.0, 0.0), "f_tip_y": np.zeros_like(t), "f_tip_z": np.where(on, -50.0, 0.0)})


#: The excavator force estimator's window of the digging cycle on hard soil [s]: the
#: machine at rest at its start, the bucket meeting the soil at 2.16 s, 0 to 3 joints
#: informative in it (the world z component determined for 0.2 s of the contact, x and y
#: never: the swing on its stop).
EXCAVATOR_WINDOW = (1.9, 3.4)


def _excavator_force_estimator() -> pd.DataFrame:
    """1.5 s of the excavator's virtual rig (seeded: deterministic) on the digging cycle
    with the hard_soil contact, sampled at 1 ms, times from 0: the measured pressures
    (gauge) and angles, the FMU's inputs."""
    from .. import experiments as E
    from ..physics.linkage import JOINTS
    from ..rig import run_excavator_offline
    t0, t1 = EXCAVATOR_WINDOW
    d = run_excavator_offline({"machine": "excavator", "contact": E.contact("hard_soil").config()},
                              E.digging_cycle(), t1)
    d = d[d["t"] >= t0 - 1e-9].reset_index(drop=True)
    table = {"time": np.round(d["t"].to_numpy() - t0, 9)}
    for j in JOINTS:
        for q in ("p_a", "p_b", "angle"):
            table[f"{q}_{j}"] = d[f"{q}_{j}"].to_numpy()
    return pd.DataFrame(table)


INPUTS = {"valve": _valve, "cylinder": _cylinder, "boom_load": _boom_load,
          "force_estimator": _force_estimator, "linkage": _linkage,
          "excavator_force_estimator": _excavator_force_estimator}


def paths(fmu_dir: Path) -> tuple[Path, Path]:
    name = Path(fmu_dir).name
    return Path(fmu_dir) / f"{name}_in.csv", Path(fmu_dir) / f"{name}_ref.csv"


#: The precision of a reference CSV: 12 significant digits, 1000 times finer than the
#: tests' tolerance (``rtol=1e-9`` in ``tests/test_reference_results.py``) and 100 times
#: coarser than the floating-point noise of one build against another (about 1e-14
#: relative: the excavator's rig and linkage in their last digits).
FLOAT_FORMAT = "%.12g"
#: Two tables that agree within this (relative, and absolute near zero) are one result:
#: a rewrite keeps the committed text, so that a rebuild changes no file by noise alone.
NOISE = 1e-11


def _text(table: pd.DataFrame) -> str:
    return table.to_csv(index=False, float_format=FLOAT_FORMAT, lineterminator="\n")


def _same(text: str, old: Path) -> bool:
    """Whether the table ``text`` holds is the one in the file ``old`` within :data:`NOISE`
    (same columns, same rows)."""
    if not old.is_file():
        return False
    a, b = pd.read_csv(io.StringIO(text)), pd.read_csv(old)
    if list(a.columns) != list(b.columns) or a.shape != b.shape:
        return False
    return bool(np.allclose(a.to_numpy(float), b.to_numpy(float), rtol=NOISE, atol=NOISE, equal_nan=True))


def reference_texts(name: str, fmu_path: Path, fmu_dir: Path | None = None) -> tuple[str, str]:
    """The text of ``<name>_in.csv`` and ``<name>_ref.csv`` as :func:`write_references`
    writes them from the FMU at ``fmu_path``: at :data:`FLOAT_FORMAT`, and the committed
    text (in ``fmu_dir``) wherever the fresh table equals it within :data:`NOISE`."""
    in_text = _text(INPUTS[name]())
    in_csv, ref_csv = paths(fmu_dir) if fmu_dir is not None else (Path(), Path())
    if fmu_dir is not None and _same(in_text, in_csv):
        in_text = in_csv.read_text()
    ref = run_table(fmu_path, pd.read_csv(io.StringIO(in_text)))
    # Boolean outputs as 0 and 1 (as fmpy writes them), which compare as numbers
    ref = ref.astype({c: int for c in ref.columns if ref[c].dtype == bool})
    ref_text = _text(ref)
    if fmu_dir is not None and _same(ref_text, ref_csv):
        ref_text = ref_csv.read_text()
    return in_text, ref_text


def write_references(fmu_dir: Path, fmu_path: Path) -> Path:
    """Write ``<name>_in.csv`` and ``<name>_ref.csv`` next to the FMU's script, each at
    :data:`FLOAT_FORMAT`; a file whose table is unchanged within :data:`NOISE` is left
    as it is (a rebuild on a clean clone changes nothing)."""
    name = Path(fmu_dir).name
    in_csv, ref_csv = paths(fmu_dir)
    in_text, ref_text = reference_texts(name, fmu_path, fmu_dir)
    for path, text in ((in_csv, in_text), (ref_csv, ref_text)):
        if not path.is_file() or path.read_text() != text:
            path.write_text(text)
    return ref_csv


__all__ = ["EXCAVATOR_WINDOW", "INPUTS", "paths", "FLOAT_FORMAT", "NOISE", "reference_texts", "write_references"]
