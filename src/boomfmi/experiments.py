"""Named command profiles: what the operator (or a test script) sends to the valve.

Each profile is a function of time returning the system inputs ``{"u": volts}``.
``paper_multistep`` is the paper's identification experiment (reference-rig.md):
three periods, each starting with u = 10 V until the piston rests at x = 0, then
u = U_i for the rest of the period, U = 1, 2.5, 4 V.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

#: The paper's step levels U_1, U_2, U_3 [V].
PAPER_LEVELS = (1.0, 2.5, 4.0)


def multistep(levels=PAPER_LEVELS, period: float = 3.0, retract: float = 1.0,
              retract_command: float = 10.0) -> Callable[[float], dict]:
    """Periods of ``period`` [s]: ``retract_command`` for ``retract`` [s], then each level."""
    levels = tuple(levels)

    def profile(t: float) -> dict:
        i = min(int(t // period), len(levels) - 1) if t >= 0 else 0
        in_period = t - i * period
        return {"u": retract_command if in_period < retract else levels[i]}
    profile.duration = period * len(levels)
    profile.breakpoints = sorted({i * period + r for i in range(len(levels)) for r in (0.0, retract)} - {0.0})
    return profile


def paper_multistep() -> Callable[[float], dict]:
    """The paper's experiment: 3 periods of 3 s (1 s retracting at 10 V, 2 s at U_i)."""
    return multistep()


def holdout_multistep() -> Callable[[float], dict]:
    """A second multistep for holdout checks: retract at 8 V, then 1.8, 3.2 and 0.5 V."""
    return multistep(levels=(1.8, 3.2, 0.5), period=3.0, retract=1.0, retract_command=8.0)


def random_steps(seed: int = 0, duration: float = 12.0, hold=(0.15, 0.8)) -> Callable[[float], dict]:
    """Steps to random commands held for random times: extending (0.5 to 4.5 V),
    retracting (5.5 to 9.5 V) and centred, with reversals mid-stroke.  A richer
    excitation than the paper's multistep (breakaways, accelerations and decelerations
    in both directions) for identification and diagnosis."""
    rng = np.random.default_rng(seed)
    times, levels, t = [], [], 0.0
    while t < duration:
        times.append(t)
        kind = rng.choice(3, p=[0.45, 0.4, 0.15])
        levels.append(float(rng.uniform(0.5, 4.5) if kind == 0 else
                            rng.uniform(5.5, 9.5) if kind == 1 else 5.0))
        t += float(rng.uniform(*hold))

    def profile(t: float) -> dict:
        i = max(0, int(np.searchsorted(times, t, side="right")) - 1)
        return {"u": levels[i]}
    profile.duration = duration
    profile.breakpoints = times[1:]
    return profile


def held(segments) -> Callable[[float], dict]:
    """Commands held over consecutive segments: ``[(duration [s], u [V]), ...]``."""
    starts = np.concatenate(([0.0], np.cumsum([d for d, _ in segments])[:-1]))
    levels = [float(u) for _, u in segments]

    def profile(t: float) -> dict:
        return {"u": levels[max(0, int(np.searchsorted(starts, t, side="right")) - 1)]}
    profile.duration = float(sum(d for d, _ in segments))
    profile.breakpoints = [float(s) for s in starts[1:]]
    return profile


def manoeuvres(seed: int = 0, duration: float = 12.0) -> Callable[[float], dict]:
    """An operator's ordinary manoeuvres, drawn from ``seed``: runs into both stroke
    ends, large (1.5 to 4.5 V from centre) and small (0.5 to 1.5 V) openings both ways,
    holds in mid-stroke with the valve at exactly 5 V for 1 to 2 s (after a short
    extension, and left by a small opening: a breakaway from rest in mid-stroke),
    direct reversals (one direction straight into the other) and a chirp around 5 V
    (amplitude 0.8 to 1.6 V, 0.5 to 4 Hz over 1.5 s).  The blocks come in a random
    order, each followed by 0.2 to 0.5 s at the centre; every design holds a run to
    each end, a hold and a chirp.  Unlike :func:`random_steps`, most stick/slip events
    here are in mid-stroke (breakaways after a hold at the valve's centre, reversals,
    stops), not starts from an end stop."""
    rng = np.random.default_rng(seed)
    side = lambda: 1.0 if rng.random() < 0.6 else -1.0     # +1: extending (u < 5)
    blocks = ["end-", "end+", "hold", "chirp"] + list(rng.choice(("large", "small", "reversal", "hold"), size=8))
    steps, chirps, t = [], [], 0.0     # steps: (start, u); chirps: (start, stop, amplitude)

    def step(u, lo, hi):
        nonlocal t
        steps.append((t, float(u)))
        t += float(rng.uniform(lo, hi))
    for kind in (blocks[i] for i in rng.permutation(len(blocks))):
        if t >= duration:
            break
        if kind == "end-":
            step(5.0 + rng.uniform(3.0, 4.5), 0.8, 1.2)
        elif kind == "end+":
            step(5.0 - rng.uniform(3.0, 4.5), 1.0, 1.4)
        elif kind == "large":
            step(5.0 - side() * rng.uniform(1.5, 4.5), 0.1, 0.3)
        elif kind == "small":
            step(5.0 - side() * rng.uniform(0.5, 1.5), 0.3, 0.7)
        elif kind == "reversal":
            s = side()
            step(5.0 - s * rng.uniform(1.0, 3.5), 0.15, 0.35)
            step(5.0 + s * rng.uniform(1.0, 3.5), 0.15, 0.35)
        elif kind == "hold":
            step(5.0 - rng.uniform(1.5, 3.0), 0.15, 0.4)
            step(5.0, 1.0, 2.0)
            step(5.0 - side() * rng.uniform(0.5, 1.5), 0.3, 0.6)
        else:
            amp = float(rng.uniform(0.8, 1.6))
            chirps.append((t, t + 1.5, amp))
            step(5.0, 1.5, 1.5)
        step(5.0, 0.2, 0.5)
    times = [s for s, _ in steps]
    levels = [u for _, u in steps]

    def profile(t: float) -> dict:
        for t0, t1, amp in chirps:
            if t0 <= t < t1:
                tau = t - t0        # 0.5 Hz rising linearly to 4 Hz
                return {"u": 5.0 + amp * math.sin(2.0 * math.pi * (0.5 * tau + 3.5 / 3.0 * tau * tau / 2.0))}
        i = max(0, int(np.searchsorted(times, t, side="right")) - 1)
        return {"u": levels[i]}
    profile.duration = duration
    profile.breakpoints = sorted(set(times[1:]) | {c for t0, t1, _ in chirps for c in (t0, t1)})
    return profile


def sine_sweep(seed: int = 0, duration: float = 12.0) -> Callable[[float], dict]:
    """A sine sweep of the command around the centre: amplitude 1 to 2.5 V, its
    frequency rising exponentially from 0.5 Hz to 6 Hz over ``duration`` [s], on a bias
    that changes sign every 1.5 to 2.5 s (0.4 to 1 V towards extension, then as much
    towards retraction), so that the open-loop piston oscillates in mid-stroke and
    travels between the ends instead of settling on one; drawn from ``seed``.  The
    piston reverses in mid-stroke again and again and seldom rests."""
    rng = np.random.default_rng(seed)
    amp = float(rng.uniform(1.0, 2.5))
    f0, f1 = 0.5, 6.0
    rate = math.log(f1 / f0) / duration
    edges, biases, t = [], [], 0.0
    while t < duration:
        edges.append(t)
        biases.append(float(rng.uniform(0.4, 1.0)) * (-1.0 if len(biases) % 2 == 0 else 1.0))
        t += float(rng.uniform(1.5, 2.5))

    def profile(t: float) -> dict:
        bias = biases[max(0, int(np.searchsorted(edges, t, side="right")) - 1)]
        phase = 2.0 * math.pi * f0 * math.expm1(rate * max(t, 0.0)) / rate
        return {"u": min(10.0, max(0.0, 5.0 + bias + amp * math.sin(phase)))}
    profile.duration = duration
    profile.breakpoints = edges[1:]
    return profile


def dig() -> Callable[[float], dict]:
    """An operator's digging cycle for force estimation (teleoperation), 10 s, from the
    boom held at mid-stroke (x0 = 50 mm in the contact scenarios): lower it gently into
    the ground and hold, raise it a little, lower it harder and press, hold, raise it,
    lower it again and raise it.  The bucket meets the ground of a contact scenario
    (the virtual rig's ``contact``: ``examples/rig/contact_soft.json`` at x = 45 mm,
    ``contact_hard.json`` at 30 mm) on the way down.  ``contact_ramp.json``'s digging
    load, against extension, rises at 40 N/s from 1 s to 300 N at 8.5 s: across three of
    the cycle's motions (it stands at 80 to 130 N, 220 to 250 N and 260 to 290 N while
    the boom moves), after a first lowering with no load."""
    return held([(0.5, 5.0), (1.5, 6.3), (1.0, 5.0), (0.25, 3.0), (0.75, 5.0), (1.5, 6.8),
                 (1.0, 5.0), (0.3, 3.0), (0.7, 5.0), (1.5, 6.3), (1.0, 3.5)])


PROFILES = {"paper_multistep": paper_multistep, "holdout_multistep": holdout_multistep,
            "random_steps": random_steps, "manoeuvres": manoeuvres, "sine_sweep": sine_sweep, "dig": dig}


def profile(name: str) -> Callable[[float], dict]:
    """A named profile; raises ValueError listing the known names."""
    if name not in PROFILES:
        raise ValueError(f"unknown experiment {name!r}; known: {', '.join(PROFILES)}")
    return PROFILES[name]()
