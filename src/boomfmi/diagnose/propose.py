"""The next experiment: the command profile that would tell two explanations apart.

Where the diagnosis cannot decide (the two most probable explanations within a factor
``AMBIGUOUS`` of each other, or ``unexplained`` the most probable: :func:`ambiguous`), each
design of :data:`DESIGNS` (the command profiles of ``experiments.py`` at a few of their
parameters: seed, depth, holds, duration) is simulated under both hypotheses by the
model the diagnosis fitted them with (``compare.simulate_recording``, at the holdout's
rig and start), and the design whose two predictions differ most relative to the
recordings' noise is proposed (:func:`propose`).  The *separation* of a design is the
expected log-likelihood ratio between the hypotheses that one recording of it gives,
under white Gaussian sensor noise of each channel's floor (``identify.preprocess.noise_floor``,
in the channel's own units)::

    separation = 1/2 sum_channels sum_samples (y_1 - y_2)^2 / sigma_channel^2

(the Kullback-Leibler divergence of one hypothesis' recording from the other's): a
design with separation ``S`` makes the wrong one ``exp(-S)`` as likely, on average.
The noise floor is the fast part of the noise; a model's slow misfit is not counted,
so the figure ranks designs rather than promising odds.

"unexplained" has no model: against it, the design that best separates the most
probable explanation of the catalogue from the baseline (``none``) is proposed, so
that the new recording shows whether that explanation's signature is really there.

The proposal is written as a command CSV (:func:`write_command_csv`: columns ``t`` [s]
and ``u`` [V] at the DAQ's 1 ms), which ``experiments.profile`` reads (``boomfmi record
--experiment next.csv``, ``rig.offline.run_offline``), with a plot of both predictions
(:func:`plot_proposal`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..compare import CHANNELS, recorded, simulate_recording
from ..experiments import COMMAND_COLUMNS, PROFILES, command_samples
from ..identify.preprocess import noise_floor
from ..recording import Recording
from .evidence import NONE, UNEXPLAINED

#: the two most probable explanations within this factor of each other: an experiment is proposed
AMBIGUOUS = 10.0
#: the DAQ's sample period of a proposed command [s]
DT = 1e-3
#: the solver's tolerance for the predictions (the diagnosis scores at 1e-5; designs are only ranked)
RTOL = 1e-4
#: the designs tried: (profile name, its parameters); each about 10 s
DESIGNS = (
    ("paper_multistep", {}),
    ("random_steps", {"seed": 1, "duration": 10.0}),
    ("random_steps", {"seed": 2, "duration": 10.0, "hold": (0.8, 2.0)}),
    ("slow_ramps", {"seed": 1, "duration": 10.0}),
    ("slow_ramps", {"seed": 2, "duration": 10.0, "depth": (1.5, 3.0), "hold": (0.8, 1.6)}),
    ("manoeuvres", {"seed": 1, "duration": 10.0}),
    ("sine_sweep", {"seed": 1, "duration": 10.0}),
)


@dataclass
class Hypothesis:
    """An explanation with a model: its name (``none``, an effect, ``a + b``), the
    baseline's values it runs with and its effects ``{effect: {parameter: value}}``."""
    name: str
    values: dict
    effects: dict = field(default_factory=dict)


@dataclass
class Proposal:
    """The design proposed, with what it would show."""
    design: str                 #: the profile's name in ``experiments``
    params: dict                #: its parameters
    hypotheses: tuple           #: the two names it tells apart
    separation: float           #: its expected log-likelihood ratio per recording (see the module)
    t: np.ndarray               #: the command's times [s] (from 0, at ``DT``)
    u: np.ndarray               #: the command [V]
    predictions: dict           #: hypothesis name -> {channel: array on ``t``} (pressures gauge, x in m)
    noise: dict                 #: channel -> the noise sigma the separation used (Pa, m)
    table: list                 #: every design tried: {"design", "params", "separation"}, best first
    reason: str = ""            #: why an experiment is proposed (which two are close)
    seconds: float = float("nan")   #: the wall time the proposal took (set by its caller)

    def summary(self) -> dict:
        """For ``diagnosis.json``: no arrays."""
        return {"design": self.design, "params": _plain(self.params), "hypotheses": list(self.hypotheses),
                "separation": round(self.separation, 3), "duration_s": round(float(self.t[-1]), 3),
                "noise_sigma": {c: float(f"{v:.4g}") for c, v in self.noise.items()}, "reason": self.reason,
                **({"seconds": round(self.seconds, 1)} if math.isfinite(self.seconds) else {}),
                "designs": [{**d, "params": _plain(d["params"]), "separation": round(d["separation"], 3)}
                            for d in self.table]}


def _plain(params: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in params.items()}


def ambiguous(probabilities: dict, factor: float = AMBIGUOUS) -> tuple[str, str] | None:
    """The two explanations an experiment should tell apart, from the diagnosis'
    ``{set: probability}``; None where the most probable is at least ``factor`` times
    as probable as the next, unless it is ``unexplained`` (the verdict names no cause: the
    experiment should find one; ``unexplained`` a distant second decides nothing)
    (``factor=inf``: the two most probable, however far apart).  With
    ``unexplained`` among the two, the other is the catalogue's most probable set (not
    ``none``) and ``unexplained`` is replaced by ``none`` (it has no model: the
    experiment tells whether the explanation's signature is there at all); None where
    the catalogue offers no set."""
    ranked = sorted(probabilities.items(), key=lambda kv: -kv[1])
    if len(ranked) < 2:
        return None
    (a, pa), (b, pb) = ranked[:2]
    if a != UNEXPLAINED and pa >= factor * pb:
        return None
    if UNEXPLAINED not in (a, b):
        return a, b
    named = next((n for n, _ in ranked if n not in (NONE, UNEXPLAINED)), None)
    return None if named is None else (named, NONE)


def design_profile(design: str, params: dict):
    """The command profile ``experiments.<design>(**params)``."""
    if design not in PROFILES:
        raise ValueError(f"unknown design {design!r}; known: {', '.join(PROFILES)}")
    return PROFILES[design](**params)


def start_recording(prof, start: Recording) -> Recording:
    """A recording of ``prof``'s command (at ``DT``) on ``start``'s rig, starting where
    ``start`` starts (its first angle and pressures held: only the command and the first
    sample are read by ``compare.simulate_recording``)."""
    t, u = command_samples(prof, DT)
    first = start.data.iloc[0]
    data = pd.DataFrame({"t": t, "u": u, "p_a": float(first["p_a"]), "p_b": float(first["p_b"]),
                         "alpha": float(first["alpha"])})
    return Recording(Path(f"<proposed {getattr(prof, '__name__', 'design')}>"), data, dict(start.rig))


def noise_sigma(recs) -> dict:
    """Each channel's noise in its own units (Pa, m): the noise floor (over the range)
    times the range, averaged over ``recs``."""
    out = {c: [] for c in CHANNELS}
    for r in recs:
        floor, m = noise_floor(r), recorded(r)
        for c in CHANNELS:
            out[c].append(floor[c] * float(np.ptp(m[c])))
    return {c: max(float(np.mean(v)), 1e-12) for c, v in out.items()}


def separation(a: dict, b: dict, sigma: dict) -> float:
    """``1/2 sum_c sum_k (a_c - b_c)^2 / sigma_c^2``: the expected log-likelihood ratio."""
    return float(sum(0.5 * np.sum((np.asarray(a[c]) - np.asarray(b[c])) ** 2) / sigma[c] ** 2 for c in CHANNELS))


def _predict(job):
    hyp, rec = job
    sim = simulate_recording(hyp.values, rec, effects=hyp.effects, rtol=RTOL)
    return {c: sim[c].to_numpy(dtype=float) for c in CHANNELS}


def propose(hypotheses, start: Recording, noise: dict, designs=DESIGNS, workers: int = 1,
            reason: str = "") -> Proposal:
    """The design of ``designs`` (``(profile name, parameters)``) whose predictions under
    the two ``hypotheses`` (:class:`Hypothesis`) differ most over ``noise`` (channel ->
    sigma in its units, :func:`noise_sigma`): each design run under both from
    ``start``'s rig and first sample (:func:`start_recording`), ``workers`` processes."""
    from .attribute import _map
    h1, h2 = hypotheses
    recs = [start_recording(design_profile(d, p), start) for d, p in designs]
    jobs = [(h, r) for r in recs for h in (h1, h2)]
    preds = _map(_predict, jobs, workers, cost=lambda job: 1)
    table = []
    for i, (d, p) in enumerate(designs):
        a, b = preds[2 * i], preds[2 * i + 1]
        s = separation(a, b, noise)
        table.append({"design": d, "params": dict(p), "separation": s if math.isfinite(s) else 0.0, "i": i})
    table.sort(key=lambda row: -row["separation"])
    best = table[0]
    i = best["i"]
    rec = recs[i]
    for row in table:
        del row["i"]
    return Proposal(best["design"], best["params"], (h1.name, h2.name), best["separation"],
                    rec.data["t"].to_numpy(), rec.data["u"].to_numpy(),
                    {h1.name: preds[2 * i], h2.name: preds[2 * i + 1]}, dict(noise), table, reason)


def write_command_csv(proposal: Proposal, path, inputs=()) -> Path:
    """Write the proposed command as a command CSV (``t`` [s], ``u`` [V]: what
    ``experiments.profile`` reads) at ``path``, as one file moved into place
    (``outputs.OutputSet``), never over one of ``inputs`` (the diagnosis' recordings)."""
    from ..outputs import OutputSet
    path = Path(path)
    with OutputSet(path.parent if str(path.parent) else Path("."), inputs=inputs) as files:
        pd.DataFrame({COMMAND_COLUMNS[0]: np.round(proposal.t, 6), COMMAND_COLUMNS[1]: np.round(proposal.u, 6)}) \
            .to_csv(files.path(path.name), index=False)
    return path


def plot_proposal(proposal: Proposal, path) -> None:
    """Both hypotheses' predictions of the proposed experiment, per channel, under its
    command, and their difference in noise sigmas (a PNG at ``path``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scale = {"x": (1e3, "x [mm]"), "p_a": (1e-5, "p_a [bar gauge]"), "p_b": (1e-5, "p_b [bar gauge]")}
    fig, axes = plt.subplots(len(CHANNELS) + 2, 1, figsize=(9, 9.5), sharex=True)
    axes[0].plot(proposal.t, proposal.u, lw=0.8, color="k")
    axes[0].set_ylabel("u [V]")
    axes[0].set_title(f"proposed: {proposal.design} {_plain(proposal.params)}, separation "
                      f"{proposal.separation:.3g}", fontsize=9)
    for ax, c in zip(axes[1:], CHANNELS):
        f, label = scale[c]
        for name, pred in proposal.predictions.items():
            ax.plot(proposal.t, f * pred[c], lw=1.0, label=name)
        ax.set_ylabel(label)
    axes[1].legend(loc="best", fontsize=8)
    a, b = (proposal.predictions[n] for n in proposal.hypotheses)     # their difference, in noise sigmas
    for c in CHANNELS:
        axes[-1].plot(proposal.t, (np.asarray(a[c]) - np.asarray(b[c])) / proposal.noise[c], lw=0.8, label=c)
    axes[-1].set_ylabel("difference / noise")
    axes[-1].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=90, format="png")
    plt.close(fig)


__all__ = ["AMBIGUOUS", "DT", "RTOL", "DESIGNS", "Hypothesis", "Proposal", "ambiguous", "design_profile",
           "start_recording", "noise_sigma", "separation", "propose", "write_command_csv", "plot_proposal"]
