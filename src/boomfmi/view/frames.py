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

An **excavator** run (its recording's kind, ``recording.recording_kind``) gives
a :class:`Run` of the :class:`LinkageMechanism` and frames of ``"kind": "excavator"``: the
whole machine's points in 3D from ``physics.linkage.forward_kinematics`` (see the
excavator section below); a boom run's mechanism is the :class:`BoomMechanism`.
:func:`load_run` and :func:`live_frame` tell the two apart; the rest is the same code.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..physics import Cylinder, Geometry, linkage_points, x_from_alpha
from ..physics import linkage
from ..physics.force_estimation import F_BOUND
from ..physics import reference_rig
from ..recording import read_recording

#: The boom's drawn length from O to the bucket's tip, as a multiple of b.  The paper
#: gives no boom length; the view draws the boom twice as long as its rod pivot's arm.
TIP_OVER_B = 2.0
POSTURE = ("alpha", "x", "p_a", "p_b")
FORCES = ("f_est", "f_ext", "f_reflect")


# -- the whole excavator ----------------------------------------------------------------------
# An excavator run (shared/spec/excavator.md) is a recording in the excavator's columns
# (``recording.recording_kind``): ``t``, per joint ``u_<j>, p_a_<j>, p_b_<j>, angle_<j>``,
# optionally the true tip force ``f_tip_x/y/z``; or a model's run beside the machine,
# the model's columns unsuffixed and the machine's suffixed ``_measured``
# (``angle_<j>_measured``, ``p_a_<j>_measured``...), as the boom's teleoperation run,
# with the estimated tip force ``f_tip_est_x/y/z`` (and the reflected ``f_reflect_x/y/z``)
# and its interval ``f_tip_lo_x/y/z``, ``f_tip_hi_x/y/z`` (``boomfmi view --model``).
#
# Its frame:
#
#     {"type": "frame", "kind": "excavator", "t": s,
#      "machine": {"angle": {joint: rad}, "p_a": {joint: Pa gauge}, "p_b": {...},
#                  "points": {name: [x, y, z] m}},
#      "model": {... the same ...} or None,
#      "f_tip": [N, N, N] or None, "f_tip_est": [...] or None, "f_reflect": [...] or None,
#      "f_tip_lo": [N or None per axis] or None, "f_tip_hi": [...] or None}
#
# ``points`` are ``physics.linkage.forward_kinematics``'s, in the world frame (z up):
# the swing axis at the ground, the boom, arm and bucket pivots, the tip and each
# cylinder's eyes; the page draws from them and does no kinematics of its own.
EXCAVATOR_POSTURE = ("angle", "p_a", "p_b")
#: the 3-vector forces of an excavator run: frame key -> the run's column prefix
TIP_FORCES = {"f_tip": "f_tip", "f_tip_est": "f_tip_est", "f_reflect": "f_reflect"}
#: m of arrow per N of tip force, on the page
TIP_FORCE_SCALE = 0.25 / 50.0
#: the interval of the estimated tip force per axis (``f_tip_lo_<a>``, ``f_tip_hi_<a>``,
#: ``physics.force_estimation``): frame key -> the run's column prefix.  A side at
#: ``+-force_estimation.F_BOUND`` or beyond is open (a stop or a sticking joint leaves
#: it unbounded) and is sent as None, per axis.
TIP_BOUNDS = {"f_tip_lo": "f_tip_lo", "f_tip_hi": "f_tip_hi"}


def heading(p: dict) -> float:
    """The upper structure's heading [rad] from the points: swing axis to boom pivot,
    seen from above."""
    axis, boom = p["swing_axis"], p["boom_pivot"]
    return math.atan2(boom[1] - axis[1], boom[0] - axis[0])


def _angles_of_points(p: dict) -> np.ndarray:
    """The joint angles as the drawing shows them, from the points: the upper
    structure's heading (swing axis to boom pivot, seen from above), the boom's
    elevation (boom pivot to arm pivot) in the upper structure's vertical plane, and the
    arm's and bucket's elevations relative to the link before.  The page reads its drawn
    angles back the same way (``app.js``: ``excavatorAngles``)."""
    h = heading(p)
    e = np.array([math.cos(h), math.sin(h), 0.0])

    def elevation(a, b):
        d = np.asarray(p[b], float) - np.asarray(p[a], float)
        return math.atan2(d[2], float(d @ e))
    eb = elevation("boom_pivot", "arm_pivot")
    ea = elevation("arm_pivot", "bucket_pivot")
    ek = elevation("bucket_pivot", "tip")
    return np.array([h, eb, ea - eb, ek - ea])


def _wrap(a):
    return (np.asarray(a, float) + math.pi) % (2 * math.pi) - math.pi


def excavator_angle_map(q_ref=None) -> list[dict]:
    """How each joint's angle (the recording's) shows in the drawing: ``q = sign *
    (drawn - offset)`` with the drawn angle of :func:`_angles_of_points`; found from
    the kinematics at ``q_ref`` (the linkage's mid-stroke posture by default) and
    checked to be the same at the joints' other postures (a revolute joint's angle is
    its drawn angle but for the sign and the offset)."""
    if q_ref is None:
        q_ref = np.asarray(linkage.joint_angles(_mid_stroke()), float)
    q_ref = np.asarray(q_ref, float)
    g0 = _angles_of_points(linkage.forward_kinematics(q_ref))
    out = []
    for k, j in enumerate(linkage.JOINTS):
        dq = np.zeros(len(q_ref))
        dq[k] = 0.05
        d = _wrap(_angles_of_points(linkage.forward_kinematics(q_ref + dq)) - g0)
        sign = 1.0 if d[k] > 0 else -1.0
        if abs(abs(d[k]) - 0.05) > 1e-6 or np.max(np.abs(np.delete(d, k))) > 1e-6:
            raise ValueError(f"the drawing cannot show joint {j!r}: turning it by 0.05 rad turns the drawn "
                             f"angles by {list(np.round(d, 6))}")
        out.append({"joint": j, "sign": sign, "offset": float(g0[k] - sign * q_ref[k])})
    return out


def _mid_stroke() -> np.ndarray:
    """Each piston at half its stroke [m] (the linkage's parameters)."""
    return 0.5 * linkage.excavator_parameters().strokes


# -- one run, one live frame, for the machine of one joint or four -------------------------------
# What differs between the boom and the excavator is the mechanism's drawing: its joints, the
# posture's quantities (one number each, or one per joint), the points it draws from, its scene,
# its forces (the piston's, scalar; or the tip's, 3-vectors) and the frame's ``kind`` (the boom's
# frame has none: the page's default).  :class:`Run`, :func:`load_run` and :func:`live_frame`
# are the same code for both.

def _missing(path, message: str, column: str):
    from ..recording import RecordingError
    return RecordingError(path, message, row=1, column=column)


@dataclass(frozen=True)
class BoomMechanism:
    """The boom's load (Eq. 8 to 12) as the view draws it: one joint, its angle ``alpha``
    and piston position ``x``, the points R and T of ``physics.linkage_points``, the
    piston's forces FORCES."""
    geom: Geometry = Geometry()
    L: float = reference_rig.L

    kind = "boom"
    joints = ("boom",)
    truth = "f_ext"

    def head(self, t: float) -> dict:
        return {"type": "frame", "t": t}

    def scene(self) -> dict:
        """The fixed parts of the drawing [m]: the pivots O and C, the stroke, the
        cylinder's body and rod lengths and bore, the bucket tip's distance from O."""
        geom, L = self.geom, self.L
        C, _ = linkage_points(0.0, geom)
        return {"O": [0.0, 0.0], "C": [C[0], C[1]], "a": geom.a, "b": geom.b, "h": geom.h,
                "l_min": geom.l_min, "L": L, "r_tip": TIP_OVER_B * geom.b,
                "body_length": geom.l_min - 0.02, "rod_length": L + 0.03,
                "bore": reference_rig.bore, "rod": reference_rig.rod}

    def points(self, alpha: float | None) -> dict:
        """The moving pivots for a boom angle: R (the rod's) and T (the bucket's tip, on
        the ray O->R at TIP_OVER_B * b from O)."""
        if alpha is None:
            return {"R": None, "T": None}
        _, R = linkage_points(alpha, self.geom)
        return {"R": [float(R[0]), float(R[1])], "T": [float(TIP_OVER_B * R[0]), float(TIP_OVER_B * R[1])]}

    def posture(self, values: dict) -> dict:
        """A posture from its POSTURE values (the frame's ``machine`` or ``model``)."""
        return dict(values, **self.points(values["alpha"]))

    def columns(self, rec, d: pd.DataFrame, suffix: str) -> dict:
        cols = {k: d[k + suffix].to_numpy(float) for k in ("alpha", "p_a", "p_b")}
        x = d.get("x" + suffix)
        cols["x"] = x.to_numpy(float) if x is not None else np.asarray(x_from_alpha(cols["alpha"], self.geom))
        return {k: cols[k] for k in POSTURE}

    def has_model(self, d: pd.DataFrame) -> bool:
        return "alpha_measured" in d

    def forces(self, rec, d: pd.DataFrame) -> dict:
        return {k: d[k].to_numpy(float) for k in FORCES if k in d}

    def frame_forces(self, at, forces: dict) -> dict:
        return {k: (at(forces[k]) if k in forces else None) for k in FORCES}

    def live_posture(self, sample: dict, suffix: str) -> dict | None:
        alpha = sample.get("alpha" + suffix)
        if alpha is None:
            return None
        x = sample.get("x" + suffix)
        return self.posture({"alpha": float(alpha),
                             "x": float(x) if x is not None else float(x_from_alpha(alpha, self.geom)),
                             "p_a": sample.get("p_a" + suffix), "p_b": sample.get("p_b" + suffix)})

    def live_forces(self, sample: dict) -> dict:
        return {k: sample.get(k) for k in FORCES}

    live_missing = "a live sample needs alpha or alpha_measured"


@dataclass(frozen=True)
class LinkageMechanism:
    """The excavator's linkage as the view draws it: the joints ``linkage.JOINTS``,
    each one's angle and pressures, the points of ``physics.linkage.forward_kinematics``,
    the tip's forces TIP_FORCES and their interval TIP_BOUNDS; ``angle_map`` as
    :func:`excavator_angle_map` (None: found at mid-stroke)."""
    angle_map: list | None = None

    kind = "excavator"
    joints = linkage.JOINTS
    truth = "f_tip"

    def head(self, t: float) -> dict:
        return {"type": "frame", "kind": "excavator", "t": t}

    def scene(self) -> dict:
        """The fixed parts of the excavator's drawing: its joints, each cylinder's bore
        and rod [m], the ground's height (z = 0), the tip force's arrow scale and how the
        drawn angles map to the recording's (:func:`excavator_angle_map`)."""
        params = linkage.excavator_parameters()
        cylinders = {j: {"bore": a.bore, "rod": a.rod} for j, a in zip(self.joints, params.actuators)}
        return {"kind": "excavator", "joints": list(self.joints), "cylinders": cylinders, "ground_z": 0.0,
                "force_scale": TIP_FORCE_SCALE,
                "angle_map": self.angle_map if self.angle_map is not None else excavator_angle_map()}

    def points(self, q) -> dict | None:
        """The drawing's points [m, world frame] for the joint angles ``q`` (swing, boom's
        alpha, arm, bucket), as lists; None for a posture with an angle missing."""
        if q is None or any(v is None for v in q):
            return None
        return {k: [float(c) for c in v] for k, v in linkage.forward_kinematics(np.asarray(q, float)).items()}

    def posture(self, values: dict) -> dict:
        """A posture from its EXCAVATOR_POSTURE values, each a list in joint order."""
        out = {k: dict(zip(self.joints, values[k])) for k in EXCAVATOR_POSTURE}
        return dict(out, points=self.points(list(out["angle"].values())))

    def columns(self, rec, d: pd.DataFrame, suffix: str) -> dict:
        missing = [f"{k}_{j}{suffix}" for k in EXCAVATOR_POSTURE for j in self.joints if f"{k}_{j}{suffix}" not in d]
        if missing:
            raise _missing(rec.path, "a run with the machine's columns (_measured) beside the model's needs "
                                     "every joint's angle, p_a and p_b of both", missing[0])
        return {k: np.column_stack([d[f"{k}_{j}{suffix}"].to_numpy(float) for j in self.joints])
                for k in EXCAVATOR_POSTURE}

    def has_model(self, d: pd.DataFrame) -> bool:
        return any(f"angle_{j}_measured" in d for j in self.joints)

    def forces(self, rec, d: pd.DataFrame) -> dict:
        forces = {}
        for key, prefix in {**TIP_FORCES, **TIP_BOUNDS}.items():
            cols = [f"{prefix}_{a}" for a in "xyz"]
            present = [c for c in cols if c in d]
            if present and len(present) < 3:
                raise _missing(rec.path, f"a tip force needs all three of {', '.join(cols)}",
                               next(c for c in cols if c not in d))
            if present:
                vals = np.column_stack([d[c].to_numpy() for c in cols])
                if vals.dtype.kind not in "fiu":
                    raise _missing(rec.path, "a tip force must be numbers", cols[0])
                forces[key] = vals.astype(float)
                if key in TIP_BOUNDS:                 # an open side: no bound to draw
                    forces[key][np.abs(forces[key]) >= F_BOUND] = np.nan
        return forces

    def frame_forces(self, at, forces: dict) -> dict:
        out = {k: (at(forces[k]) if k in forces else None) for k in TIP_FORCES}
        for k, v in out.items():
            if v is not None and any(c is None for c in v):
                out[k] = None
        out.update({k: (at(forces[k]) if k in forces else None) for k in TIP_BOUNDS})
        return out

    def live_posture(self, sample: dict, suffix: str) -> dict | None:
        q = [sample.get(f"angle_{j}{suffix}") for j in self.joints]
        if any(v is None for v in q):
            return None
        out = {k: {j: sample.get(f"{k}_{j}{suffix}") for j in self.joints} for k in EXCAVATOR_POSTURE}
        return dict(out, points=self.points(q))

    def live_forces(self, sample: dict) -> dict:
        forces = {}
        for key, prefix in TIP_FORCES.items():
            v = [sample.get(f"{prefix}_{a}") for a in "xyz"]
            forces[key] = None if any(c is None for c in v) else [float(c) for c in v]
        for key, prefix in TIP_BOUNDS.items():                 # per axis; an open side None
            v = [sample.get(f"{prefix}_{a}") for a in "xyz"]
            forces[key] = (None if all(c is None for c in v) else
                           [float(c) if c is not None and abs(float(c)) < F_BOUND else None for c in v])
        return forces

    live_missing = "a live excavator sample needs every joint's angle (angle_<joint> or angle_<joint>_measured)"


def mechanism_of(machine) -> "BoomMechanism | LinkageMechanism":
    """The view's drawing of a ``model.machine.Machine``: the boom's load (the machine of
    one joint, its model's geometry and stroke) or the excavator's linkage."""
    if machine.mechanism == "boom":
        return BoomMechanism(machine.model.geometry, machine.model.cylinder.L)
    return LinkageMechanism()


@dataclass
class Run:
    """A run's columns as arrays, for the machine of one joint or four (``mechanism``):
    ``machine`` and ``model`` map the posture's quantities to arrays (one column, or
    (n, joints) in the joints' order; ``model`` is None for a recording of the machine
    alone); ``forces`` maps the forces present (the tip's interval with an open side nan)."""
    path: Path
    t: np.ndarray
    machine: dict
    model: dict | None
    forces: dict
    mechanism: "BoomMechanism | LinkageMechanism"

    @property
    def kind(self) -> str:
        return self.mechanism.kind

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def has_truth(self) -> bool:
        return self.mechanism.truth in self.forces

    def scene(self) -> dict:
        return self.mechanism.scene()

    def frame(self, t: float) -> dict:
        """The frame at time ``t`` [s]: linear interpolation between samples (exact at
        a sample's time), the run's ends held outside it."""
        t = min(max(float(t), float(self.t[0])), float(self.t[-1]))
        i = min(max(int(np.searchsorted(self.t, t, side="right")) - 1, 0), len(self.t) - 1)
        w = (t - self.t[i]) / (self.t[i + 1] - self.t[i]) if i < len(self.t) - 1 and self.t[i + 1] > self.t[i] else 0.0

        def at(col: np.ndarray):
            v = col[i] if w == 0.0 else col[i] + w * (col[i + 1] - col[i])
            if np.ndim(v):
                return [float(x) if math.isfinite(x) else None for x in v]
            return float(v) if math.isfinite(v) else None

        mech = self.mechanism

        def posture(cols: dict) -> dict:
            return mech.posture({k: at(c) for k, c in cols.items()})

        return {**mech.head(t), "machine": posture(self.machine),
                "model": posture(self.model) if self.model is not None else None,
                **mech.frame_forces(at, self.forces)}

    def history(self, t: float, window: float = 10.0, rate: float = 30.0) -> list[dict]:
        """Frames over the ``window`` seconds before ``t``, ``rate`` per second, for the
        page's plots after a seek or a (re)connection."""
        start = max(float(self.t[0]), t - window)
        n = int((t - start) * rate)
        return [self.frame(start + k / rate) for k in range(n)] + [self.frame(t)]


def load_run(path) -> Run:
    """Read a run file (see the module's text), the boom's or the excavator's (the
    recording's kind); raises RecordingError naming the file, line and column of anything
    malformed."""
    rec = read_recording(path)
    d: pd.DataFrame = rec.data
    if rec.kind == "excavator":
        mech = LinkageMechanism()
    else:
        mech = BoomMechanism(rec.rig_tuple(Geometry), rec.rig_tuple(Cylinder).L)
    if mech.has_model(d):
        machine, model = mech.columns(rec, d, "_measured"), mech.columns(rec, d, "")
    else:
        machine, model = mech.columns(rec, d, ""), None
    forces = mech.forces(rec, d)
    if isinstance(mech, LinkageMechanism):      # the drawn angles, found at the run's first posture
        try:
            mech = LinkageMechanism(excavator_angle_map(machine["angle"][0]))
        except ValueError:
            mech = LinkageMechanism(excavator_angle_map())
    return Run(Path(path), d["t"].to_numpy(float), machine, model, forces, mech)


def live_frame(sample: dict, geom: Geometry) -> dict:
    """A frame from one live sample: the flat mapping a co-simulation sends
    (``view.live.LiveSender``): ``t``, the model's ``alpha, x, p_a, p_b`` (an
    excavator's: ``angle_<joint>``, ``p_a_<joint>``...), the machine's the same suffixed
    ``_measured``, and whichever forces it has (an excavator's: ``f_tip_<a>``,
    ``f_tip_est_<a>``, ``f_reflect_<a>``, ``f_tip_lo/hi_<a>``).  A sample without the
    machine's columns shows the model as the machine (a model-only run).  ``geom`` is the
    boom's (an excavator's sample has none)."""
    mech = LinkageMechanism() if is_excavator_sample(sample) else BoomMechanism(geom)
    machine, model = mech.live_posture(sample, "_measured"), mech.live_posture(sample, "")
    if machine is None:
        machine, model = model, None
    if machine is None:
        raise ValueError(mech.live_missing)
    return {**mech.head(float(sample.get("t", 0.0))), "machine": machine, "model": model,
            **mech.live_forces(sample)}


def is_excavator_sample(sample: dict) -> bool:
    """Whether a live sample is the excavator's (it has a joint's angle)."""
    return any(f"angle_{j}{s}" in sample for j in linkage.JOINTS for s in ("", "_measured"))


__all__ = ["Run", "BoomMechanism", "LinkageMechanism", "mechanism_of", "load_run", "live_frame"]
