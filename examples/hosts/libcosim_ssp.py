"""Run boomfmi's SSP in libcosim (through libcosimpy), driving the valve's command over
time.  From the repository's root, after ``./run.sh`` (or ``build_fmus.py``)::

    .venv/bin/python examples/hosts/libcosim_ssp.py                  # the boom, paper_multistep

- libcosim 0.11 refuses a connection from a system input connector ("No such node
  (<xmlattr>.startElement)"), so it takes the copy in ``build/osp/`` (the same system,
  the valve's ``u`` a free input; ``boomfmi.fmubuild.ssp.osp_ssp`` writes one for any SSP).
- The SSD's parameter bindings (``reference_rig``) apply as they are.
- The command is set by an override manipulator before the step it is for.
- libcosim logs every step at ``debug`` unless told otherwise: the level is lowered here.

libcosim steps as boomfmi's Jacobi master does; its k-th sample is the master's row at
t_(k+1) (``tests/test_hosts.py`` compares the two to 1e-6).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from boomfmi import experiments

#: what is written for each component (libcosim observes every variable; these are the plot's)
OUTPUTS = {"boom_load": ("x", "v"), "cylinder": ("p_a", "p_b")}


def run(ssp, experiment: str = "paper_multistep", step: float = 1e-3,
        stop_time: float | None = None) -> pd.DataFrame:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver

    osp = Path(ssp)
    if osp.parent.name != "osp":                 # build/x.ssp -> build/osp/x.ssp
        osp = osp.parent / "osp" / osp.name
    if not osp.is_file():
        raise FileNotFoundError(f"{osp} does not exist: build_fmus.py writes it beside {ssp}")
    profile = getattr(experiments, experiment)()
    stop = float(stop_time if stop_time is not None else profile.duration)
    step_ns = round(step * 1e9)
    log_output_level(CosimLogLevel.WARNING)
    ex = CosimExecution.from_ssp_file(str(osp), step_size=step_ns)
    slaves = {n: ex.slave_index_from_instance_name(n) for n in ("valve", *OUTPUTS)}
    ref = {(n, v.name.decode()): v.reference for n, i in slaves.items() for v in ex.slave_variables(i)}
    observer, manipulator = CosimObserver.create_last_value(), CosimManipulator.create_override()
    if not (ex.add_observer(observer) and ex.add_manipulator(manipulator)):
        raise RuntimeError("libcosim would not take the observer or the manipulator")
    rows, u_now = [], None
    for k in range(round(stop / step)):
        u = profile(k * step)["u"]
        if u != u_now:           # takes effect in this very step, before fmi2DoStep(t_k)
            manipulator.slave_real_values(slaves["valve"], [ref[("valve", "u")]], [u])
            u_now = u
        if not ex.step():
            raise RuntimeError(f"libcosim failed its step at t = {k * step:g} s")
        row = {"time": ex.status().current_time / 1e9, "valve.u": u}
        for name, variables in OUTPUTS.items():
            values = observer.last_real_values(slaves[name], [ref[(name, v)] for v in variables])
            row.update({f"{name}.{v}": value for v, value in zip(variables, values)})
        rows.append(row)
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ssp", nargs="?", default="build/excavator_boom.ssp", type=Path)
    ap.add_argument("--experiment", default="paper_multistep",
                    help="a one-valve profile of boomfmi.experiments (paper_multistep, random_steps, ...)")
    ap.add_argument("--step", type=float, default=1e-3, help="communication step [s]")
    ap.add_argument("--stop-time", type=float, help="[s]; the experiment's duration by default")
    ap.add_argument("--out", type=Path, default=Path("libcosim_run.csv"))
    a = ap.parse_args(argv)
    try:
        df = run(a.ssp, a.experiment, a.step, a.stop_time)
    except FileNotFoundError as e:
        sys.exit(f"libcosim_ssp.py: error: {e}")
    df.to_csv(a.out, index=False)
    print(f"libcosim ran {a.ssp.name} for {df['time'].iloc[-1]:g} s: {len(df)} rows in {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
