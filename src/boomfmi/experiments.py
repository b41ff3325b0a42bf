"""Named command profiles: what the operator (or a test script) sends to the valve.

Each profile is a function of time returning the system inputs ``{"u": volts}``.
``paper_multistep`` is the paper's identification experiment (reference-rig.md):
three periods, each starting with u = 10 V until the piston rests at x = 0, then
u = U_i for the rest of the period, U = 1, 2.5, 4 V.
"""
from __future__ import annotations

from typing import Callable

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
    return profile


def paper_multistep() -> Callable[[float], dict]:
    """The paper's experiment: 3 periods of 3 s (1 s retracting at 10 V, 2 s at U_i)."""
    return multistep()


PROFILES = {"paper_multistep": paper_multistep}


def profile(name: str) -> Callable[[float], dict]:
    """A named profile; raises ValueError listing the known names."""
    if name not in PROFILES:
        raise ValueError(f"unknown experiment {name!r}; known: {', '.join(PROFILES)}")
    return PROFILES[name]()
