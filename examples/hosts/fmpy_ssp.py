"""Run boomfmi's SSP in fmpy's own SSP runner, a changing command and the parameter set
included.  From the repository's root, after ``./run.sh`` (or ``build_fmus.py``)::

    .venv/bin/python examples/hosts/fmpy_ssp.py                      # the boom, paper_multistep
    .venv/bin/python examples/hosts/fmpy_ssp.py build/excavator.ssp --experiment digging_cycle

What this needs that a plain ``simulate_ssp(ssp, parameter_set={"valve.u": 1.0})`` does
not give (fmpy then fails with "'dict' object has no attribute 'parameters'"):

- ``parameter_set`` is an fmpy ``ParameterSet``: the SSP carries its set whole, with
  hierarchical names (``resources/reference_rig.ssv`` or ``resources/excavator.ssv``),
  read with ``fmpy.ssp.ssd.read_ssv``.  fmpy applies none of the SSD's own bindings.
- the command goes to the system's input connectors (``u``, or ``u_swing`` ... on the
  excavator) as ``input={name: function of time}``; ``boomfmi.system.fmpy_input`` makes
  them from a named experiment and reads the command at the communication point
  nearest fmpy's float time (fmpy adds the step up: 2.9999999999997806 for 3 s).

fmpy's row k matches boomfmi's Jacobi master's row k (docs/hosts.md has the figures).
"""
from __future__ import annotations

import argparse
import sys
import zipfile
from pathlib import Path

import pandas as pd
from fmpy.ssp.ssd import read_ssv
from fmpy.ssp.simulation import simulate_ssp

from boomfmi import experiments
from boomfmi.system import fmpy_input


def parameter_set_of(ssp: Path) -> str:
    """The SSP's whole parameter set, ``resources/<set>.ssv`` beside the per-component
    ``resources/<set>_<component>.ssv`` files its SSD binds."""
    with zipfile.ZipFile(ssp) as z:
        sets = sorted(n for n in z.namelist() if n.startswith("resources/") and n.endswith(".ssv"))
    whole = [s for s in sets if any(o.startswith(s[:-len(".ssv")] + "_") for o in sets)]
    if len(whole) != 1:
        raise ValueError(f"{ssp}: expected one whole parameter set beside its components' sets, "
                         f"found {whole or sets or 'none'}")
    return whole[0]


def run(ssp, experiment: str = "paper_multistep", step: float = 1e-3,
        stop_time: float | None = None) -> pd.DataFrame:
    """fmpy's run of ``ssp`` under the named experiment: time and every output, as a table."""
    ssp = Path(ssp)
    profile = getattr(experiments, experiment)()
    stop = float(stop_time if stop_time is not None else profile.duration)
    rows = simulate_ssp(str(ssp), stop_time=stop, step_size=step,
                        parameter_set=read_ssv(str(ssp), resource=parameter_set_of(ssp)),
                        input=fmpy_input(ssp, profile, step))
    return pd.DataFrame({name: rows[name] for name in rows.dtype.names})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ssp", nargs="?", default="build/excavator_boom.ssp", type=Path)
    ap.add_argument("--experiment", default="paper_multistep",
                    help="a profile of boomfmi.experiments (paper_multistep, digging_cycle, ...)")
    ap.add_argument("--step", type=float, default=1e-3, help="communication step [s]")
    ap.add_argument("--stop-time", type=float, help="[s]; the experiment's duration by default")
    ap.add_argument("--out", type=Path, default=Path("fmpy_run.csv"))
    a = ap.parse_args(argv)
    if not a.ssp.is_file():
        sys.exit(f"fmpy_ssp.py: error: {a.ssp} does not exist (run ./run.sh or build_fmus.py first)")
    df = run(a.ssp, a.experiment, a.step, a.stop_time)
    df.to_csv(a.out, index=False)
    print(f"fmpy ran {a.ssp.name} for {len(df) * a.step:g} s: {len(df)} rows in {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
