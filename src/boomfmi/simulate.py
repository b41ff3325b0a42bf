"""Run an experiment on an SSP system and return it in the recording format.

``run_experiment`` drives every free input named ``u`` (the valve command; the model's
valve and, in the teleoperation system, the hardware bridge) with a named command
profile or with the ``u`` column of a recording, runs the co-simulation, and returns
the columns of a recording (``t, u, p_a, p_b, alpha``, gauge pressures) plus ``x`` and
``v``, so that model output and rig recordings compare column by column.  The columns
are found by name among the model components' outputs (``p_a`` is the one output
called ``p_a``), not wired here.  Where the system holds a hardware bridge, its
measurements follow as ``p_a_measured``, ``p_b_measured``, ``alpha_measured``,
``x_measured``, ``u_applied``, the rig's true ``f_ext`` where it knows it, and the
link's ``link_ok``, ``failsafe``, ``lost_packets``, ``deadline_misses``; where it holds a
force estimator, its ``f_est`` and ``f_reflect``.
"""
from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from . import physics as ph
from .compare import initial_state
from .experiments import (EXCAVATOR_PROFILES, PROFILES, command_file, command_samples, excavator_profile, is_command_file,
                          profile)
from .physics import reference_rig
from .physics.validation import require_positive
from .recording import read_experiment
from .system.master import CoSimulation
from .system.ssv import Parameter

RECORDED = ("p_a", "p_b", "alpha", "x", "v")
#: The whole excavator's joints (the linkage's, ``physics.linkage.JOINTS``).
JOINTS = ph.JOINTS


def _unique(names: list[str], short: str, what: str) -> str:
    hits = [n for n in names if n.rpartition(".")[2] == short]
    if len(hits) != 1:
        raise ValueError(f"the system must have exactly one {what} named {short!r}, it has {hits or 'none'}")
    return hits[0]


def rig_parameters(experiment: str, parameters: dict) -> dict:
    """A recording's sidecar overrides as SSP parameters: each value goes to every
    component parameter of that name (``P_s`` to ``valve.P_s``, ``a`` to
    ``boom_load.a``...)."""
    if experiment in PROFILES or is_command_file(experiment):     # no sidecar: the SSP's own rig
        return {}
    over = read_experiment(experiment).rig_values()
    return {f"{comp}.{name}": value for name, value in over.items()
            for comp, names in parameters.items() if name in names}


def replay_parameters(recording) -> dict:
    """The teleoperation system's parameters for replaying ``recording`` through its
    hardware bridge: replay mode, the file, and the model starting where the machine
    starts (``boom_load.x0`` from the recording's first angle)."""
    x0, _, _ = initial_state(read_experiment(recording))
    return {"hardware_bridge.mode": "replay", "hardware_bridge.recording": str(recording),
            "boom_load.x0": x0}


def experiment_inputs(experiment: str, input_names: list[str]):
    """``(inputs, stop_time)`` for a named profile or a recording's ``u`` column, driving
    every input in ``input_names`` with the same command."""
    if experiment in PROFILES:
        prof = profile(experiment)
        return (lambda t: dict.fromkeys(input_names, prof(t)["u"])), prof.duration
    path = Path(experiment)
    if path.suffix.lower() != ".csv" and not path.exists():
        raise ValueError(f"unknown experiment {experiment!r}: give one of {', '.join(PROFILES)} "
                         f"or a recording (.csv)")
    if is_command_file(path):          # a command CSV (t, u: diagnose --propose writes one)
        prof = command_file(path)
        t, u = command_samples(prof)
        return pd.DataFrame({"t": t, **{n: u for n in input_names}}), prof.duration
    rec = read_experiment(path)
    table = pd.DataFrame({"t": rec.data["t"], **{n: rec.data["u"] for n in input_names}})
    return table, float(rec.data["t"].iloc[-1])


def live_columns(cosim, bridges: list[str], P_atm: float) -> dict[str, tuple[str, float]]:
    """The live view's sample names -> (result column, offset): the model's posture
    and gauge pressures, the bridge's measurements as ``*_measured``, the forces."""
    cols = {}
    for n, outs in cosim.outputs.items():
        for o in outs:
            if n in bridges:
                if o in ("p_a", "p_b", "alpha", "x"):
                    cols[f"{o}_measured"] = (f"{n}.{o}", 0.0)
                elif o == "f_ext":
                    cols["f_ext"] = (f"{n}.{o}", 0.0)
            elif o in ("p_a", "p_b"):
                cols[o] = (f"{n}.{o}", -P_atm)
            elif o in ("alpha", "x", "f_est", "f_reflect"):
                cols[o] = (f"{n}.{o}", 0.0)
    return cols


def simulate_with_view(cosim, stop_time: float, inputs, progress: bool, view: str | None,
                       view_key: bytes | None, columns: dict[str, tuple[str, float]], geom=None) -> pd.DataFrame:
    """``cosim.simulate``; with ``view`` (udp://HOST:PORT), each row also goes to ``boomfmi
    view --live`` as a sample of ``columns`` (sample name -> (result column, offset)) and
    the boom's ``geom`` (none for the excavator), signed with ``view_key``
    (``view.live.LiveSender``)."""
    sender = None
    if view:
        from .view.live import LiveSender
        sender = LiveSender(view, columns, geom, key=view_key)
    try:
        return cosim.simulate(stop_time, inputs, progress=progress, monitor=sender)
    finally:
        if sender is not None:
            sender.close()


def bound_value(cosim, name: str) -> float:
    """The value the system binds to any component's parameter ``name`` (the first
    binding found), else the reference rig's."""
    return next((float(p.value) for n, p in cosim.structure.parameters.items()
                 if n.rpartition(".")[2] == name), getattr(reference_rig, name))


#: The longest communication step, as a share of a radian of the air springs' highest
#: natural frequency: the cylinder takes the boom's motion as a held velocity over a
#: step, which on the shipped boom keeps the chamber pressures physical (below the
#: supply) up to about 2 ms and not at 5 ms (docs/cosim-accuracy.md).
STABLE_SHARE = 0.1


def max_stable_step(cosim) -> float:
    """The longest communication step [s] at which the cylinder's coupling with the boom
    stays stable: ``STABLE_SHARE / omega``, omega [rad/s] the air springs' natural
    frequency with both chambers at the supply pressure, at the stroke end where it is
    highest (``physics.pneumatic_stiffness`` over the moving mass)."""
    cyl = ph.Cylinder(**{k: bound_value(cosim, k) for k in ph.Cylinder._fields})
    gas = ph.Gas(k=bound_value(cosim, "k"))
    P_s, M = bound_value(cosim, "P_s"), bound_value(cosim, "M")
    try:           # the FMUs check their values when initialised, after this divides by them
        ph.check_cylinder(cyl)
        ph.check_gas(gas)
        require_positive("P_s", P_s)
        require_positive("M", M)
    except ph.ParameterError as e:
        names = [n for n in cosim.structure.parameters if n.rpartition(".")[2] == e.name]
        where = f"{cosim.structure.parameter_origin.get(names[0], 'parameter set')}: {names[0]}" if names else e.name
        raise ValueError(f"{where}: {e}") from None
    stiffness = max(ph.pneumatic_stiffness(P_s, P_s, x, cyl, gas) for x in (0.0, cyl.L))
    return STABLE_SHARE / math.sqrt(stiffness / M)


def run_experiment(ssp, experiment: str = "paper_multistep", step: float = 1e-3,
                   stop_time: float | None = None, algorithm: str = "gauss-seidel",
                   parameters=None, progress: bool = False, view: str | None = None,
                   view_key: bytes | None = None) -> pd.DataFrame:
    """Simulate ``experiment`` on the SSP; return recording columns plus x and v.
    ``view`` (udp://HOST:PORT) streams the run to ``boomfmi view --live`` as it goes,
    signed with ``view_key`` (by default ``link.protocol.load_key()``'s: $BOOMFMI_LINK_KEY)."""
    if experiment not in PROFILES and experiment not in EXCAVATOR_PROFILES \
            and Path(experiment).suffix.lower() != ".csv" and not Path(experiment).exists():
        raise ValueError(f"unknown experiment {experiment!r}: give one of {', '.join(PROFILES)}, "
                         f"for the whole excavator one of {', '.join(EXCAVATOR_PROFILES)}, or a recording (.csv)")
    with CoSimulation(ssp, step, algorithm, parameters) as cosim:
        if any(i.model_description.modelName == "linkage" for i in cosim.instances.values()):
            return run_excavator(cosim, experiment, stop_time, progress, view, view_key)
        names = {n: {v.name for v in i.model_description.modelVariables if v.causality == "parameter"}
                 for n, i in cosim.instances.items()}
        over = rig_parameters(experiment, names)
        if over:             # the recording's rig over the SSP's own values, under --params
            cosim.structure.bind({n: Parameter(n, "Real", v) for n, v in over.items() if n not in cosim.given},
                                 f"{experiment} (sidecar)")
        if any(i.model_description.modelName == "cylinder" for i in cosim.instances.values()):
            limit = max_stable_step(cosim)
            if cosim.step_size > limit:
                raise ValueError(f"a step of {cosim.step_size:g} s is beyond what the cylinder's coupling with "
                                 f"the boom keeps stable here ({limit * 1e3:.3g} ms: a tenth of a radian of the "
                                 f"air springs' highest natural frequency); use --step {limit * 1e3:.2g}e-3 "
                                 f"or less")
        u_names = [n for n in cosim.inputs if n.rpartition(".")[2] == "u"]
        if not u_names:
            raise ValueError(f"the system has no free input named 'u' to drive; its inputs: {cosim.inputs}")
        bridges = [n for n, i in cosim.instances.items() if i.model_description.modelName == "hardware_bridge"]
        inputs, duration = experiment_inputs(experiment, u_names)
        P_atm = bound_value(cosim, "P_atm")
        geom = [bound_value(cosim, g) for g in ("a", "b", "h", "l_min")]
        result = simulate_with_view(cosim, stop_time if stop_time is not None else duration, inputs, progress,
                                    view, view_key, live_columns(cosim, bridges, P_atm), geom)
        outputs = [c for c in result.columns if c.count(".") == 1 and c not in cosim.inputs
                   and c.partition(".")[0] not in bridges and c.rpartition(".")[2] in RECORDED]
    model_u = [n for n in u_names if n.partition(".")[0] not in bridges] or u_names
    out = pd.DataFrame({"t": result["time"], "u": result[model_u[0]]})
    for name in RECORDED:
        col = result[_unique(outputs, name, "output")]
        out[name] = col - P_atm if name in ("p_a", "p_b") else col
    for bridge in bridges[:1]:
        for name in ("p_a", "p_b", "alpha", "x"):
            out[f"{name}_measured"] = result[f"{bridge}.{name}"]
        out["u_applied"] = result[f"{bridge}.u_applied"]
        for name in ("f_ext", "link_ok", "failsafe", "lost_packets", "deadline_misses"):
            if f"{bridge}.{name}" in result:
                out[name] = result[f"{bridge}.{name}"]
    for name in ("f_est", "f_reflect"):
        hits = [c for c in result.columns if c.count(".") == 1 and c.rpartition(".")[2] == name]
        if hits:
            out[name] = result[hits[0]]
    return out


def excavator_wiring(cosim) -> dict[str, tuple[str, str, str]]:
    """Per joint, ``(linkage, cylinder, valve)``: the components of an excavator system,
    found through its connections (the cylinder drives the linkage's ``p_a_<joint>``,
    the valve the cylinder's ``mdot_a``), not by their names."""
    links = [n for n, i in cosim.instances.items() if i.model_description.modelName == "linkage"]
    if len(links) != 1:
        raise ValueError(f"an excavator system has exactly one linkage, this one has {links or 'none'}")
    link = links[0]
    conns = cosim.structure.connections
    source = {(c.end_element, c.end_connector): c.start_element for c in conns}
    out = {}
    for j in JOINTS:
        cyl = source.get((link, f"p_a_{j}"))
        valve = source.get((cyl, "mdot_a")) if cyl else None
        if cyl is None or valve is None or f"{valve}.u" not in cosim.inputs:
            raise ValueError(f"the excavator system must drive {link}.p_a_{j} from a cylinder fed by a valve "
                             f"whose u is a free input (found cylinder {cyl!r}, valve {valve!r})")
        out[j] = (link, cyl, valve)
    return out


def excavator_inputs(experiment: str, valves: dict[str, str]):
    """``(inputs, stop_time)`` for a named excavator profile or an excavator recording's
    ``u_<joint>`` columns, each driving its joint's valve (``valves``: joint -> component)."""
    if experiment in EXCAVATOR_PROFILES:
        prof = excavator_profile(experiment)
        return (lambda t: {f"{valves[j]}.u": u for j, u in ((k[2:], u) for k, u in prof(t).items())}), prof.duration
    if experiment in PROFILES:
        raise ValueError(f"{experiment!r} is a boom experiment; the whole excavator takes one of "
                         f"{', '.join(EXCAVATOR_PROFILES)} or an excavator recording")
    rec = read_experiment(experiment)
    if rec.kind != "excavator":
        raise ValueError(f"{experiment}: a boom recording; the whole excavator replays an excavator recording "
                         f"(u_swing, u_boom, u_arm, u_bucket)")
    table = pd.DataFrame({"t": rec.data["t"], **{f"{valves[j]}.u": rec.data[f"u_{j}"] for j in JOINTS}})
    return table, float(rec.data["t"].iloc[-1])


def excavator_columns(cosim, wiring: dict[str, tuple[str, str, str]]) -> dict[str, tuple[str, float]]:
    """The whole excavator's run columns -> (result column, offset), in their order (see
    :func:`run_excavator`): the offset turns the cylinders' absolute pressures into gauge."""
    P_atm = bound_value(cosim, "P_atm")
    cols = {f"u_{j}": (f"{valve}.u", 0.0) for j, (link, cyl, valve) in wiring.items()}
    for q in ("p_a", "p_b"):
        cols.update({f"{q}_{j}": (f"{cyl}.{q}", -P_atm) for j, (link, cyl, valve) in wiring.items()})
    for q in ("angle", "x", "v"):
        cols.update({f"{q}_{j}": (f"{link}.{q}_{j}", 0.0) for j, (link, cyl, valve) in wiring.items()})
    link = next(iter(wiring.values()))[0]
    cols.update({f"f_tip_{c}": (f"{link}.f_tip_{c}", 0.0) for c in "xyz"})
    return cols


def run_excavator(cosim, experiment: str, stop_time: float | None = None, progress: bool = False,
                  view: str | None = None, view_key: bytes | None = None) -> pd.DataFrame:
    """The whole excavator's run in the excavator recording's columns: ``t``, per joint
    ``u_<j>``, ``p_a_<j>``, ``p_b_<j>`` (gauge [Pa]), ``angle_<j>``, then ``x_<j>``,
    ``v_<j>`` and the tip force ``f_tip_x``, ``f_tip_y``, ``f_tip_z`` the linkage was
    given (0 unless a parameter set drives it).  ``view`` streams the run to ``boomfmi
    view --live`` as the excavator's samples (those of these columns a sample carries:
    the model's ``angle_<j>``, ``p_a_<j>``, ``p_b_<j>`` and ``f_tip_<a>``)."""
    wiring = excavator_wiring(cosim)
    inputs, duration = excavator_inputs(experiment, {j: w[2] for j, w in wiring.items()})
    columns = excavator_columns(cosim, wiring)
    result = simulate_with_view(cosim, stop_time if stop_time is not None else duration, inputs, progress,
                                view, view_key, columns)
    out = {"t": result["time"]}
    for name, (col, offset) in columns.items():
        if col not in result and name.startswith("f_tip_"):      # the linkage's tip force, not recorded
            out[name] = 0.0
        else:
            out[name] = result[col] + offset
    return pd.DataFrame(out)


__all__ = ["RECORDED", "JOINTS", "rig_parameters", "replay_parameters", "experiment_inputs", "live_columns",
           "simulate_with_view", "bound_value", "STABLE_SHARE", "max_stable_step", "run_experiment",
           "excavator_wiring", "excavator_inputs", "excavator_columns", "run_excavator"]
