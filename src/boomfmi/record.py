"""Record an experiment on a rig through the hardware-bridge FMU.

``record_experiment`` loads the bridge FMU through fmpy, points it at the rig, drives
its ``u`` with a command profile, and writes what comes back as a recording, row by
row and crash-safe: a process killed mid-run leaves a file whose every row is valid,
and a link that fails mid-run ends the run with an error after everything received
so far has been written.

The whole excavator's experiments (``experiments.EXCAVATOR_PROFILES``: the digging
cycle...) go through the ``excavator_bridge`` FMU to an excavator rig
(``boomfmi rig serve --config examples/rig/excavator_*.json``) and are written in the
excavator recording's columns (:data:`EXCAVATOR_COLUMNS`).
"""
from __future__ import annotations

import math
import signal
import threading
from pathlib import Path

from .experiments import EXCAVATOR_PROFILES, JOINTS, excavator_profile, profile
from .paths import default_file
from .recording import RecordingWriter
from .system.instance import FmuError, FmuInstance

#: A row holds the sample measured at ``t`` and the command the valve got from ``t`` on
#: (``u``; ``u_cmd`` is what was sent, which differs while the rig is in fail-safe).
#: ``x_alpha`` is x from the measured alpha by Eq. 12 (the format's ``x`` is a direct
#: measurement, which the bridge does not have).
COLUMNS = ("t", "u", "p_a", "p_b", "alpha", "f_ext", "x_alpha", "u_cmd", "link_ok", "failsafe", "t_rig")
OUTPUTS = ("u_applied", "p_a", "p_b", "alpha", "f_ext", "x", "link_ok", "failsafe", "t_rig", "lost_packets")
#: The excavator's recording through its bridge: the excavator recording's columns (the
#: commands the valves got), the true tip force where the rig knows it, each piston's x
#: from its measured angle (``x_angle_<joint>``), the commands sent, the link's state.
EXCAVATOR_COLUMNS = (("t",) + tuple(f"{q}_{j}" for q in ("u", "p_a", "p_b", "angle") for j in JOINTS)
                     + ("f_tip_x", "f_tip_y", "f_tip_z") + tuple(f"x_angle_{j}" for j in JOINTS)
                     + tuple(f"u_cmd_{j}" for j in JOINTS) + ("link_ok", "failsafe", "t_rig"))
_MEASURED = (tuple(f"{q}_{j}" for q in ("p_a", "p_b", "angle") for j in JOINTS) + ("f_tip_x", "f_tip_y", "f_tip_z")
             + tuple(f"x_{j}" for j in JOINTS))
EXCAVATOR_OUTPUTS = (tuple(f"u_applied_{j}" for j in JOINTS) + _MEASURED
                     + ("link_ok", "failsafe", "t_rig", "lost_packets"))
#: The bridges' default places, in the build folder (``paths.built``: the checkout's
#: ``build/`` or ``$BOOMFMI_BUILD``, whatever the working directory).
FMU = "fmus/hardware_bridge.fmu"
EXCAVATOR_FMU = "fmus/excavator_bridge.fmu"
#: The most steps a run may have: an hour at the DAQ's 1 kHz (the largest recording the
#: reader takes, ``recording.MAX_BYTES``, holds about that much).
MAX_STEPS = 3_600_000


def steps(step, stop) -> int:
    """The number of steps of a run of ``stop`` seconds at ``step`` seconds each; a
    ValueError naming the option unless both are finite and > 0, ``step`` is at most
    ``stop`` and the run has at most :data:`MAX_STEPS` steps."""
    for option, value in (("--step", step), ("--stop", stop)):
        try:
            good = math.isfinite(float(value)) and float(value) > 0
        except (TypeError, ValueError):
            good = False
        if not good:
            raise ValueError(f"{option} {value!r}: must be a finite number of seconds > 0")
    step, stop = float(step), float(stop)
    if step > stop:
        raise ValueError(f"--step {step:g} s is longer than --stop {stop:g} s: the run would have no step")
    n = int(round(stop / step))
    if n > MAX_STEPS:
        raise ValueError(f"--stop {stop:g} s at --step {step:g} s is {n} steps: at most {MAX_STEPS} "
                         f"(an hour at the DAQ's 1 kHz); a longer step or a shorter run")
    return n


def _kept(e: Exception, w: RecordingWriter) -> None:
    """Say in the failed run's error that the recording it would have replaced is kept."""
    if w.replacing and e.args:
        rows = (f"this run's {w.rows} rows are kept in {w.kept_path}, marked incomplete" if w.rows
                else "this run recorded no row")
        e.args = (f"{e.args[0]}; the existing {w.path} is left as it was ({rows})", *e.args[1:])


def _interrupted(e: BaseException) -> bool:
    """Whether ``e`` is an interrupt (Ctrl-C, SIGINT): a KeyboardInterrupt, or the bridge
    FMU's error for one raised inside its step (its Python code runs in this process,
    gets the signal, and its FMI call returns fmi2Error naming it)."""
    return isinstance(e, KeyboardInterrupt) or (isinstance(e, FmuError) and "KeyboardInterrupt" in str(e))


class _Sigint:
    """Ctrl-C (SIGINT) noted, not raised, while the run is in the bridge FMU's calls: its
    Python code runs in this process, and an interrupt raised inside one of its calls
    (a ``fmi2GetReal``) would end the instance with an error that no longer says why.
    The loop checks :attr:`hit` between steps.  Outside the main thread (where no
    handler can be set) it never hits, and Ctrl-C raises as usual."""

    def __enter__(self):
        self.hit = False
        self._old = None
        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._note)
        return self

    def _note(self, signum, frame):
        self.hit = True

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
        return False


def _inputs(fmu, key_file) -> list:
    """The run's input files, which the recording may not be."""
    return [Path(fmu), *([Path(key_file)] if key_file else [])]


def _rig_values(machine, kind: str) -> dict:
    """The sidecar's ``rig`` of a recording of ``machine`` (none without one); a machine
    of the other kind is refused before anything is opened."""
    if machine is None:
        return {}
    if machine.kind != kind:
        raise ValueError(f"{machine.path}: describes {'an' if machine.kind == 'excavator' else 'a'} {machine.kind}; "
                         f"this experiment records {'an' if kind == 'excavator' else 'a'} {kind}")
    return {"rig": machine.sidecar()}


def record_experiment(fmu, rig: str, out, experiment: str = "paper_multistep", step: float = 1e-3,
                      stop_time: float | None = None, key_file: str | None = None,
                      timeout: float = 0.05, retries: int = 2, loss_budget: int = 20, machine=None) -> dict:
    """Run ``experiment`` on the rig at ``rig`` (udp://HOST:PORT); write ``out``, and
    beside it the sidecar with ``machine``'s values (a ``machine.MachineFile``) where given.

    ``fmu`` None: ``build/fmus/hardware_bridge.fmu`` of the checkout (or of
    ``$BOOMFMI_BUILD``: :mod:`boomfmi.paths`, from any working directory), or for an
    excavator experiment (:func:`record_excavator_experiment`, to which it then hands
    over) ``build/fmus/excavator_bridge.fmu``; FileNotFoundError naming where it looked.

    ``step`` and ``stop_time`` are checked (:func:`steps`) before anything is opened.
    Nothing is written, and an existing ``out`` is left as it was, until the rig has
    answered (the bridge's handshake brings the first sample).  From then on rows are
    written as they come, and the sidecar says ``incomplete`` until the run ends well:
    a recorder killed mid-run leaves its rows and that mark; a link that fails ends the
    run with :class:`FmuError` after every row received is written and the sidecar
    names why.  Where ``out`` exists already, the rows go beside it and replace it only
    when the run has ended well (``recording.RecordingWriter``): a failed, interrupted
    or killed run leaves it as it was.  ``out`` is locked while it is written
    (``outputs.OutputError`` for a second writer) and may not be the FMU or key file.
    Returns the bridge's link figures (``lost_packets``, ``rows``).
    """
    if experiment in EXCAVATOR_PROFILES:
        return record_excavator_experiment(default_file(EXCAVATOR_FMU, "--fmu") if fmu is None else fmu, rig,
                                           out, experiment, step,
                                           stop_time, key_file, timeout, retries, loss_budget, machine)
    fmu = default_file(FMU, "--fmu") if fmu is None else fmu
    command = profile(experiment)
    stop = command.duration if stop_time is None else stop_time
    n = steps(step, stop)                               # before anything is opened
    parameters = dict(mode="udp", rig=rig, key_file=str(key_file or ""), timeout=timeout,
                      retries=retries, loss_budget=loss_budget)
    notes = {"notes": f"recorded from {rig}, experiment {experiment}", **_rig_values(machine, "boom")}
    rows = 0
    with FmuInstance(fmu, name="hardware_bridge") as bridge:
        bridge.initialize(parameters, start_time=0.0, stop_time=stop, inputs={"u": command(0.0)["u"]})
        y = bridge.get(*OUTPUTS)                        # the sample at t_0: the rig has answered
        with RecordingWriter(out, COLUMNS, sidecar={**notes, "incomplete": "the recorder did not finish "
                                                    "(killed or still running)"},
                             inputs=_inputs(fmu, key_file)) as w, _Sigint() as sigint:
            for k in range(n):
                t = k * step
                u = command(t)["u"]
                bridge.set(u=u)
                try:
                    if sigint.hit:
                        raise KeyboardInterrupt
                    bridge.step_to(t, step)
                except (FmuError, KeyboardInterrupt) as e:
                    w.write((t, u, y["p_a"], y["p_b"], y["alpha"], y["f_ext"], y["x"], u, 0.0,
                             float(y["failsafe"]), y["t_rig"]))
                    if _interrupted(e):
                        w.set_sidecar({**notes, "incomplete": f"interrupted at t = {t:g} s (Ctrl-C or SIGINT)"})
                        raise KeyboardInterrupt from None
                    w.set_sidecar({**notes, "incomplete": f"the link failed at t = {t:g} s: {e}"})
                    _kept(e, w)
                    raise
                nxt = bridge.get(*OUTPUTS)              # u_applied: what the valve got over [t_k, t_k+1)
                w.write((t, nxt["u_applied"], y["p_a"], y["p_b"], y["alpha"], y["f_ext"], y["x"], u,
                         float(y["link_ok"]), float(y["failsafe"]), y["t_rig"]))
                rows += 1
                y = nxt
            u = command(n * step)["u"]
            w.write((n * step, u, y["p_a"], y["p_b"], y["alpha"], y["f_ext"], y["x"], u,
                     float(y["link_ok"]), float(y["failsafe"]), y["t_rig"]))
            w.set_sidecar(notes)
        return {"rows": rows + 1, "lost_packets": y["lost_packets"]}


def record_excavator_experiment(fmu, rig: str, out, experiment: str = "digging_cycle", step: float = 1e-3,
                                stop_time: float | None = None, key_file: str | None = None,
                                timeout: float = 0.05, retries: int = 2, loss_budget: int = 20,
                                machine=None) -> dict:
    """:func:`record_experiment` for the whole excavator: the excavator experiment
    ``experiment`` (``experiments.excavator_profile``) through the ``excavator_bridge``
    FMU ``fmu`` to the excavator rig at ``rig``, written to ``out`` in
    :data:`EXCAVATOR_COLUMNS` (row by row, crash-safe, the sidecar's ``incomplete`` as
    there).  Returns ``{"rows", "lost_packets"}``."""
    command = excavator_profile(experiment)
    stop = command.duration if stop_time is None else stop_time
    n = steps(step, stop)                               # before anything is opened
    parameters = dict(mode="udp", rig=rig, key_file=str(key_file or ""), timeout=timeout,
                      retries=retries, loss_budget=loss_budget)
    notes = {"notes": f"recorded from {rig}, excavator experiment {experiment}", **_rig_values(machine, "excavator")}

    def cmds(t):
        c = command(t)
        return [float(c[f"u_{j}"]) for j in JOINTS]

    def row(t, applied, y, sent, link_ok):
        return (t, *applied, *(y[c] for c in _MEASURED[:-4]), *(y[f"x_{j}"] for j in JOINTS), *sent,
                link_ok, float(y["failsafe"]), y["t_rig"])

    rows = 0
    with FmuInstance(fmu, name="excavator_bridge") as bridge:
        bridge.initialize(parameters, start_time=0.0, stop_time=stop,
                          inputs={f"u_{j}": u for j, u in zip(JOINTS, cmds(0.0))})
        y = bridge.get(*EXCAVATOR_OUTPUTS)
        with RecordingWriter(out, EXCAVATOR_COLUMNS, sidecar={**notes, "incomplete": "the recorder did not finish "
                                                              "(killed or still running)"},
                             inputs=_inputs(fmu, key_file)) as w, _Sigint() as sigint:
            for k in range(n):
                t = k * step
                u = cmds(t)
                bridge.set(**{f"u_{j}": c for j, c in zip(JOINTS, u)})
                try:
                    if sigint.hit:
                        raise KeyboardInterrupt
                    bridge.step_to(t, step)
                except (FmuError, KeyboardInterrupt) as e:
                    w.write(row(t, u, y, u, 0.0))
                    if _interrupted(e):
                        w.set_sidecar({**notes, "incomplete": f"interrupted at t = {t:g} s (Ctrl-C or SIGINT)"})
                        raise KeyboardInterrupt from None
                    w.set_sidecar({**notes, "incomplete": f"the link failed at t = {t:g} s: {e}"})
                    _kept(e, w)
                    raise
                nxt = bridge.get(*EXCAVATOR_OUTPUTS)       # u_applied: what the valves got over [t_k, t_k+1)
                w.write(row(t, [nxt[f"u_applied_{j}"] for j in JOINTS], y, u, float(y["link_ok"])))
                rows += 1
                y = nxt
            u = cmds(n * step)
            w.write(row(n * step, u, y, u, float(y["link_ok"])))
            w.set_sidecar(notes)
        return {"rows": rows + 1, "lost_packets": y["lost_packets"]}


__all__ = ["record_experiment", "record_excavator_experiment", "FmuError", "COLUMNS", "EXCAVATOR_COLUMNS"]
