"""Replay each FMU's reference inputs (fmus/<name>/<name>_in.csv) through the built
.fmu and compare with its reference outputs (<name>_ref.csv)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from boomfmi.system.instance import run_table

ROOT = Path(__file__).resolve().parents[1]


#: the FMUs whose reference pair is replayed here (linkage's: tests/test_linkage.py)
NAMES = ["valve", "cylinder", "boom_load", "force_estimator", "excavator_force_estimator"]


def test_every_generated_reference_is_on_disk_and_replayed():
    from boomfmi.fmubuild.references import INPUTS, paths
    assert set(INPUTS) == set(NAMES) | {"linkage"}
    for name in INPUTS:
        assert all(p.is_file() for p in paths(ROOT / "fmus" / name)), name


@pytest.mark.parametrize("name", NAMES)
def test_reference_result(fmu, name):
    folder = ROOT / "fmus" / name
    inputs = pd.read_csv(folder / f"{name}_in.csv")
    expected = pd.read_csv(folder / f"{name}_ref.csv")
    result = run_table(fmu(name), inputs)
    assert list(result.columns) == list(expected.columns)
    assert len(result) == len(expected) == len(inputs)
    for col in expected.columns:
        np.testing.assert_allclose(result[col], expected[col], rtol=1e-9, atol=1e-12, err_msg=col)
