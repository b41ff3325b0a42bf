"""Record an experiment on a rig through the hardware-bridge FMU.

``record_experiment`` loads the bridge FMU through fmpy, points it at the rig, drives
its ``u`` with a command profile, and writes what comes back as a recording, row by
row and crash-safe: a process killed mid-run leaves a file whose every row is valid,
and a link that fails mid-run ends the run with an error after everything received
so far has been written.
"""
from __future__ import annotations

from pathlib import Path

from .experiments import profile
from .recording import RecordingWriter
from .system.instance import FmuError, FmuInstance

COLUMNS = ("t", "u", "p_a", "p_b", "alpha", "f_ext", "x", "u_cmd", "link_ok", "failsafe", "t_rig")
OUTPUTS = ("u_applied", "p_a", "p_b", "alpha", "f_ext", "x", "link_ok", "failsafe", "t_rig", "lost_packets")


def record_experiment(fmu, rig: str, out, experiment: str = "paper_multistep", step: float = 1e-3,
                      stop_time: float | None = None, key_file: str | None = None,
                      timeout: float = 0.05, retries: int = 2, loss_budget: int = 20) -> dict:
    """Run ``experiment`` on the rig at ``rig`` (udp://HOST:PORT); write ``out``.

    Returns the bridge's link figures (``lost_packets``, ``rows``).  Raises
    :class:`FmuError` when the link fails; the recording then holds every row received.
    """
    command = profile(experiment)
    stop = command.duration if stop_time is None else stop_time
    n = int(round(stop / step))
    parameters = dict(mode="udp", rig=rig, key_file=str(key_file or ""), timeout=timeout,
                      retries=retries, loss_budget=loss_budget)
    rows = 0
    with FmuInstance(fmu, name="hardware_bridge") as bridge, \
            RecordingWriter(out, COLUMNS, sidecar={"notes": f"recorded from {rig}, experiment {experiment}"}) as w:
        bridge.initialize(parameters, start_time=0.0, stop_time=stop, inputs={"u": command(0.0)["u"]})

        def write(t: float, u_cmd: float) -> None:
            o = bridge.get(*OUTPUTS)
            w.write((t, o["u_applied"], o["p_a"], o["p_b"], o["alpha"], o["f_ext"], o["x"], u_cmd,
                     float(o["link_ok"]), float(o["failsafe"]), o["t_rig"]))
            bridge.lost = o["lost_packets"]

        write(0.0, command(0.0)["u"])
        rows = 1
        for k in range(n):
            t = k * step
            u = command(t)["u"]
            bridge.set(u=u)
            bridge.step_to(t, step)
            write((k + 1) * step, u)
            rows += 1
        return {"rows": rows, "lost_packets": bridge.lost}


__all__ = ["record_experiment", "FmuError", "COLUMNS"]
