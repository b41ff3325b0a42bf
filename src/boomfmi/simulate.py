"""Run an experiment on an SSP system and return it in the recording format.

``run_experiment`` drives the system's free input named ``u`` (the valve command) with
a named command profile or with the ``u`` column of a recording, runs the
co-simulation, and returns the columns of a recording (``t, u, p_a, p_b, alpha``, gauge
pressures) plus ``x`` and ``v``, so that model output and rig recordings compare
column by column.  The columns are found by name among the components' outputs
(``p_a`` is the one output called ``p_a``), not wired here.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from .experiments import PROFILES, profile
from .physics import reference_rig as rig
from .recording import read_recording
from .system.master import CoSimulation

RECORDED = ("p_a", "p_b", "alpha", "x", "v")


def _unique(names: list[str], short: str, what: str) -> str:
    hits = [n for n in names if n.rpartition(".")[2] == short]
    if len(hits) != 1:
        raise ValueError(f"the system must have exactly one {what} named {short!r}, it has {hits or 'none'}")
    return hits[0]


def experiment_inputs(experiment: str, input_name: str):
    """``(inputs, stop_time)`` for a named profile or a recording's ``u`` column."""
    if experiment in PROFILES:
        prof = profile(experiment)
        return (lambda t: {input_name: prof(t)["u"]}), prof.duration
    path = Path(experiment)
    if path.suffix.lower() != ".csv" and not path.exists():
        raise ValueError(f"unknown experiment {experiment!r}: give one of {', '.join(PROFILES)} "
                         f"or a recording (.csv)")
    rec = read_recording(path)
    table = pd.DataFrame({"t": rec.data["t"], input_name: rec.data["u"]})
    return table, float(rec.data["t"].iloc[-1])


def run_experiment(ssp, experiment: str = "paper_multistep", step: float = 1e-3,
                   stop_time: float | None = None, algorithm: str = "gauss-seidel",
                   parameters=None, progress: bool = False) -> pd.DataFrame:
    """Simulate ``experiment`` on the SSP; return recording columns plus x and v."""
    with CoSimulation(ssp, step, algorithm, parameters) as cosim:
        u_name = _unique(cosim.inputs, "u", "free input")
        inputs, duration = experiment_inputs(experiment, u_name)
        result = cosim.simulate(stop_time if stop_time is not None else duration, inputs,
                                progress=progress)
        outputs = [c for c in result.columns if c.count(".") == 1 and c not in cosim.inputs]
        P_atm = next((float(p.value) for n, p in cosim.structure.parameters.items()
                      if n.endswith(".P_atm")), rig.P_atm)
    out = pd.DataFrame({"t": result["time"], "u": result[u_name]})
    for name in RECORDED:
        col = result[_unique(outputs, name, "output")]
        out[name] = col - P_atm if name in ("p_a", "p_b") else col
    return out
