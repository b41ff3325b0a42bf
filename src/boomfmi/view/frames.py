"""What the virtual view shows, frame by frame: the machine's posture, the model's
(the ghost), the pressures and the forces, from a run file or from live samples.

A **run** is a CSV in the recording format (``t, u, p_a, p_b, alpha``, gauge
pressures), the machine alone; or the output of ``boomfmi simulate`` on the
teleoperation system, where the model's columns (``alpha``, ``x``, ``p_a``, ``p_b``)
stand beside the machine's (``alpha_measured``, ``x_measured``, ``p_a_measured``,
``p_b_measured``) with ``f_est``, ``f_reflect`` and the rig's true ``f_ext``.

A **frame** is a dict, sent to the page as JSON::

    {"type": "frame", "t": s,
     "machine": {"alpha": rad, "x": m, "p_a": Pa gauge, "p_b": Pa gauge,
                 "R": [m, m], "T": [m, m]},
     "model": {... the same ...} or None,
     "f_est": N or None, "f_ext": N or None, "f_reflect": N or None}

R is the rod's pivot on the boom and T the bucket's tip, in the boom's plane with the
boom pivot O at the origin (``physics.linkage_points``); the page draws from these
points and does no geometry of its own.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..physics import Cylinder, Geometry, linkage_points, x_from_alpha
from ..physics import reference_rig
from ..recording import read_recording

#: The boom's drawn length from O to the bucket's tip, as a multiple of b.  The paper
#: gives no boom length; the view draws the boom twice as long as its rod pivot's arm.
TIP_OVER_B = 2.0
POSTURE = ("alpha", "x", "p_a", "p_b")
FORCES = ("f_est", "f_ext", "f_reflect")


def scene(geom: Geometry = Geometry(), L: float = reference_rig.L) -> dict:
    """The fixed parts of the drawing [m]: the pivots O and C, the stroke, the
    cylinder's body and rod lengths and bore, the bucket tip's distance from O."""
    C, _ = linkage_points(0.0, geom)
    return {"O": [0.0, 0.0], "C": [C[0], C[1]], "a": geom.a, "b": geom.b, "h": geom.h,
            "l_min": geom.l_min, "L": L, "r_tip": TIP_OVER_B * geom.b,
            "body_length": geom.l_min - 0.02, "rod_length": L + 0.03,
            "bore": reference_rig.bore, "rod": reference_rig.rod}


def _tip(R):
    """The bucket's tip T on the ray O->R, at TIP_OVER_B * b from O."""
    return TIP_OVER_B * R[0], TIP_OVER_B * R[1]


@dataclass
class Run:
    """A run's columns as arrays: ``machine`` and ``model`` map POSTURE names to arrays
    (``model`` is None for a recording of the machine alone); ``forces`` maps the
    FORCES present."""
    path: Path
    t: np.ndarray
    machine: dict
    model: dict | None
    forces: dict
    geom: Geometry
    L: float

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def frame(self, t: float) -> dict:
        """The frame at time ``t`` [s]: linear interpolation between samples (exact at
        a sample's time), the run's ends held outside it."""
        t = min(max(float(t), float(self.t[0])), float(self.t[-1]))
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        i = min(max(i, 0), len(self.t) - 1)
        if i < len(self.t) - 1 and self.t[i + 1] > self.t[i]:
            w = (t - self.t[i]) / (self.t[i + 1] - self.t[i])
        else:
            w = 0.0

        def at(col: np.ndarray) -> float:
            v = col[i] if w == 0.0 else col[i] + w * (col[i + 1] - col[i])
            return None if not math.isfinite(v) else float(v)

        def posture(cols: dict) -> dict:
            out = {k: at(cols[k]) for k in POSTURE}
            return dict(out, **points(out["alpha"], self.geom))

        return {"type": "frame", "t": t, "machine": posture(self.machine),
                "model": posture(self.model) if self.model is not None else None,
                **{k: (at(self.forces[k]) if k in self.forces else None) for k in FORCES}}

    def history(self, t: float, window: float = 10.0, rate: float = 30.0) -> list[dict]:
        """Frames over the ``window`` seconds before ``t``, ``rate`` per second, for the
        page's plots after a seek or a (re)connection."""
        start = max(float(self.t[0]), t - window)
        n = int((t - start) * rate)
        return [self.frame(start + k / rate) for k in range(n)] + [self.frame(t)]


def points(alpha: float | None, geom: Geometry) -> dict:
    """The moving pivots for a boom angle: R (the rod's) and T (the bucket's tip)."""
    if alpha is None:
        return {"R": None, "T": None}
    _, R = linkage_points(alpha, geom)
    return {"R": [float(R[0]), float(R[1])], "T": list(map(float, _tip(R)))}


def load_run(path) -> Run:
    """Read a run file (see the module's text); raises RecordingError naming the file,
    line and column of anything malformed."""
    rec = read_recording(path)
    d: pd.DataFrame = rec.data
    geom = rec.rig_tuple(Geometry)
    L = rec.rig_tuple(Cylinder).L

    def posture(suffix: str) -> dict:
        cols = {k: d[k + suffix].to_numpy(float) for k in ("alpha", "p_a", "p_b")}
        x = d.get("x" + suffix)
        cols["x"] = x.to_numpy(float) if x is not None else np.asarray(x_from_alpha(cols["alpha"], geom))
        return cols

    if "alpha_measured" in d:
        machine, model = posture("_measured"), posture("")
    else:
        machine, model = posture(""), None
    forces = {k: d[k].to_numpy(float) for k in FORCES if k in d}
    return Run(Path(path), d["t"].to_numpy(float), machine, model, forces, geom, L)


def live_frame(sample: dict, geom: Geometry) -> dict:
    """A frame from one live sample: the flat mapping a co-simulation sends
    (``view.live.LiveSender``): ``t``, the model's ``alpha, x, p_a, p_b``, the machine's
    ``alpha_measured, ...``, and whichever forces it has.  A sample without the
    machine's columns shows the model as the machine (a model-only run)."""
    def posture(suffix: str) -> dict | None:
        alpha = sample.get("alpha" + suffix)
        if alpha is None:
            return None
        x = sample.get("x" + suffix)
        out = {"alpha": float(alpha), "x": float(x) if x is not None else float(x_from_alpha(alpha, geom)),
               "p_a": sample.get("p_a" + suffix), "p_b": sample.get("p_b" + suffix)}
        return dict(out, **points(out["alpha"], geom))

    machine, model = posture("_measured"), posture("")
    if machine is None:
        machine, model = model, None
    if machine is None:
        raise ValueError("a live sample needs alpha or alpha_measured")
    return {"type": "frame", "t": float(sample.get("t", 0.0)), "machine": machine, "model": model,
            **{k: sample.get(k) for k in FORCES}}


__all__ = ["Run", "load_run", "live_frame", "scene", "points"]
