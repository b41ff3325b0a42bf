"""Named command profiles: what the operator (or a test script) sends to the valve.

Each profile is a function of time returning the system inputs ``{"u": volts}``.
``paper_multistep`` is the paper's identification experiment (reference-rig.md):
three periods, each starting with u = 10 V until the piston rests at x = 0, then
u = U_i for the rest of the period, U = 1, 2.5, 4 V.
"""
from __future__ import annotations

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
            "random_steps": random_steps, "dig": dig}


def profile(name: str) -> Callable[[float], dict]:
    """A named profile; raises ValueError listing the known names."""
    if name not in PROFILES:
        raise ValueError(f"unknown experiment {name!r}; known: {', '.join(PROFILES)}")
    return PROFILES[name]()
