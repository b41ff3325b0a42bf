"""Preprocessing of recordings: the paper's second-order low-pass filter, x from alpha
by Eq. 12, and velocity and acceleration estimates.

Offline the filter runs forwards and backwards (zero phase: no delay, squared
magnitude, so an effective fourth order); ``causal=True`` gives the plain second-order
filter a controller could run online.  Derivatives are central differences of the
filtered position.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt, lfilter

from .. import physics as ph
from ..physics import linkage as exc
from ..recording import EXCAVATOR_RIG_KEYS, Recording

#: Default cut-off of the low-pass filter [Hz] (the paper does not give its own).
CUTOFF = 25.0


def lowpass(y: np.ndarray, fs: float, cutoff: float = CUTOFF, causal: bool = False) -> np.ndarray:
    """Second-order Butterworth low-pass at ``cutoff`` [Hz] of samples at ``fs`` [Hz]."""
    b, a = butter(2, cutoff / (fs / 2.0))
    if causal:
        return lfilter(b, a, y - y[0]) + y[0]
    return filtfilt(b, a, y, padtype="odd", padlen=min(len(y) - 1, 3 * max(len(a), len(b)) * 10))


@dataclass
class Prepared:
    """A recording ready for identification: every signal filtered alike, SI units,
    pressures absolute."""
    t: np.ndarray
    u: np.ndarray
    p_a: np.ndarray        #: filtered, absolute [Pa]
    p_b: np.ndarray
    x: np.ndarray          #: filtered piston position [m] from alpha by Eq. 12
    v: np.ndarray          #: [m/s]
    a: np.ndarray          #: [m/s^2]
    phi: np.ndarray        #: cylinder angle [rad], Eq. 10, from the filtered x
    x_raw: np.ndarray      #: unfiltered Eq. 12 position [m]
    p_a_raw: np.ndarray    #: unfiltered absolute pressures [Pa]
    p_b_raw: np.ndarray
    fs: float
    cutoff: float = CUTOFF  #: the low-pass filter's cut-off [Hz]
    source: str = ""

    @property
    def dt(self) -> float:
        return 1.0 / self.fs


def prepare(rec: Recording, cutoff: float = CUTOFF, geometry: ph.Geometry | None = None,
            P_atm: float | None = None) -> Prepared:
    """Filter a recording and derive x, v, a and phi, at the recording's rig (its
    sidecar's geometry and P_atm) unless ``geometry`` or ``P_atm`` are given."""
    d = rec.data
    t = d["t"].to_numpy(dtype=float)
    steps = np.diff(t)
    fs = 1.0 / float(np.median(steps))
    if np.max(np.abs(steps - 1.0 / fs)) > 0.1 / fs:
        raise ValueError(f"{rec.path}: samples are not evenly spaced (median step {1e3 / fs:.3f} ms); "
                         f"resample before identification")
    P_atm = rec.P_atm if P_atm is None else P_atm
    geometry = rec.rig_tuple(ph.Geometry) if geometry is None else geometry
    p_a_raw = d["p_a"].to_numpy(dtype=float) + P_atm
    p_b_raw = d["p_b"].to_numpy(dtype=float) + P_atm
    x_raw = ph.x_from_alpha(d["alpha"].to_numpy(dtype=float), geometry)
    x = lowpass(x_raw, fs, cutoff)
    v = np.gradient(x, t)
    a = np.gradient(v, t)
    return Prepared(t=t, u=d["u"].to_numpy(dtype=float), p_a=lowpass(p_a_raw, fs, cutoff),
                    p_b=lowpass(p_b_raw, fs, cutoff), x=x, v=v, a=a,
                    phi=ph.phi_from_x(np.clip(x, 0.0, None), geometry), x_raw=x_raw,
                    p_a_raw=p_a_raw, p_b_raw=p_b_raw, fs=fs, cutoff=cutoff, source=str(rec.path))


#: A holdout error (the NRMSE summed over x, p_a, p_b) beyond NOISE_FACTOR times the
#: noise floor (summed likewise) plus ABS_FLOOR is a gap the model does not explain.
NOISE_FACTOR = 3.0
ABS_FLOOR = 0.002


def beyond_noise(errors: dict, rec) -> dict:
    """Whether the ``errors`` (channel -> NRMSE) of a model against ``rec`` are a gap
    beyond its noise: ``beyond_noise``, ``nrmse_sum``, ``noise_floor_sum``, ``threshold``."""
    noise = float(sum(noise_floor(rec).values()))
    threshold = NOISE_FACTOR * noise + ABS_FLOOR
    total = float(sum(errors.values()))
    return {"beyond_noise": total > threshold, "nrmse_sum": total, "noise_floor_sum": noise, "threshold": threshold}


def noise_floor(rec) -> dict:
    """Each channel's measurement noise over its range (x, p_a, p_b: the NRMSE a
    perfect model would still show): the RMS of what a 50 Hz low-pass removes.  The
    floor ``identify`` judges a holdout error against and ``diagnose`` its gaps."""
    from ..compare import CHANNELS, recorded
    m = recorded(rec)
    fs = 1.0 / float(np.median(np.diff(rec.data["t"].to_numpy(float))))
    return {c: float(np.std(m[c] - lowpass(m[c], fs, 50.0)) / max(float(np.ptp(m[c])), 1e-12)) for c in CHANNELS}


# --- a machine of joints: the data of each joint (issue 32: one pipeline for one joint or four)

@dataclass
class JointData:
    """One recording's joint of the linkage, ready for every stage of
    ``identify.joints``."""
    p: Prepared                #: the joint as an equivalent single cylinder (unit areas; F_net as p_a - P_atm)
    modes: object              #: fit.Modes of its position
    F_p: np.ndarray            #: pneumatic force [N], from the raw pressures
    scale: np.ndarray          #: Eq. 9's factor (cos(phi) for the boom, 1 otherwise)
    D0: np.ndarray             #: M_x(0) x'' + bias(0) - lam J^T f_tip [N] (25 Hz signals)
    dD: np.ndarray             #: the payload's share per kg [N/kg]
    own0: np.ndarray           #: the joint's own inertia M_x[i,i](0) x''_i [N]
    unsure: np.ndarray         #: [N] the other joints' motion's share of the net force (its coupling terms
                               #: less gravity, no payload): known only as well as their filtered
                               #: accelerations and speeds; its whole size, what it may be off by at most
    coupling_error: np.ndarray  #: [N] how far those terms move between the other joints' motion filtered
                                #: at the cut-off and at twice it: the scale of their error
    down: np.ndarray           #: its payload share per kg [N/kg]
    Mii0: np.ndarray           #: M_x[i, i] at no payload [kg]
    dMii: np.ndarray           #: per kg of payload
    L: float


def machine_for(rec, ex: exc.Excavator | None = None) -> exc.Excavator:
    """The linkage of an excavator recording: ``ex`` (default: ``excavator.md``'s
    machine) with the recording's sidecar values (a machine file's, ``machine.py``:
    ``<field>_<joint>`` ..., P_atm)."""
    ex = ex or exc.Excavator()
    own = {k: float(v) for k, v in rec.rig.items() if k in EXCAVATOR_RIG_KEYS}
    return exc.excavator_from_values(own, ex) if own else ex


def machine_of(rec):
    """The machine (``model.machine.Machine``) a recording is of, by its kind: the
    boom rig of its sidecar (``compare.rig_model``: one joint) or the whole excavator
    of its sidecar (:func:`machine_for`: four)."""
    from ..compare import rig_model
    from ..model.machine import boom_machine, excavator_machine
    from ..recording import recording_kind
    if recording_kind(rec) == "excavator":
        return excavator_machine(machine_for(rec))
    return boom_machine(rig_model(rec))


def _frame(rec):
    """The recording's data as a DataFrame (a Recording or a DataFrame)."""
    return rec.data if hasattr(rec, "data") else rec


def prepare_machine(rec, machine=None, cutoff: float = CUTOFF) -> list:
    """A recording ready for identification, one entry per joint of ``machine`` (a
    ``model.machine.Machine``, or the linkage ``physics.linkage.Excavator``; default
    ``excavator.md``'s): the one-joint machine (the boom rig) is the boom's load whole
    (Eq. 8 to 12), its entry :func:`prepare` at its geometry and P_atm; each joint of
    the linkage a :class:`JointData` (``Recording`` or DataFrame with the excavator's
    columns, pressures gauge), the linkage's known terms evaluated at every sample."""
    if machine is not None and getattr(machine, "model", None) is not None:
        return [prepare(rec, cutoff, geometry=machine.model.geometry, P_atm=machine.model.P_atm)]
    ex = getattr(machine, "ex", machine) if machine is not None else exc.Excavator()
    return _prepare_linkage(rec, ex, cutoff)


#: How long [s] before and after it slides a joint still counts as moving for the other
#: joints' net force (:func:`_prepare_linkage`): its motion filtered at the preparation's
#: cut-off spreads a start's or a stop's acceleration over about a period of it
#: (40 ms at 25 Hz), and the classification sees a start only once the speed passes the
#: threshold that tells it from rest.
STILL_MARGIN = 0.03


def _others(Mx: np.ndarray, acc: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """Each piston's share [N] of the other joints' inertia (``Mx`` [kg] times the
    accelerations ``acc`` [m/s^2], less its own) and of ``bias`` (velocity and gravity
    terms, ``physics.linkage.piston_dynamics``); at one sample or at every row ((n, 4, 4),
    (n, 4), (n, 4))."""
    own = np.diagonal(Mx, axis1=-2, axis2=-1) * acc
    return np.einsum("...ij,...j->...i", Mx, acc) - own + bias


def _prepare_linkage(rec, ex: exc.Excavator, cutoff: float) -> list[JointData]:
    """:func:`prepare_machine` on the linkage: one :class:`JointData` per joint of
    ``physics.linkage.JOINTS``.

    A joint's net force (its ``p_a``, everything on it but its own inertia and
    friction) holds the other joints' inertia and velocity terms from their motion
    filtered at ``cutoff``.  Where such a joint rests (``fit.modes_of``, more than
    :data:`STILL_MARGIN` from its sliding) its acceleration is zero, not the twice
    differentiated noise of a quantised angle: that noise, 0.6 to 1.5 N on the
    bucket's, the boom's and the arm's net force with the excavator rig's 12-bit
    angles, is the size of a start's evidence of F_s (its running maximum reached each
    level early).

    Those terms are known only as well as the filtered motion: ``unsure`` is their
    whole size (what a rest's force may be off by at most: the bound F_s must exceed),
    ``coupling_error`` how far they move when the other joints' motion is filtered at
    twice ``cutoff`` (the scale of their error, by which a start's evidence of F_s is
    blurred).  Blurred by their whole size, the arm's starts put F_s 1.25 % low on
    average over ten noise draws (benchmarks/excavator_identification.py --noise-seeds);
    bounded by the error's scale only, a rest of the boom's while the arm and the bucket
    swing bounded F_s 30 % above its truth."""
    from .fit import _dilate, modes_of          # fit builds on this module
    JOINTS = exc.JOINTS
    d = _frame(rec)
    P_atm = float(rec.P_atm) if hasattr(rec, "P_atm") else ex.P_atm
    t = d["t"].to_numpy(float)
    fs = 1.0 / float(np.median(np.diff(t)))
    q_raw = np.column_stack([d[f"angle_{j}"].to_numpy(float) for j in JOINTS])
    x_raw = exc.pistons_from_angles(q_raw, ex)
    x = np.column_stack([lowpass(x_raw[:, i], fs, cutoff) for i in range(4)])
    v = np.gradient(x, t, axis=0)
    a = np.gradient(v, t, axis=0)
    p_a = np.column_stack([d[f"p_a_{j}"].to_numpy(float) for j in JOINTS]) + P_atm
    p_b = np.column_stack([d[f"p_b_{j}"].to_numpy(float) for j in JOINTS]) + P_atm
    F_p = exc.cylinder_forces(p_a, p_b, ex)
    f_tip = None
    if all(c in d for c in ("f_tip_x", "f_tip_y", "f_tip_z")):
        f_tip = d[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy(float)
        if not np.any(f_tip):
            f_tip = None
    n = len(t)
    modes = [modes_of(x_raw[:, i], t, fs, act.stroke) for i, act in enumerate(ex.actuators)]
    moving = np.column_stack([_dilate(m.sliding, int(round(STILL_MARGIN * fs))) for m in modes])
    a_moving = np.where(moving, a, 0.0)
    # the same motion filtered twice as fast: how far the coupling terms move with it
    x2 = np.column_stack([lowpass(x_raw[:, i], fs, min(2.0 * cutoff, 0.45 * fs)) for i in range(4)])
    v2 = np.gradient(x2, t, axis=0)
    a2_moving = np.where(moving, np.gradient(v2, t, axis=0), 0.0)
    xc = np.clip(x, 0.0, ex.strokes)
    # the linkage's terms at every sample (without the payload, and their change per
    # kilogram of it: they are linear in it)
    (Mx0, bias0, _), (Mx1, bias1, _) = (exc.piston_dynamics(xc, v, m, ex) for m in (0.0, 1.0))
    inertia = lambda Mx, acc: np.einsum("nij,nj->ni", Mx, acc)
    diag0, diag1 = np.diagonal(Mx0, axis1=1, axis2=2), np.diagonal(Mx1, axis1=1, axis2=2)
    D = np.stack([inertia(Mx0, a) + bias0, inertia(Mx1, a) + bias1])
    own = np.stack([diag0 * a, diag1 * a])
    Mii = np.stack([diag0, diag1])
    # the other joints' inertia from where they move only (the velocity terms as they
    # are: a resting joint's speed noise enters them squared)
    coupling = _others(Mx0, a_moving, bias0)
    unsure = np.abs(coupling - exc.piston_dynamics(xc, np.zeros_like(v), 0.0, ex)[1])
    # M_x depends on the posture only: the faster filter's terms need its bias alone
    coupling_error = np.abs(coupling - _others(Mx0, a2_moving, exc.piston_dynamics(xc, v2, 0.0, ex)[1]))
    if f_tip is not None:
        for k in np.flatnonzero(np.any(f_tip != 0.0, axis=1)):     # (a zero force has no torque)
            q = exc.joint_angles(xc[k], ex)
            tau = exc.tip_torques(q, f_tip[k], ex) / exc.lever_arms(xc[k], ex)
            D[0, k] -= tau
            D[1, k] -= tau
            coupling[k] -= tau
    scale = exc.friction_scale(xc, ex)
    phi_boom = ph.phi_from_x(xc[:, 1], ex.geometry)
    out = []
    for i, (j, act) in enumerate(zip(JOINTS, ex.actuators)):
        F_net = F_p[:, i] - coupling[:, i]     # everything on it but its own inertia and friction
        phi = phi_boom if j == "boom" else np.zeros(n)
        p = Prepared(t=t, u=d[f"u_{j}"].to_numpy(float), p_a=lowpass(F_net, fs, cutoff) + P_atm,
                     p_b=np.full(n, P_atm), x=x[:, i], v=v[:, i], a=a[:, i], phi=phi, x_raw=x_raw[:, i],
                     p_a_raw=F_net + P_atm, p_b_raw=np.full(n, P_atm), fs=fs, cutoff=cutoff,
                     source=f"{getattr(rec, 'path', '')}:{j}")
        out.append(JointData(p=p, modes=modes[i], F_p=F_p[:, i], scale=scale[:, i],
                             D0=D[0, :, i], dD=D[1, :, i] - D[0, :, i], own0=own[0, :, i],
                             unsure=unsure[:, i], coupling_error=coupling_error[:, i],
                             down=own[1, :, i] - own[0, :, i], Mii0=Mii[0, :, i], dMii=Mii[1, :, i] - Mii[0, :, i],
                             L=act.stroke))
    return out

__all__ = [
    "CUTOFF", "lowpass", "Prepared", "prepare", "NOISE_FACTOR", "ABS_FLOOR", "beyond_noise",
    "noise_floor", "JointData", "machine_for", "machine_of", "prepare_machine",
]
