#!/usr/bin/env python3
"""Real-time factor of the full boom and of the whole excavator at a 1 ms step, and
their FMI-call floors.

Runs build/excavator_boom.ssp (Gauss-Seidel, 1 ms) over 10 simulated seconds of the
paper's command profile, and build/excavator.ssp (nine FMUs: four valves, four
cylinders, the linkage) over 10 s of the digging cycle and over 10 s of
excavator_excitation (every joint moving), and prints for each the real-time factor
(simulated seconds per wall second).  Then runs the same system with every FMU
replaced by a "null" FMU built the same way (pythonfmu, boomfmi's base class and
status shim, the same variables and dependencies) whose step computes nothing but
moves each output to the step's time.  The ratio of the two wall times says how much
of the run is the model's own work and how much the FMI call path (fmpy -> shim ->
pythonfmu -> Python).  Each figure is the best of --repeat runs, pinned to one core.

The master skips writing an input whose value has not changed.  In the floor every
input changes every step, so it makes every call the master can make, as the full
system does while every joint moves (excavator_excitation); on the digging cycle the
resting joints' valves and cylinders keep their inputs, and the full run makes fewer
calls than its floor.

    python benchmarks/cosim_speed.py [--repeat 3] [--systems boom,excavator,excavator_excitation]
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from fmpy import read_model_description  # noqa: E402

from boomfmi.experiments import digging_cycle, excavator_excitation, paper_multistep  # noqa: E402
from boomfmi.fmubuild import build_fmu  # noqa: E402
from boomfmi.system import CoSimulation  # noqa: E402

NULL_SCRIPT = '''"""null_{name}: the interface of {name}, computing nothing (benchmark floor)."""
from boomfmi_null_{name}_lib.fmislave import BoomSlave, Variable


class Null{cls}(BoomSlave):
    description = "computes nothing: the FMI-call floor of {name}"
    variables = {variables!r}

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.modelName = "null_{name}"
        self._outputs = [v.name for v in self.variables if v.causality == "output" and v.type == "Real"]

    def step(self, t, dt):
        # the outputs move every step, as the model's do: the master skips writing an
        # input whose value has not changed, and constant outputs would spare it calls
        for name in self._outputs:
            setattr(self, name, t)
'''


def null_fmu(fmu: Path, workdir: Path) -> Path:
    """Build a null FMU with the same variables and dependencies as ``fmu``."""
    md = read_model_description(str(fmu))
    deps = {u.variable.name: tuple(d.name for d in u.dependencies) for u in md.outputs}
    from boomfmi.fmislave import Variable
    variables = []
    for v in md.modelVariables:
        start = float(v.start) if v.start is not None else (1.0e5 if v.unit == "Pa" else 0.0)
        variables.append(Variable(v.name, v.causality, v.unit or "1", v.description, start,
                                  None, None, "Real", deps.get(v.name, ())))
    name = md.coSimulation.modelIdentifier
    folder = workdir / f"null_{name}"
    folder.mkdir()
    script = NULL_SCRIPT.format(name=name, cls=name.title().replace("_", ""),
                                variables=tuple(variables))
    script = script.replace("Variable(name=", "Variable(").replace("boomfmi.fmislave.", "")
    (folder / f"null_{name}_fmu.py").write_text(script)
    return build_fmu(folder, workdir / "built")


def null_ssp(ssp: Path, workdir: Path) -> Path:
    """The same SSP with each component's FMU replaced by its null twin."""
    out = workdir / "null.ssp"
    with zipfile.ZipFile(ssp) as src, zipfile.ZipFile(out, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename.endswith(".fmu"):
                tmp = workdir / Path(item.filename).name
                tmp.write_bytes(data)
                data = null_fmu(tmp, workdir).read_bytes()
            dst.writestr(item, data)
    return out


#: the whole excavator's command profiles: the digging cycle (one or two joints move at a
#: time, the others rest with their valves closed, so the master skips their unchanged
#: inputs) and the identification's excitation (every joint moving all the time)
EXCAVATOR_PROFILES = {"excavator": digging_cycle, "excavator_excitation": excavator_excitation}


def best_wall(ssp: Path, stop: float, repeat: int, excavator: str | None = None) -> float:
    """The best wall time [s] of ``repeat`` runs: the boom on the paper's profile, the
    whole excavator on the profile ``EXCAVATOR_PROFILES[excavator]``, each repeated to
    ``stop``."""
    if excavator:
        dig = EXCAVATOR_PROFILES[excavator]()
        inputs = lambda s: {f"valve_{k[2:]}.u": u for k, u in dig(s % dig.duration).items()}   # noqa: E731
    else:
        profile = paper_multistep()
        inputs = lambda s: {"valve.u": profile(s % profile.duration)["u"]}   # noqa: E731
    walls = []
    for _ in range(repeat):
        with CoSimulation(ssp, 1e-3, "gauss-seidel") as cosim:
            t = time.perf_counter()
            cosim.simulate(stop, inputs)
            walls.append(time.perf_counter() - t)
    return min(walls)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ssp", type=Path, default=ROOT / "build" / "excavator_boom.ssp")
    ap.add_argument("--excavator-ssp", type=Path, default=ROOT / "build" / "excavator.ssp",
                    help="the whole excavator (9 FMUs), run on the digging cycle")
    ap.add_argument("--systems", default="boom,excavator,excavator_excitation",
                    help="which systems: boom, excavator (the digging cycle), excavator_excitation")
    ap.add_argument("--stop", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, one core")
    for system in args.systems.split(","):
        excavator = system if system in EXCAVATOR_PROFILES else None
        ssp = args.excavator_ssp if excavator else args.ssp
        with tempfile.TemporaryDirectory() as tmp:
            floor_ssp = null_ssp(ssp, Path(tmp))
            full = best_wall(ssp, args.stop, args.repeat, excavator)
            floor = best_wall(floor_ssp, args.stop, args.repeat, excavator)
        n = _components(ssp)
        print(f"{system} ({n} FMUs), 1 ms step, {args.stop:g} s simulated: {full:.3f} s wall, "
              f"real-time factor {args.stop / full:.2f}")
        print(f"  FMI-call floor (null FMUs, every input changing every step): {floor:.3f} s wall, "
              f"real-time factor {args.stop / floor:.2f}")
        print(f"  ratio full / floor: {full / floor:.2f} (the model's work is {100 * (1 - floor / full):.0f} % "
              f"of the run{'; fewer calls than the floor: resting joints keep their inputs' if excavator == 'excavator' else ''})")
    return 0


def _components(ssp: Path) -> int:
    from boomfmi.system.ssp import read_ssp
    return len(read_ssp(ssp).components)


if __name__ == "__main__":
    sys.exit(main())
