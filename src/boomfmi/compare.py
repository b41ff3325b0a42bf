"""Model against recording: the one place where the two are compared.

A recording comes from a rig whose values its sidecar may set (``recording-format.md``:
the sidecar's ``rig`` values override the reference rig's).  :func:`rig_model` builds
that rig's :class:`~boomfmi.model.Model` once; :func:`model_for` puts identified load
values and candidate effects on it; :func:`initial_state` says where the recording
starts; :func:`simulate_recording` runs the monolithic reference on the recording's
command and samples; :func:`recorded` and :func:`nrmse` compare channel by channel.
Identification, diagnosis and ``boomfmi simulate`` all compare through these.
"""
from __future__ import annotations

import bisect
import math

import numpy as np

from . import physics as ph
from .model import Model
from .model.reference import simulate_reference
from .recording import Recording

#: The channels on which model and recording are compared: chamber pressures (gauge)
#: and the piston position from the angle (Eq. 12).
CHANNELS = ("p_a", "p_b", "x")
#: the channels measured by pressure transducers (compared as sensed: :func:`as_sensed`)
PRESSURES = ("p_a", "p_b")


def rig_model(rec: Recording) -> Model:
    """The model at the recording's rig: the reference rig's values with the sidecar's
    overrides (valve, gas, cylinder, geometry, load, P_atm), no effects."""
    return Model(valve=rec.rig_tuple(ph.Valve), gas=rec.rig_tuple(ph.Gas), cylinder=rec.rig_tuple(ph.Cylinder),
                 geometry=rec.rig_tuple(ph.Geometry), load=rec.rig_tuple(ph.Load), P_atm=rec.P_atm)


def model_for(values: dict, effects: dict | None = None, rig: Model | None = None) -> Model:
    """``rig`` (a :func:`rig_model`; default the reference rig) with the identified
    ``values`` in place of its load (and ``A_max``) and the candidate ``effects`` on."""
    rig = rig if rig is not None else Model()
    load = rig.load._replace(**{k: values[k] for k in ph.Load._fields if k in values and math.isfinite(values[k])})
    valve = rig.valve._replace(A_max=values["A_max"]) if "A_max" in values else rig.valve
    return Model(valve=valve, gas=rig.gas, cylinder=rig.cylinder, geometry=rig.geometry, load=load,
                 P_atm=rig.P_atm, effects=dict(effects or {}))


def initial_state(rec: Recording, rig: Model | None = None) -> tuple[float, float, float]:
    """Where a recording starts: the piston position x0 [m] (Eq. 12 from the first
    angle, within the stroke, at the recording's rig) and the absolute chamber pressures
    p_a0, p_b0 [Pa]."""
    rig = rig if rig is not None else rig_model(rec)
    alpha0 = float(rec.data["alpha"].iloc[0])
    x0 = float(np.clip(ph.x_from_alpha(alpha0, rig.geometry), 0.0, rig.cylinder.L))
    return (x0, float(rec.data["p_a"].iloc[0]) + rig.P_atm, float(rec.data["p_b"].iloc[0]) + rig.P_atm)


#: A change of the recorded command [V] from one sample to the next beyond which it is a
#: step (the solver restarts there); smaller changes, as of a sine sweep, are followed
#: as a ramp through the samples.
U_STEP = 0.25
#: The longest step [s] the solver may take where the command ramps (at least two of the
#: recording's samples): a state at rest (a closed valve, a stuck piston) has no error
#: for the step-size control to see, and would otherwise stride over the command's
#: moves.  Measured against a fine solve (``benchmarks/solver_step.py``, docs/solver-step.md:
#: five command designs, four effect sets, three seeds), the worst error is 0.07 of the
#: recording's noise floor at the scoring tolerance (1e-5; 0.06 with 2 ms) and 0.26 at
#: the fits' (1e-4; 0.40 with 2 ms), in a third less time than with 2 ms.
MAX_STEP = 0.01


def simulate_recording(values: dict, rec: Recording, effects: dict | None = None, rtol: float = 1e-9,
                       rig: Model | None = None, max_step: float | None = None):
    """The model with ``values`` (and ``effects``) at the recording's rig, driven by its
    command, on its times; pressures gauge like the recording.  The command is held
    between samples, as the rig's output card holds it; where it moves by less than
    ``U_STEP`` from one sample to the next, the staircase is followed as the ramp
    through its steps' midpoints (half a sample later than the samples: the staircase's
    mean delay), so that the solver need not restart at every sample.  ``rig``: the
    recording's :func:`rig_model`, where the caller has it already.  ``max_step`` [s]:
    the longest solver step where the command ramps (default: ``MAX_STEP``, at least
    two samples)."""
    rig = rig if rig is not None else rig_model(rec)
    t = rec.data["t"].to_numpy(dtype=float)
    u = rec.data["u"].to_numpy(dtype=float)
    jumps = np.abs(np.diff(u)) > U_STEP
    changes = t[1:][jumps]
    small = np.flatnonzero((np.diff(u) != 0) & ~jumps)
    t0 = t[0]

    def command(s):
        i = max(0, int(np.searchsorted(t, s + t0 + 1e-9, side="right")) - 1)
        return {"u": float(u[i])}
    u_between = _ramp(t - t0, u, jumps) if len(small) else None
    model = model_for(values, effects, rig)
    model.x0, model.p_a0, model.p_b0 = initial_state(rec, rig)
    if max_step is None:
        max_step = max(MAX_STEP, 2.0 * float(np.median(np.diff(t))))
    sim = simulate_reference(model, command, float(t[-1] - t0), times=t - t0, breakpoints=changes - t0,
                             rtol=rtol, u_between=u_between, max_step=np.inf if u_between is None else max_step)
    sim["p_a"] -= rig.P_atm
    sim["p_b"] -= rig.P_atm
    return sim


def _ramp(t: np.ndarray, u: np.ndarray, jumps: np.ndarray):
    """The sampled command ``u`` on times ``t`` [s] as a function of time that ramps
    through its samples' midpoints (half a sample after each sample: the held
    staircase's mean delay), never across a step (``jumps[k]``: a step between sample k
    and k + 1), held at a stretch's ends."""
    seg = np.concatenate(([0], np.cumsum(jumps))).tolist()      # the stretch of each sample
    mid = (t + 0.5 * np.median(np.diff(t))).tolist()
    # as lists of floats (the solver calls this at every step: NumPy's scalar indexing
    # and searchsorted cost microseconds each; the same values, the same arithmetic)
    times, u, n = t.tolist(), u.tolist(), len(u)

    def u_between(s: float) -> float:
        i = max(0, bisect.bisect_right(times, s + 1e-9) - 1)
        j = i + 1 if s >= mid[i] else i - 1          # the neighbouring knot on s's side
        if j < 0 or j >= n or seg[j] != seg[i]:
            return float(u[i])
        return float(u[i] + (s - mid[i]) / (mid[j] - mid[i]) * (u[j] - u[i]))
    return u_between


def recorded(rec: Recording, rig: Model | None = None) -> dict:
    """A recording's x (Eq. 12 from its alpha, at its rig's geometry), p_a and p_b
    (gauge) as arrays."""
    rig = rig if rig is not None else rig_model(rec)
    return {"x": ph.x_from_alpha(rec.data["alpha"].to_numpy(dtype=float), rig.geometry),
            "p_a": rec.data["p_a"].to_numpy(float), "p_b": rec.data["p_b"].to_numpy(float)}


#: the least share of a recording's samples at exactly its extreme value for that value
#: to count as the sensor's rail (noise alone does not repeat an extreme value)
RAIL_SHARE = 0.002


def as_sensed(measured, simulated):
    """``simulated`` as the sensor that recorded ``measured`` would read it: clipped at
    that sensor's rails, each extreme of ``measured`` that repeats on at least
    ``RAIL_SHARE`` of the samples (and 5).  A gauge transducer over 0 .. 10 bar reads
    0 while a closed chamber that expands falls below the atmosphere: without this, the
    model would be blamed for the sensor's floor.  Used on the pressures only (a
    position repeats its extremes at the end stops, which the model must meet itself)."""
    m = np.asarray(measured, float)
    n_min = max(5, int(RAIL_SHARE * m.size))
    lo, hi = float(np.min(m)), float(np.max(m))
    out = np.asarray(simulated, float)
    if np.count_nonzero(m == lo) >= n_min:
        out = np.maximum(out, lo)
    if np.count_nonzero(m == hi) >= n_min:
        out = np.minimum(out, hi)
    return out


def nrmse(sim, rec: Recording, rig: Model | None = None, against=None) -> dict:
    """NRMSE of x, p_a, p_b: RMS error over the recording's range.  ``sim`` maps each
    channel to values on the recording's samples (gauge pressures); ``against``, so
    mapped too, in place of the recording (two models compared on its scale).
    Pressures are compared as their sensors read them (:func:`as_sensed`)."""
    out = {}
    for name, measured in recorded(rec, rig).items():
        span = float(np.ptp(measured)) or 1.0
        sensed = (lambda v: as_sensed(measured, v)) if name in PRESSURES else (lambda v: np.asarray(v, float))
        ref = measured if against is None else sensed(against[name])
        out[name] = float(np.sqrt(np.mean((sensed(sim[name]) - ref) ** 2)) / span)
    return out


def shrink(before: dict, after: dict) -> float:
    """``1 - (error after) / (error before)``, the errors (NRMSE per channel) summed over
    the channels: the share of the gap an effect removes."""
    return 1.0 - sum(after.values()) / max(sum(before.values()), 1e-12)


__all__ = ["CHANNELS", "PRESSURES", "rig_model", "model_for", "initial_state", "U_STEP", "MAX_STEP", "simulate_recording",
           "recorded", "RAIL_SHARE", "as_sensed", "nrmse", "shrink"]
