"""Record an experiment on a rig through the hardware-bridge FMU.

``record_experiment`` loads the bridge FMU through fmpy, points it at the rig, drives
its ``u`` with a command profile, and writes what comes back as a recording, row by
row and crash-safe: a process killed mid-run leaves a file whose every row is valid,
and a link that fails mid-run ends the run with an error after everything received
so far has been written.
"""
from __future__ import annotations

from .experiments import profile
from .recording import RecordingWriter
from .system.instance import FmuError, FmuInstance

#: A row holds the sample measured at ``t`` and the command the valve got from ``t`` on
#: (``u``; ``u_cmd`` is what was sent, which differs while the rig is in fail-safe).
#: ``x_alpha`` is x from the measured alpha by Eq. 12 (the format's ``x`` is a direct
#: measurement, which the bridge does not have).
COLUMNS = ("t", "u", "p_a", "p_b", "alpha", "f_ext", "x_alpha", "u_cmd", "link_ok", "failsafe", "t_rig")
OUTPUTS = ("u_applied", "p_a", "p_b", "alpha", "f_ext", "x", "link_ok", "failsafe", "t_rig", "lost_packets")


def record_experiment(fmu, rig: str, out, experiment: str = "paper_multistep", step: float = 1e-3,
                      stop_time: float | None = None, key_file: str | None = None,
                      timeout: float = 0.05, retries: int = 2, loss_budget: int = 20) -> dict:
    """Run ``experiment`` on the rig at ``rig`` (udp://HOST:PORT); write ``out``.

    Nothing is written, and an existing ``out`` is left as it was, until the rig has
    answered (the bridge's handshake brings the first sample).  From then on rows are
    written as they come, and the sidecar says ``incomplete`` until the run ends well:
    a recorder killed mid-run leaves its rows and that mark; a link that fails ends the
    run with :class:`FmuError` after every row received is written and the sidecar
    names why.  Returns the bridge's link figures (``lost_packets``, ``rows``).
    """
    command = profile(experiment)
    stop = command.duration if stop_time is None else stop_time
    n = int(round(stop / step))
    parameters = dict(mode="udp", rig=rig, key_file=str(key_file or ""), timeout=timeout,
                      retries=retries, loss_budget=loss_budget)
    notes = {"notes": f"recorded from {rig}, experiment {experiment}"}
    rows = 0
    with FmuInstance(fmu, name="hardware_bridge") as bridge:
        bridge.initialize(parameters, start_time=0.0, stop_time=stop, inputs={"u": command(0.0)["u"]})
        y = bridge.get(*OUTPUTS)                        # the sample at t_0: the rig has answered
        with RecordingWriter(out, COLUMNS, sidecar={**notes, "incomplete": "the recorder did not finish "
                                                    "(killed or still running)"}) as w:
            for k in range(n):
                t = k * step
                u = command(t)["u"]
                bridge.set(u=u)
                try:
                    bridge.step_to(t, step)
                except FmuError as e:
                    w.write((t, u, y["p_a"], y["p_b"], y["alpha"], y["f_ext"], y["x"], u, 0.0,
                             float(y["failsafe"]), y["t_rig"]))
                    w.set_sidecar({**notes, "incomplete": f"the link failed at t = {t:g} s: {e}"})
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


__all__ = ["record_experiment", "FmuError", "COLUMNS"]
