"""A fixed-step co-simulation master for SSP systems, on fmpy's FMU instances.

Everything the master wires comes from the SSP: components, connections (with their
linear transformations) and parameter bindings.  What it adds over
``fmpy.ssp.simulate_ssp`` (FMPy issues #15, #234, #704): parameter bindings are
applied at system and component level (an unknown name is an error), linear
transformations are applied on every connection, the FMUs start from their own start
values, and every result row is stamped with the time its values belong to, starting
with a row at t0.

Inputs that no connection drives (``boom_load.f_ext``) and the system's own input
connectors (``u``, wired to ``valve.u``) are the run's inputs: they take the values
given to :meth:`CoSimulation.simulate`, or keep their start values.  A system input
connector is fed by the command as fmpy feeds it, and reaches the component inputs it
is connected to through the connection's linear transformation; the run lists it by
the component inputs it feeds (``valve.u``, the name it had before the SSDs declared
system connectors) and accepts either name.  The master takes each input at the
communication points only: a command that changes between two points is applied from
the next one on (a table's row at 0.3005 s, at a 1 ms step, from 0.301 s).

Time is kept as an integer number of nanoseconds, as libcosim does, so that long runs
do not drift and the step sizes handed to the FMUs are those libcosim hands them.

Algorithms, for each step from t_k to t_(k+1):

* **Jacobi** (libcosim's fixed-step algorithm): every component takes the inputs
  transferred after the previous step, all step, and then all outputs are read and
  transferred.  A direct-feedthrough output (the valve's flows) is thus seen by its
  consumers one step late.
* **Gauss-Seidel**: the components step one after another, each taking the newest
  outputs of those before it.  The order comes from the connection graph and the
  declared output dependencies: a component whose feedthrough outputs feed another
  steps first (strict; a feedthrough cycle is an algebraic loop and is refused), and
  among the rest those with fewer unmet inputs first, then SSD order.

Each row at t_k holds state outputs after the step to t_k and feedthrough outputs
evaluated with the inputs at t_k (the master sets those inputs and reads the outputs
again before recording), so every value in a row belongs to t_k.
"""
from __future__ import annotations

import math
import sys
import tempfile
import time as _time
from operator import itemgetter
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
import pandas as pd

from .instance import FmuInstance
from .ssp import SYSTEM, SystemStructure, check_against_fmus, read_ssp
from .ssv import Parameter, SspError, read_ssv

ALGORITHMS = ("gauss-seidel", "jacobi")
NS_PER_S = 1_000_000_000
#: The most communication steps one run may have: its rows are held in memory (a boom's
#: 13 columns take about 1 GB at this bound), and it is 2.8 hours at the 1 ms step, over
#: twice the longest recording read (``recording.MAX_BYTES``, about an hour at 1 kHz).
MAX_STEPS = 10_000_000


class _Progress:
    """A progress bar on stderr, shown only once a run has taken more than a second."""

    def __init__(self, total: float, enabled: bool):
        self.total, self.enabled = total, enabled
        self.start = _time.perf_counter()
        self.last = 0.0
        self.shown = False

    def update(self, done: float) -> None:
        if not self.enabled:
            return
        now = _time.perf_counter()
        if now - self.start < 1.0 or now - self.last < 0.1:
            return
        self.last, self.shown = now, True
        share = min(done / self.total, 1.0) if self.total > 0 else 1.0
        rate = done / (now - self.start)
        sys.stderr.write(f"\r[{'#' * int(30 * share):<30}] {100 * share:5.1f}%  "
                         f"t = {done:7.3f} s  ({rate:5.1f} x real time)")
        sys.stderr.flush()

    def close(self) -> None:
        if self.shown:
            sys.stderr.write("\n")


class CoSimulation:
    """An SSP system ready to run.

    Parameters
    ----------
    ssp : path of a ``.ssp`` archive (or a folder laid out like one).
    step : communication step [s].
    algorithm : ``"gauss-seidel"`` (default) or ``"jacobi"``.
    parameters : further parameter sets applied after the SSP's own bindings: paths of
        ``.ssv`` files (hierarchical names, ``valve.A_max``) and/or mappings.
    """

    def __init__(self, ssp, step: float, algorithm: str = "gauss-seidel", parameters=None):
        if algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {', '.join(ALGORITHMS)}, not {algorithm!r}")
        if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0):
            raise ValueError(f"the communication step must be > 0 s, not {step!r}")
        self.step_ns = int(round(step * NS_PER_S))
        if self.step_ns < 1:
            raise ValueError(f"the communication step {step} s is below a nanosecond")
        self.algorithm = algorithm
        self.structure: SystemStructure = read_ssp(ssp)
        self.given: set[str] = set()          #: names the caller's parameter sets bind
        for extra in _as_list(parameters):
            if isinstance(extra, Mapping):
                bound = {n: Parameter(n, _ptype(v), v) for n, v in extra.items()}
                self.structure.bind(bound, "parameters given to the master")
            else:
                path = Path(extra)
                if not path.is_file():
                    raise SspError(f"{path}: no such parameter set")
                bound = read_ssv(path.read_bytes(), str(path))
                self.structure.bind(bound, str(path))
            self.given.update(bound)
        self._tmp = tempfile.TemporaryDirectory(prefix="boomfmi_ssp_")
        self._ran = False
        self.instances: dict[str, FmuInstance] = {}
        try:
            for i, (name, comp) in enumerate(self.structure.components.items()):
                # the copy's name is its place in the SSD, never the component's name (data
                # from the file: ssp.read_ssp refuses any that is not a plain name)
                fmu_path = Path(self._tmp.name) / f"component{i}.fmu"
                fmu_path.write_bytes(self.structure.read(comp.source))
                try:
                    self.instances[name] = FmuInstance(fmu_path, name=name)
                except ValueError as e:       # not an FMU: named by its place in the SSP
                    raise SspError(str(e).replace(str(fmu_path), f"{self.structure.path}:{comp.source}")) from None
            check_against_fmus(self.structure, {n: i.model_description for n, i in self.instances.items()})
            check_shared(self.structure, self.instances)
            self._wire()
        except BaseException:
            self.close()
            raise

    @property
    def step_size(self) -> float:
        return self.step_ns / NS_PER_S

    # -- wiring --------------------------------------------------------------------------
    def _wire(self) -> None:
        s = self.structure
        names = list(self.instances)
        slot: dict[tuple[str, str], int] = {}

        def slot_of(element: str, connector: str) -> int:
            return slot.setdefault((element, connector), len(slot))

        # every Real output of every component has a slot (they are all recorded)
        self.outputs: dict[str, list[str]] = {}
        self.feedthrough: dict[str, set[str]] = {}
        for n in names:
            md = self.instances[n].model_description
            self.outputs[n] = [u.variable.name for u in md.outputs if u.variable.type == "Real"]
            self.feedthrough[n] = {u.variable.name for u in md.outputs
                                   if u.dependencies and u.variable.type == "Real"}
            for o in self.outputs[n]:
                slot_of(n, o)
        driven = {(c.end_element, c.end_connector) for c in s.connections if c.end_element}
        # the run's inputs: the system's input connectors, each named by the component
        # inputs it feeds (valve.u, fed by the system connector u: the names a system
        # without connectors gives them), and the component inputs nothing drives.
        # _input_map: a name the caller may give -> (slot, factor, offset), the slot
        # holding (value - offset) / factor; a system connector's own name is one too.
        self.inputs: list[str] = []
        self._input_map: dict[str, tuple[int, float, float]] = {}
        self._system_inputs: dict[str, list[tuple[str, float, float]]] = {}
        for c, kind in s.connectors.items():
            if kind not in ("input", "parameter"):
                continue
            i = slot_of(SYSTEM, c)
            fed = [(f"{conn.end_element}.{conn.end_connector}", conn.factor, conn.offset)
                   for conn in s.connections
                   if conn.start_element == SYSTEM and conn.start_connector == c and conn.end_element]
            self._system_inputs[c] = fed
            named = [(name, f, o) for name, f, o in fed if f != 0.0]   # a factor of 0 cuts the input off
            for name, f, o in named:
                self.inputs.append(name)
                self._input_map[name] = (i, f, o)
            if not named:
                self.inputs.append(c)
            self._input_map[c] = (i, 1.0, 0.0)
        free: dict[str, list[str]] = {n: [] for n in names}
        for n in names:
            for v in self.instances[n].model_description.modelVariables:
                if v.causality == "input" and v.type == "Real" and (n, v.name) not in driven:
                    free[n].append(v.name)
                    self.inputs.append(f"{n}.{v.name}")
                    self._input_map[f"{n}.{v.name}"] = (slot_of(n, v.name), 1.0, 0.0)

        incoming: dict[str, dict[str, tuple[int, float, float]]] = {n: {} for n in names}
        for n in names:
            for v in free[n]:
                incoming[n][v] = (slot[(n, v)], 1.0, 0.0)
        self.system_outputs: dict[str, tuple[int, float, float]] = {}
        for conn in s.connections:
            src = slot.get((conn.start_element, conn.start_connector))
            if src is None:
                raise SspError(f"{s.path}: connection {conn.describe()}: "
                               f"{conn.start_connector} is not a Real output")
            if conn.end_element == SYSTEM:
                self.system_outputs[conn.end_connector] = (src, conn.factor, conn.offset)
            elif conn.end_connector in incoming[conn.end_element]:
                raise SspError(f"{s.path}: input {conn.end_element}.{conn.end_connector} "
                               f"has more than one incoming connection")
            else:
                incoming[conn.end_element][conn.end_connector] = (src, conn.factor, conn.offset)
        self.n_slots = len(slot)
        self._slot = slot
        # the hot path's setters and getters (their value-reference arrays built once):
        # each component's driven inputs, its feedthrough outputs and all its outputs
        inst = self.instances

        def reader(n: str, outs: list[str]):
            return (inst[n].real_reader(inst[n].value_references(outs)) if outs else None,
                    [slot[(n, o)] for o in outs])
        self._write = {n: (inst[n].real_writer(inst[n].value_references(list(incoming[n])))
                           if incoming[n] else None, _gather(list(incoming[n].values()))) for n in names}
        self._feed_read = {n: reader(n, [o for o in self.outputs[n] if o in self.feedthrough[n]])
                           for n in names}
        self._all_read = {n: reader(n, self.outputs[n]) for n in names}
        feed_edges = {n: set() for n in names}
        soft_edges = {n: set() for n in names}
        for conn in s.connections:
            a, b = conn.start_element, conn.end_element
            if not (a and b):
                continue
            through = conn.start_connector in self.feedthrough[a]
            if a == b and through:
                raise SspError(f"{s.path}: algebraic loop: {conn.describe()} feeds {a}'s "
                               f"direct-feedthrough output back into its own input")
            if a != b:
                (feed_edges if through else soft_edges)[a].add(b)
        self.step_order = _order(names, feed_edges, soft_edges, str(s.path))
        self._feed_components = [n for n in self.step_order if self._feed_read[n][0]]
        # Integer and Boolean outputs (a bridge's link status) are recorded, not transferred
        self._discrete_out = {}
        for n in names:
            md = self.instances[n].model_description
            for typ in ("Integer", "Boolean"):
                vs = [u.variable for u in md.outputs if u.variable.type == typ]
                if vs:
                    self._discrete_out[(n, typ)] = ([v.valueReference for v in vs], [v.name for v in vs])

    # -- running -------------------------------------------------------------------------
    def _set_inputs(self, name: str, values: list[float]) -> None:
        write, sources = self._write[name]
        if write is not None:
            write(sources(values))

    def _read(self, name: str, which: dict, values: list[float]) -> None:
        read, slots = which[name]
        if read is not None:
            for i, v in zip(slots, read()):
                values[i] = v

    def simulate(self, stop_time: float | None = None, inputs=None, start_time: float | None = None,
                 progress: bool = False, monitor=None) -> pd.DataFrame:
        """Run from the start time to ``stop_time`` [s]; return one row per
        communication point, t0 included.

        ``inputs`` drives the run's inputs (``valve.u``, or the system connector ``u``
        that feeds it: one of the two names), each read at the communication points:
        a mapping of constants, a callable ``inputs(t) -> {name: value}``, or a
        DataFrame with a ``t`` (or ``time``) column whose rows hold from their time to
        the next.  An input not given keeps its start value.  ``monitor(columns, row)``,
        where given, sees each row as it is recorded (the live view's feed); it must be
        quick.
        """
        if self._ran:
            raise RuntimeError("a CoSimulation runs once (its FMUs have left initialisation); make a new one")
        self._ran = True
        s = self.structure
        t0 = s.start_time if start_time is None else float(start_time)
        t_end = s.stop_time if stop_time is None else float(stop_time)
        if t_end is None:
            raise ValueError("no stop time: give one (the SSD has no DefaultExperiment stopTime)")
        for what, t in (("start", t0), ("stop", t_end)):
            if not math.isfinite(t):
                raise ValueError(f"the {what} time must be a finite number of seconds, not {t}")
        t0_ns = int(round(t0 * NS_PER_S))
        n_steps = int(round((t_end - t0) * NS_PER_S / self.step_ns))
        if n_steps < 1:
            raise ValueError(f"stop time {t_end} s leaves no step of {self.step_size} s after {t0} s")
        if n_steps > MAX_STEPS:
            raise ValueError(f"stop time {t_end:g} s is {n_steps:.3g} steps of {self.step_size:g} s; a run may have "
                             f"at most {MAX_STEPS:,} (MAX_STEPS: {MAX_STEPS * self.step_size / 3600:.3g} h at this "
                             f"step, its rows held in memory): run it in parts")
        source = _input_source(inputs, list(self._input_map))

        by_comp: dict[str, dict] = {n: {} for n in self.instances}
        for name, p in s.parameters.items():
            element, _, var = name.partition(".")
            by_comp[element][var] = p.value
        for n, inst in self.instances.items():
            inst.initialize(by_comp[n], start_time=t0, stop_time=t_end)

        values = [0.0] * self.n_slots
        system_slots = {self._input_map[c][0] for c in self._system_inputs}
        for c in self._system_inputs:
            values[self._input_map[c][0]] = self._input_start(c)
        for name in self.inputs:
            if self._input_map[name][0] not in system_slots:
                values[self._input_map[name][0]] = self._input_start(name)
        for n in self.instances:
            self._read(n, self._all_read, values)
        columns, record = self._recording()
        rows = np.empty((n_steps + 1, len(columns)))
        m = len(record)
        take = _gather(record)
        bar = _Progress(t_end - t0, progress)
        input_slots = list(self._input_map.items())
        feed_buffer = list(values)

        def take_inputs(t: float) -> None:
            given = source(t)
            for name, (i, f, o) in input_slots:
                if name in given:
                    values[i] = (float(given[name]) - o) / f

        def record_row(k: int, t: float) -> None:
            # feedthrough outputs at t, from the inputs at t; Jacobi keeps them out of
            # the transfer (they reach consumers after the next step, as in libcosim)
            row_values = values
            if self._feed_components:
                if self.algorithm == "jacobi":
                    feed_buffer[:] = values
                    row_values = feed_buffer
                for n in self._feed_components:
                    self._set_inputs(n, row_values)
                    self._read(n, self._feed_read, row_values)
            rows[k, 0] = t
            rows[k, 1:m + 1] = take(row_values)
            j = m + 1
            for (n, typ), (vrs, _) in self._discrete_out.items():
                fmu = self.instances[n].fmu
                got = fmu.getInteger(vrs) if typ == "Integer" else fmu.getBoolean(vrs)
                rows[k, j:j + len(vrs)] = got
                j += len(vrs)

        # consistent start values (FMI 2.0, 3.2.3: a connected input starts at its output's
        # start value): a feedthrough output follows the other FMUs' start outputs, not its
        # own inputs' start values (the valve's flows at the cylinders' start pressures).
        # The inputs' values at t0 then reach it as in any Jacobi host (libcosim, fmpy, ecos).
        for _ in self._feed_components:
            for n in self._feed_components:
                self._set_inputs(n, values)
                self._read(n, self._feed_read, values)
        self._check_one_name_per_input(source(t0))
        take_inputs(t0)
        record_row(0, t0)
        order = self.step_order
        instances = self.instances
        try:
            for k in range(n_steps):
                t_k = (t0_ns + k * self.step_ns) / NS_PER_S
                t_next = (t0_ns + (k + 1) * self.step_ns) / NS_PER_S
                dt = t_next - t_k
                if self.algorithm == "jacobi":
                    for n in order:
                        self._set_inputs(n, values)
                    for n in order:
                        instances[n].step_to(t_k, dt)
                    for n in order:
                        self._read(n, self._all_read, values)
                else:
                    for n in order:
                        self._set_inputs(n, values)
                        instances[n].step_to(t_k, dt)
                        self._read(n, self._all_read, values)
                take_inputs(t_next)
                record_row(k + 1, t_next)
                if monitor is not None:
                    monitor(columns, rows[k + 1])
                bar.update(t_next - t0)
        finally:
            bar.close()
        return pd.DataFrame(rows, columns=columns)

    def _input_start(self, name: str) -> float:
        """A run's input starts at its parameter binding's value, else at the start value
        of the FMU input it is.  A system input connector starts at its own binding, else
        at the first one of the component inputs it feeds (their binding, else their
        start value) has, through the connection's transformation."""
        bound = self.structure.parameters.get(name)
        if bound is not None:
            return float(bound.value)
        fed = self._system_inputs.get(name)
        if fed is None:
            element, _, connector = name.rpartition(".")
            var = self.instances[element].variables[connector]
            return float(var.start) if var.start is not None else 0.0
        for target, f, o in fed:
            if f != 0.0:
                return (self._input_start(target) - o) / f
        return 0.0

    def _check_one_name_per_input(self, given) -> None:
        """Refuse inputs that set one system input connector under two names (``u`` and
        the ``valve.u`` it feeds)."""
        by_slot: dict[int, str] = {}
        for name in given:
            slot = self._input_map.get(name, (None,))[0]
            if slot is None:
                continue
            if slot in by_slot:
                raise ValueError(f"the inputs give {by_slot[slot]!r} and {name!r}, one system input connector "
                                 f"under two names: give one of them")
            by_slot[slot] = name

    def _recording(self):
        """Columns: time, the run's inputs, system outputs, then every component output."""
        columns, record = ["time"], []
        for name in self.inputs:
            columns.append(name)
            record.append(self._input_map[name])
        for c, (i, f, o) in self.system_outputs.items():
            columns.append(c)
            record.append((i, f, o))
        for n in self.instances:
            for o in self.outputs[n]:
                columns.append(f"{n}.{o}")
                record.append((self._slot[(n, o)], 1.0, 0.0))
        columns.extend(f"{n}.{name}" for (n, _), (_, names) in self._discrete_out.items() for name in names)
        return columns, record

    def close(self) -> None:
        for inst in self.instances.values():
            inst.close()
        self.instances = {}
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def simulate_ssp(ssp, stop_time=None, step: float = 1e-3, algorithm: str = "gauss-seidel",
                 inputs=None, parameters=None, progress: bool = False) -> pd.DataFrame:
    """Load, run and close an SSP system in one call (see :class:`CoSimulation`)."""
    with CoSimulation(ssp, step, algorithm, parameters) as cosim:
        return cosim.simulate(stop_time, inputs, progress=progress)


def fmpy_input(ssp, inputs, step: float, start_time: float = 0.0) -> dict[str, Callable[[float], float]]:
    """``inputs`` (as :meth:`CoSimulation.simulate` takes them: a mapping of constants, a
    callable ``inputs(t) -> {name: value}`` such as a named profile, or a table) as the
    ``input`` argument of fmpy's SSP runner (``fmpy.ssp.simulation.simulate_ssp``): one
    function of time per system input connector of ``ssp`` that ``inputs`` gives.

    fmpy's runner adds the step to a float time, and calls each function at that float
    (0.30000000000000004, or 2.9999999999999996 for 3 s): a command that changes at a
    communication point would land a step late wherever the float falls short of it.
    These functions read the command at the communication point nearest the float they
    are given, so the valves get the command of the step's start whatever float fmpy
    sends, as boomfmi's master gives it (a change between two points from the next one
    on).  fmpy hands a system input's value to the components it feeds a step later than
    the master does, but its first step is idle (every connector starts at 0), which
    puts the two back in step: fmpy's row k holds the master's row k.
    """
    if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0):
        raise ValueError(f"the communication step must be > 0 s, not {step!r}")
    structure = read_ssp(ssp)
    names = [c for c, kind in structure.connectors.items() if kind in ("input", "parameter")]
    if not names:
        raise ValueError(f"{structure.path}: declares no system input connector for fmpy to drive")
    source = _input_source(inputs, names)
    given = [n for n in names if n in source(float(start_time))]
    if not given:
        raise ValueError(f"the inputs give none of {structure.path.name}'s system input connectors "
                         f"{', '.join(names)}")
    t0, h = float(start_time), float(step)

    def at_point(name: str) -> Callable[[float], float]:
        return lambda t: float(source(t0 + round((t - t0) / h) * h)[name])
    return {name: at_point(name) for name in given}


#: Parameters that name one physical quantity of the machine wherever a component
#: declares them (the cylinder's stroke is the boom's stroke): they must agree.
SHARED = ("L", "A_a", "A_b", "V_a0", "V_b0", "a", "b", "h", "l_min", "P_atm")


def check_shared(structure: SystemStructure, instances: Mapping[str, FmuInstance]) -> None:
    """Raise :class:`SspError` where two components that a connection joins hold
    different values of one of :data:`SHARED` (bound, or else the FMU's start value).

    Only joined components are compared: in the boom the cylinder and the boom load
    are one cylinder, while in the whole excavator each joint's cylinder has its own
    stroke and areas (``cylinder_boom.L`` and ``cylinder_arm.L`` differ rightly)."""
    pairs = {tuple(sorted((c.start_element, c.end_element))) for c in structure.connections
             if c.start_element in instances and c.end_element in instances and c.start_element != c.end_element}
    for name in SHARED:
        seen: dict[str, float] = {}
        for comp, inst in instances.items():
            var = inst.variables.get(name)
            if var is None or var.causality != "parameter":
                continue
            bound = structure.parameters.get(f"{comp}.{name}")
            seen[comp] = float(bound.value if bound is not None else var.start)
        for a, b in sorted(pairs):
            if a in seen and b in seen and seen[a] != seen[b]:
                listed = ", ".join(f"{c}.{name} = {v:g}" for c, v in seen.items() if c in (a, b))
                raise SspError(f"{name} is one quantity of the machine but the components disagree: {listed}; "
                               f"set every one of them")


def _gather(sources: list[tuple[int, float, float]]) -> Callable[[list[float]], list[float]]:
    """``values -> [f * values[i] + o for each (i, f, o) in sources]`` (a component's
    inputs from their connections, a recorded row from its columns' slots), an item
    getter where every one is one to one (factor 1, offset 0)."""
    if len(sources) > 1 and all((f, o) == (1.0, 0.0) for _, f, o in sources):
        get = itemgetter(*(i for i, _, _ in sources))
        return lambda values: list(get(values))
    return lambda values: [f * values[i] + o for i, f, o in sources]


def _as_list(parameters) -> list:
    if parameters is None:
        return []
    if isinstance(parameters, (str, Path, Mapping)):
        return [parameters]
    return list(parameters)


def _ptype(value) -> str:
    if isinstance(value, bool):
        return "Boolean"
    if isinstance(value, int):
        return "Integer"
    if isinstance(value, float):
        return "Real"
    return "String"


def _order(names: list[str], strict: dict[str, set[str]], soft: dict[str, set[str]],
           where: str) -> list[str]:
    """Gauss-Seidel order: topological over ``strict`` (feedthrough) edges, a cycle
    there being an algebraic loop; ties go to the element with fewest unmet ``soft``
    inputs, then to SSD order."""
    hard_in = {n: 0 for n in names}
    soft_in = {n: 0 for n in names}
    for a in names:
        for b in strict[a]:
            hard_in[b] += 1
        for b in soft[a]:
            soft_in[b] += 1
    order, left = [], list(names)
    while left:
        ready = [n for n in left if hard_in[n] == 0]
        if not ready:
            raise SspError(f"{where}: algebraic loop through direct feedthrough among {', '.join(left)}")
        n = min(ready, key=lambda m: (soft_in[m], names.index(m)))
        order.append(n)
        left.remove(n)
        for b in strict[n]:
            hard_in[b] -= 1
        for b in soft[n]:
            soft_in[b] -= 1
    return order


def _input_source(inputs, names: list[str]) -> Callable[[float], Mapping[str, float]]:
    if inputs is None:
        return lambda t: {}
    if isinstance(inputs, pd.DataFrame):
        tcol = "t" if "t" in inputs.columns else "time"
        times = inputs[tcol].to_numpy(dtype=float)
        cols = {c: inputs[c].to_numpy(dtype=float) for c in names if c in inputs.columns}
        if not cols:
            raise ValueError(f"the input table has none of the system's inputs {names}")

        def held(t: float) -> dict[str, float]:
            i = max(int(np.searchsorted(times, t + 1e-9, side="right")) - 1, 0)
            return {c: v[i] for c, v in cols.items()}
        return held
    if isinstance(inputs, Mapping):
        const = dict(inputs)
        unknown = set(const) - set(names)
        if unknown:
            raise ValueError(f"the system has no free input {sorted(unknown)}; its inputs: {names}")
        return lambda t: const
    if callable(inputs):
        return inputs
    raise TypeError(f"inputs must be a mapping, a callable or a DataFrame, not {type(inputs).__name__}")


__all__ = ["ALGORITHMS", "NS_PER_S", "MAX_STEPS", "CoSimulation", "simulate_ssp", "fmpy_input", "SHARED",
           "check_shared"]
