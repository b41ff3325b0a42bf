"""Named command profiles: what the operator (or a test script) sends to the valve.

Each profile is a function of time returning the system inputs ``{"u": volts}`` (the
excavator's, at the end: ``{"u_swing": ..., "u_boom": ..., "u_arm": ..., "u_bucket": ...}``).
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


def slow_ramps(seed: int = 0, duration: float = 12.0, depth=(0.4, 1.6), hold=(0.0, 0.0),
               step: float | None = None) -> Callable[[float], dict]:
    """Slow triangles of the command around the centre, the way an operator eases a boom:
    alternately each side, ``depth`` [V] from 5 V (drawn per triangle), 0.4 to 1.25 s
    each way, the peak held for ``hold`` [s] (drawn; (0, 0): none).  ``step`` [s]: the
    command as a staircase of that period (a joystick sampled by a controller); None:
    continuous."""
    rng = np.random.default_rng(seed)
    knots_t, knots_u, t, side = [0.0], [5.0], 0.0, 1.0
    while t < duration:
        side = -side
        peak = 5.0 + side * float(rng.uniform(*depth))
        for dt_, u in ((rng.uniform(0.4, 1.25), peak), (rng.uniform(*hold), peak), (rng.uniform(0.4, 1.25), 5.0)):
            t += float(dt_)
            knots_t.append(t)
            knots_u.append(u)

    def profile(t: float) -> dict:
        if step:
            t = math.floor(t / step) * step
        return {"u": float(np.interp(t, knots_t, knots_u))}
    profile.duration = duration
    profile.breakpoints = ([float(s) for s in np.arange(step, duration, step)] if step else
                           [k for k in knots_t[1:] if k < duration])
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


#: Feedback taps of the maximum-length linear feedback shift registers by register
#: length n (x^n + x^m + 1, the XOR of bits n and m): a sequence of period 2^n - 1.
MLS_TAPS = {5: 3, 6: 5, 7: 6, 9: 5, 10: 7, 11: 9}


def mls(n: int = 9, seed: int = 1) -> np.ndarray:
    """One period (2^n - 1 bits, 0 or 1) of the maximum-length sequence of the n-bit
    Fibonacci shift register of :data:`MLS_TAPS`, started from the non-zero state
    ``seed`` mod (2^n - 1) + 1.  Balanced (2^(n-1) ones) with a two-valued circular
    autocorrelation: the pseudo-random binary sequence (PRBS) of system identification."""
    if n not in MLS_TAPS:
        raise ValueError(f"no maximum-length taps for a {n!r}-bit register; known: {', '.join(map(str, MLS_TAPS))}")
    m, period = MLS_TAPS[n], 2 ** n - 1
    state = [(int(seed) % period + 1) >> i & 1 for i in range(n)]
    out = np.empty(period, dtype=int)
    for k in range(period):
        out[k] = state[-1]
        bit = state[n - 1] ^ state[m - 1]
        state = [bit] + state[:-1]
    return out


def pseudo_random_steps(seed: int = 0, duration: float = 12.0, clock: float = 0.12, levels: int = 2,
                        amplitude=(1.2, 3.0), n: int = 9) -> Callable[[float], dict]:
    """Pseudo-random steps of the command around the centre, switching only at multiples
    of ``clock`` [s] (the sequence's clock; 0.12 s: a flat spectrum up to ~0.4 / clock =
    3.3 Hz).  ``levels = 2``: a pseudo-random binary sequence (PRBS), u = 5 - a [V] for a
    1 bit (extending) and 5 + a for a 0 bit (retracting), the bits the n-bit maximum-length
    sequence of :func:`mls` from a start drawn from ``seed``; ``levels > 2``: a
    pseudo-random multi-level sequence, each clock period one of ``levels`` commands
    evenly spaced over 5 - a .. 5 + a drawn from ``seed``.  The amplitude a [V] is drawn
    per design from ``amplitude`` (within 0 .. 5 V, so that u stays within 0 .. 10 V)."""
    if not clock > 0:
        raise ValueError(f"clock is the sequence's period [s]: > 0, not {clock!r}")
    if int(levels) != levels or levels < 2:
        raise ValueError(f"levels is a whole number >= 2, not {levels!r}")
    lo_a, hi_a = (float(a) for a in amplitude)
    if not 0.0 < lo_a <= hi_a <= 5.0:
        raise ValueError(f"amplitude [V] is a range within (0, 5], not {amplitude!r}")
    rng = np.random.default_rng(seed)
    amp = float(rng.uniform(lo_a, hi_a))
    count = int(math.ceil(duration / clock))
    if levels == 2:
        bits = mls(n, int(rng.integers(2 ** n - 1)))
        values = np.where(np.resize(bits, count) == 1, 5.0 - amp, 5.0 + amp)
    else:
        values = 5.0 + amp * np.linspace(-1.0, 1.0, int(levels))[rng.integers(int(levels), size=count)]
    values = [float(v) for v in values]

    def profile(t: float) -> dict:
        return {"u": values[min(max(int(t / clock + 1e-9), 0), count - 1)]}
    profile.duration = duration
    profile.breakpoints = [k * clock for k in range(1, count) if values[k] != values[k - 1]]
    profile.amplitude = amp
    return profile


def joystick(seed: int = 0, duration: float = 12.0, bandwidth=(0.4, 1.2), step: float = 0.02,
             gain: float = 0.9, held=(0.6, 2.5), released=(0.3, 1.2), tau_return: float = 0.08,
             detent: float = 0.03) -> Callable[[float], dict]:
    """An operator on a spring-centred joystick, sampled by the machine's controller every
    ``step`` [s] (the command a staircase of that period): the hand's motion is white
    noise through a critically damped second-order low-pass of corner f_c [Hz] (drawn per
    design from ``bandwidth``), scaled so that its deflection's standard deviation is 0.7
    of full travel, then held at the stick's mechanical stops (+-1, saturation).  The
    operator holds the stick for ``held`` [s] and lets it go for ``released`` [s] (each
    drawn), and while released the stick's spring returns it to centre with time constant
    ``tau_return`` [s] (and the hand, taking it again, joins it over ~0.15 s); within
    ``detent`` of centre it rests in its detent (exactly 5 V).
    u = 5 - 5 ``gain`` deflection [V] (a deflection forward extends the cylinder), within
    5 -+ 5 ``gain``, so within 0 .. 10 V for gain <= 1."""
    if not step > 0 or not 0.0 < gain <= 1.0 or not tau_return > 0 or not 0.0 <= detent < 1.0:
        raise ValueError(f"joystick needs step > 0 s, 0 < gain <= 1, tau_return > 0 s and 0 <= detent < 1; "
                         f"got step={step!r}, gain={gain!r}, tau_return={tau_return!r}, detent={detent!r}")
    rng = np.random.default_rng(seed)
    f_c = float(rng.uniform(*bandwidth))
    count = int(math.ceil(duration / step)) + 1
    w = 2.0 * math.pi * f_c
    # the hand: white noise through two first-order stages of corner f_c (critically damped)
    a = math.exp(-w * step)
    noise = rng.standard_normal(count)
    y1 = np.empty(count)
    y2 = np.empty(count)
    s1 = s2 = 0.0
    for k in range(count):
        s1 = a * s1 + (1.0 - a) * noise[k]
        s2 = a * s2 + (1.0 - a) * s1
        y1[k], y2[k] = s1, s2
    hand = 0.7 * y2 / (float(np.std(y2)) or 1.0)
    # holding and letting go: the stick follows the hand while held, its spring otherwise
    grip = np.zeros(count, dtype=bool)
    t, on = 0.0, True
    while t < duration + step:
        dt_ = float(rng.uniform(*(held if on else released)))
        grip[int(t / step):int((t + dt_) / step) + 1] = on
        t, on = t + dt_, not on
    r = math.exp(-step / tau_return)
    stick = np.empty(count)
    s, since = 0.0, 0
    for k in range(count):
        if grip[k]:          # the hand takes the stick from where it is, over ~0.15 s
            since += 1
            g = 1.0 - math.exp(-since * step / 0.15)
            s = (1.0 - g) * s + g * float(np.clip(hand[k], -1.0, 1.0))
        else:
            since, s = 0, r * s
        stick[k] = 0.0 if abs(s) < detent else s
    values = [float(5.0 - 5.0 * gain * v) for v in stick]

    def profile(t: float) -> dict:
        return {"u": values[min(max(int(t / step + 1e-9), 0), count - 1)]}
    profile.duration = duration
    profile.breakpoints = [k * step for k in range(1, count) if k * step < duration and values[k] != values[k - 1]]
    profile.bandwidth = f_c
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
            "random_steps": random_steps, "slow_ramps": slow_ramps, "manoeuvres": manoeuvres,
            "sine_sweep": sine_sweep, "dig": dig}


def profile(name: str) -> Callable[[float], dict]:
    """A named profile, or a command CSV (a name ending in ``.csv``: :func:`command_file`);
    raises ValueError listing the known names."""
    if name not in PROFILES and str(name).lower().endswith(".csv"):
        return command_file(name)
    if name not in PROFILES:
        raise ValueError(f"unknown experiment {name!r}; known: {', '.join(PROFILES)} or a command CSV (t, u)")
    return PROFILES[name]()


#: a command CSV's columns: time [s] from 0, command [V] (``diagnose --propose`` writes one)
COMMAND_COLUMNS = ("t", "u")


def is_command_file(path) -> bool:
    """Whether ``path`` is a command CSV (its header exactly ``t,u``), not a recording."""
    try:
        with open(path, newline="") as f:
            header = f.readline()
    except OSError:
        return False
    return [c.strip() for c in header.strip().split(",")] == list(COMMAND_COLUMNS)


def command_samples(prof: Callable[[float], dict], dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """A profile sampled as the DAQ sends it: times ``0, dt, ...`` up to its duration and
    the command ``u`` [V] at each (held until the next sample)."""
    t = np.round(np.arange(int(round(prof.duration / dt)) + 1) * dt, 9)
    return t, np.array([float(prof(float(s))["u"]) for s in t])


def command_file(path) -> Callable[[float], dict]:
    """A command CSV (header ``t,u``: time [s] from 0, strictly rising; command [V],
    0 to 10) as a profile: each sample's command held until the next (as the rig's output
    card holds it), the last to the end.  Errors name the file, line and column."""
    import csv
    where = str(path)
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        raise ValueError(f"{where}: cannot read the command CSV: {e.strerror or e}") from None
    if not rows or [c.strip() for c in rows[0]][:2] != list(COMMAND_COLUMNS):
        raise ValueError(f"{where}, line 1: a command CSV starts with the header "
                         f"{','.join(COMMAND_COLUMNS)} (time [s], command [V])")
    times, levels = [], []
    for line, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        for col, text in zip(COMMAND_COLUMNS, (row + ["", ""])[:2]):
            try:
                v = float(text)
            except ValueError:
                raise ValueError(f"{where}, line {line}, column {col!r}: {text!r} is not a number") from None
            if not math.isfinite(v):
                raise ValueError(f"{where}, line {line}, column {col!r}: {text!r} is not finite")
            (times if col == "t" else levels).append(v)
        if not 0.0 <= levels[-1] <= 10.0:
            raise ValueError(f"{where}, line {line}, column 'u': {levels[-1]:g} V is outside the valve's 0 to 10 V")
        if len(times) == 1 and times[0] != 0.0:
            raise ValueError(f"{where}, line {line}, column 't': the command starts at t = 0, not {times[0]:g} s")
        if len(times) > 1 and times[-1] <= times[-2]:
            raise ValueError(f"{where}, line {line}, column 't': {times[-1]:g} s does not follow "
                             f"{times[-2]:g} s (times rise strictly)")
    if len(times) < 2:
        raise ValueError(f"{where}: a command CSV needs at least two samples")
    t_arr, u_arr = np.asarray(times), np.asarray(levels)

    def prof(t: float) -> dict:
        return {"u": float(u_arr[max(0, int(np.searchsorted(t_arr, t + 1e-9, side="right")) - 1)])}
    prof.duration = float(t_arr[-1])
    prof.breakpoints = [float(s) for s, d in zip(t_arr[1:], np.diff(u_arr)) if d != 0.0]
    return prof


# -- the whole excavator (shared/spec/excavator.md) ---------------------------------------------
#: The excavator's joints, each with its own valve: the commands are ``u_<joint>`` [V]
#: (the linkage's ``physics.linkage.JOINTS``; the recording's ``recording.JOINTS``).
JOINTS = ("swing", "boom", "arm", "bucket")
#: The valve's centre [V]: the spool closes both ports (reference-rig.md).
CENTRE = 5.0


def held_joints(segments) -> Callable[[float], dict]:
    """Commands to the four valves held over consecutive segments: ``[(duration [s],
    {joint: u [V], ...}), ...]``; a joint a segment leaves out is held at the centre
    (5 V).  Returns ``{"u_swing": V, "u_boom": V, "u_arm": V, "u_bucket": V}``."""
    segments = [(float(d), dict(us)) for d, us in segments]
    for d, us in segments:
        unknown = set(us) - set(JOINTS)
        if unknown:
            raise ValueError(f"unknown joint {sorted(unknown)[0]!r}; the excavator's joints are {', '.join(JOINTS)}")
        if not d > 0:
            raise ValueError(f"a segment lasts more than 0 s, not {d!r}")
        for j, u in us.items():
            if not 0.0 <= u <= 10.0:
                raise ValueError(f"u_{j} = {u!r} V lies outside 0 to 10 V")
    starts = np.concatenate(([0.0], np.cumsum([d for d, _ in segments])[:-1]))
    levels = [{f"u_{j}": float(us.get(j, CENTRE)) for j in JOINTS} for _, us in segments]

    def profile(t: float) -> dict:
        return dict(levels[max(0, int(np.searchsorted(starts, t, side="right")) - 1)])
    profile.duration = float(sum(d for d, _ in segments))
    profile.breakpoints = [float(s) for s in starts[1:]]
    return profile


#: The digging cycle's phases: (name, duration [s], {joint: offset from the centre [V]}).
#: A negative offset (u below 5 V) extends the joint's cylinder, a positive one retracts
#: it (the MPYE's routing, reference-rig.md).  Extending the swing cylinder turns the
#: upper structure to the trench, retracting the boom's lowers the boom (as in
#: :func:`dig`), extending the arm's pulls the arm in and extending the bucket's curls
#: the bucket.
DIG_CYCLE = (
    ("rest", 0.5, {}),
    ("swing to the trench", 1.5, {"swing": -2.0}),
    ("boom down", 1.5, {"boom": +1.5}),
    ("arm in", 1.5, {"arm": -2.0, "boom": +0.5}),
    ("bucket curl", 1.0, {"bucket": -2.0}),
    ("lift", 1.5, {"boom": -2.5}),
    ("swing back", 1.5, {"swing": +2.0}),
    ("dump", 1.0, {"bucket": +2.5, "arm": +1.5}),
    ("rest", 0.5, {}),
)


def digging_cycle(level: float = 1.0, pace: float = 1.0) -> Callable[[float], dict]:
    """The excavator's digging cycle (:data:`DIG_CYCLE`, 10.5 s): swing to the trench,
    boom down, arm in (the boom following a little), bucket curl, lift, swing back and
    dump (bucket open, arm out), from rest and back to rest at the valves' centre.
    ``level`` scales every opening (1: 1.5 to 2.5 V from the centre), ``pace`` every
    duration (2: twice as long).  Returns ``{"u_<joint>": V}`` for the four joints, with
    ``.duration``, ``.breakpoints`` and ``.phases`` (name, start, stop [s])."""
    if not 0.0 < level <= 2.0:
        raise ValueError(f"level scales the openings: in (0, 2], not {level!r}")
    if not pace > 0.0:
        raise ValueError(f"pace scales the durations: > 0, not {pace!r}")
    segments = [(d * pace, {j: CENTRE + level * off for j, off in offs.items()}) for _, d, offs in DIG_CYCLE]
    profile = held_joints(segments)
    starts = [0.0, *np.cumsum([d * pace for _, d, _ in DIG_CYCLE])]
    profile.phases = [(name, float(starts[i]), float(starts[i + 1])) for i, (name, _, _) in enumerate(DIG_CYCLE)]
    return profile


def per_joint(profiles: dict) -> Callable[[float], dict]:
    """Four boom-style profiles (``{"u": V}`` each) as one excavator profile: ``profiles``
    maps each joint to its own; the duration is the shortest, the breakpoints all of
    theirs."""
    if set(profiles) != set(JOINTS):
        raise ValueError(f"per_joint wants one profile for each of {', '.join(JOINTS)}, got {', '.join(profiles)}")
    items = [(j, profiles[j]) for j in JOINTS]

    def profile(t: float) -> dict:
        return {f"u_{j}": p(t)["u"] for j, p in items}
    profile.duration = float(min(p.duration for _, p in items))
    profile.breakpoints = sorted({b for _, p in items for b in getattr(p, "breakpoints", ())
                                  if b < profile.duration})
    return profile


def _joint_seeds(seed: int) -> list[int]:
    """An independent seed for each joint, drawn from ``seed``."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(len(JOINTS))]


def excavator_random_steps(seed: int = 0, duration: float = 20.0) -> Callable[[float], dict]:
    """:func:`random_steps` on each of the four valves, each joint drawn from its own
    seed (spawned from ``seed``), so that the joints start, reverse and stop at
    different times: breakaways and accelerations of each joint while the others move
    or rest, for identification per joint."""
    return per_joint({j: random_steps(s, duration) for j, s in zip(JOINTS, _joint_seeds(seed))})


def excavator_manoeuvres(seed: int = 0, duration: float = 20.0) -> Callable[[float], dict]:
    """:func:`manoeuvres` on each of the four valves, each joint from its own seed: runs
    into both ends, holds at exactly 5 V, reversals and a chirp, per joint, at
    independent times."""
    return per_joint({j: manoeuvres(s, duration) for j, s in zip(JOINTS, _joint_seeds(seed))})


def excavator_excitation(seed: int = 0, duration: float = 24.0, hold=(0.08, 0.35),
                         opening=(0.04, 4.5), reverse: float = 0.85) -> Callable[[float], dict]:
    """The richer excitation for identifying each joint: blocks of 1.5 to 3 s in which
    one or two joints (drawn from ``seed``, every joint in turn at least once in each
    round of four blocks) take short steps (``hold`` seconds) while the others rest at
    the centre, every joint at rest between blocks.

    A step opens the valve by an offset drawn log-uniform over ``opening`` [V] from the
    centre (15 % of steps are exactly at the centre, 5 V) and reverses the previous
    step's direction with probability ``reverse``.  Short steps that mostly reverse
    keep a fast light joint (the bucket crosses its 50 mm stroke in half a second) in
    mid-stroke instead of on its stops; the small openings make it slide slowly, where
    the flow rather than the viscous friction sets the speed, so that K_v and F_d are
    seen at many speeds rather than at one (at one speed only K_v v + F_d is); each
    reversal and each step from the centre is a start from rest for F_s.  A joint
    moving alone separates its own friction and mass from the others'; two together
    excite the linkage's coupling."""
    rng = np.random.default_rng(seed)
    lo, hi = math.log(opening[0]), math.log(opening[1])
    segments, t = [], 0.0
    while t < duration:
        for lead in rng.permutation(len(JOINTS)):
            if t >= duration:
                break
            moving = {JOINTS[int(lead)]}
            if rng.random() < 0.4:
                moving.add(JOINTS[int(rng.integers(len(JOINTS)))])
            block_end = t + float(rng.uniform(1.5, 3.0))
            sign = {j: float(rng.choice([-1.0, 1.0])) for j in sorted(moving)}
            while t < block_end:
                d = float(rng.uniform(*hold))
                us = {}
                for j in sorted(moving):
                    if rng.random() < 0.15:
                        us[j] = CENTRE
                        continue
                    if rng.random() < reverse:
                        sign[j] = -sign[j]
                    us[j] = CENTRE + sign[j] * math.exp(rng.uniform(lo, hi))
                segments.append((d, us))
                t += d
            d = float(rng.uniform(0.2, 0.4))               # every joint at rest between blocks
            segments.append((d, {}))
            t += d
    profile = held_joints(segments)
    profile.duration = float(duration)
    profile.breakpoints = [b for b in profile.breakpoints if b < duration]
    return profile


# -- contact scenarios of the bucket's tip -----------------------------------------------------
class TipContact:
    """A contact scenario with a known force on the bucket's tip [N, world frame, z up,
    the force the environment exerts on the bucket], as the recordings' ``f_tip_x/y/z``.

    ``kind`` is ``"ground"`` or ``"prescribed"``:

    * ground: soil whose surface is the horizontal plane ``z = ground_z`` [m]; below it
      the soil pushes the tip up, ``f_z = stiffness * (ground_z - z) + damping *
      max(-v_z, 0)`` (never pulling, 0 above the surface), and drags it against its
      horizontal velocity, ``f_xy = -friction * f_z * v_xy / max(|v_xy|, v_slip)``
      (``v_slip`` [m/s] regularises the drag near rest);
    * prescribed: the force is given whatever the tip does: ``force`` [N] (x, y, z)
      from ``start`` to ``stop`` [s], reached linearly over ``ramp`` [s] and released
      as fast (a load cell's scenario; no motion needed to know it).

    :meth:`force` evaluates it; :meth:`config` is the description a rig's configuration
    carries (plain JSON numbers)."""

    KINDS = ("ground", "prescribed")

    def __init__(self, name: str, kind: str, *, ground_z: float = 0.0, stiffness: float = 0.0,
                 damping: float = 0.0, friction: float = 0.0, v_slip: float = 0.01,
                 force=(0.0, 0.0, 0.0), start: float = 0.0, stop: float = math.inf, ramp: float = 0.0):
        if kind not in self.KINDS:
            raise ValueError(f"contact {name!r}: kind must be one of {', '.join(self.KINDS)}, not {kind!r}")
        values = {"ground_z": ground_z, "stiffness": stiffness, "damping": damping, "friction": friction,
                  "v_slip": v_slip, "start": start, "ramp": ramp}
        for k, v in values.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"contact {name!r}: {k} must be a finite number, not {v!r}")
        for k in ("stiffness", "damping", "friction", "ramp"):
            if values[k] < 0:
                raise ValueError(f"contact {name!r}: {k} must be >= 0, not {values[k]!r}")
        if not v_slip > 0:
            raise ValueError(f"contact {name!r}: v_slip must be > 0 m/s, not {v_slip!r}")
        force = tuple(float(f) for f in force)
        if len(force) != 3 or not all(math.isfinite(f) for f in force):
            raise ValueError(f"contact {name!r}: force must be three finite numbers [N], not {force!r}")
        if not stop > start:
            raise ValueError(f"contact {name!r}: stop ({stop!r} s) must come after start ({start!r} s)")
        if kind == "ground" and stiffness <= 0:
            raise ValueError(f"contact {name!r}: the ground needs a stiffness > 0 N/m")
        self.name, self.kind = name, kind
        self.ground_z, self.stiffness, self.damping = float(ground_z), float(stiffness), float(damping)
        self.friction, self.v_slip = float(friction), float(v_slip)
        self.f, self.start, self.stop, self.ramp = force, float(start), float(stop), float(ramp)

    def force(self, t: float, tip, tip_velocity=(0.0, 0.0, 0.0)) -> np.ndarray:
        """The force on the tip [N] (x, y, z) at time ``t`` [s], the tip at ``tip`` [m]
        moving at ``tip_velocity`` [m/s], both in the world frame."""
        if self.kind == "prescribed":
            if t < self.start or t > self.stop:
                return np.zeros(3)
            if self.ramp > 0:
                w = min(1.0, (t - self.start) / self.ramp, (self.stop - t) / self.ramp)
            else:
                w = 1.0
            return w * np.asarray(self.f)
        z, v = float(tip[2]), np.asarray(tip_velocity, float)
        depth = self.ground_z - z
        if depth <= 0:
            return np.zeros(3)
        fz = max(0.0, self.stiffness * depth + self.damping * max(-float(v[2]), 0.0))
        vxy = v[:2]
        drag = -self.friction * fz * vxy / max(float(np.hypot(*vxy)), self.v_slip)
        return np.array([drag[0], drag[1], fz])

    def config(self) -> dict:
        """The scenario as plain JSON values: a rig configuration's tip contact."""
        if self.kind == "ground":
            return {"type": "ground", "ground_z": self.ground_z, "stiffness": self.stiffness,
                    "damping": self.damping, "friction": self.friction, "v_slip": self.v_slip}
        return {"type": "prescribed", "force": list(self.f), "start": self.start,
                "stop": None if math.isinf(self.stop) else self.stop, "ramp": self.ramp}

    def __repr__(self) -> str:
        return f"TipContact({self.name!r}, {self.config()})"


#: The excavator's contact scenarios, each meant for :func:`digging_cycle`.  The soils'
#: surface is the ground plane (z = 0, the boom pivot 0.20 m above it): from a mid-stroke
#: posture the tip comes down into it while the boom goes down and the arm comes in
#: (some 7 cm deep if nothing stopped it), where the cylinders' few tens of newtons at
#: the tip meet the soil some 2 cm (soft) or 2 mm (hard) deep.  The prescribed push
#: acts up and back on the tip for 4 s of the cycle's dig, as a load cell would
#: measure it, whatever the tip does.
CONTACTS = {
    "soft_soil": lambda: TipContact("soft_soil", "ground", ground_z=0.0, stiffness=1500.0, damping=100.0,
                                    friction=0.3),
    "hard_soil": lambda: TipContact("hard_soil", "ground", ground_z=0.0, stiffness=15000.0, damping=500.0,
                                    friction=0.5),
    "prescribed_push": lambda: TipContact("prescribed_push", "prescribed", force=(-15.0, 5.0, 25.0),
                                          start=3.5, stop=7.5, ramp=0.5),
    # a load cell's push on the tip held mid-workspace (:func:`closed_loop_hold`)
    "mid_push": lambda: TipContact("mid_push", "prescribed", force=(-15.0, 5.0, 25.0), start=2.0, stop=8.5,
                                   ramp=0.5),
}


def contact(name: str) -> TipContact:
    """A named contact scenario of :data:`CONTACTS`; ValueError listing the known names."""
    if name not in CONTACTS:
        raise ValueError(f"unknown contact scenario {name!r}; known: {', '.join(CONTACTS)}")
    return CONTACTS[name]()


# -- closed-loop experiments: an operator (or an automatic bucket controller) on the angles ----
class JointTrajectoryController:
    """A joint controller that is part of the experiment, as an operator or an automatic
    bucket controller is (not part of any estimator): per joint a PI on the measured
    joint angle against a trajectory in joint space, with damping on the angle's rate,
    its output the valve command ``u = 5 - (kp e + ki int e - kd w)`` [V] clipped to
    0 .. 10 V, ``e = q_ref - q`` [rad], ``w`` [rad/s] the measured angle's rate through
    a first-order filter of ``tau_d`` [s] (the angle sensor's steps are not motion)
    (a command below the centre extends the cylinder, which raises every joint's angle
    of the linkage).  ``waypoints``: ``[(t [s], (swing, boom, arm, bucket) [rad]), ...]``
    from t = 0, joined linearly (the joints keep moving through a waypoint unless their
    direction turns there); after the last the reference holds.  ``kp`` [V/rad] and
    ``ki`` [V/(rad s)], ``kd`` [V s/rad] per joint or one for all; the integral term is held within
    +-``i_max`` [V] (no wind-up against the ground).

    Call it as ``controller(t, angles)`` with the sample measured at ``t``, in time order
    (:func:`boomfmi.rig.run_excavator_offline` does, for a profile whose
    ``closed_loop`` is true); called without ``angles`` (an open-loop runner: the rig
    server, the hardware bridge, an SSP's simulation) it raises ValueError rather than
    hold the valves at the centre unseen.  :meth:`reset` restarts the integrators."""

    closed_loop = True

    def __init__(self, waypoints, duration: float | None = None, kp=30.0, ki=60.0, kd=0.0, i_max: float = 2.0,
                 tau_d: float = 0.03):
        pts = [(float(t), tuple(float(a) for a in q)) for t, q in waypoints]
        if len(pts) < 2:
            raise ValueError("a trajectory needs at least two waypoints")
        if pts[0][0] != 0.0:
            raise ValueError(f"the trajectory's first waypoint is at t = 0 s, not {pts[0][0]!r}")
        for (t0, _), (t1, q) in zip(pts, pts[1:]):
            if not t1 > t0:
                raise ValueError(f"waypoint times must increase: {t1!r} s after {t0!r} s")
        for t, q in pts:
            if len(q) != len(JOINTS) or not all(math.isfinite(a) for a in q):
                raise ValueError(f"the waypoint at {t!r} s needs {len(JOINTS)} finite angles [rad] "
                                 f"({', '.join(JOINTS)}), not {q!r}")
        self.times = np.array([t for t, _ in pts])
        self.angles = np.array([q for _, q in pts])
        self.kp = np.broadcast_to(np.asarray(kp, float), (len(JOINTS),)).copy()
        self.ki = np.broadcast_to(np.asarray(ki, float), (len(JOINTS),)).copy()
        self.kd = np.broadcast_to(np.asarray(kd, float), (len(JOINTS),)).copy()
        if np.any(self.kp < 0) or np.any(self.ki < 0) or np.any(self.kd < 0) or not i_max >= 0:
            raise ValueError("the controller's gains and i_max must be >= 0")
        if not tau_d > 0:
            raise ValueError(f"tau_d must be > 0 s, not {tau_d!r}")
        self.tau_d = float(tau_d)
        self.i_max = float(i_max)
        self.duration = float(self.times[-1] if duration is None else duration)
        self.breakpoints = [float(t) for t in self.times[1:] if t < self.duration]
        self.reset()

    def reset(self) -> None:
        self._integral = np.zeros(len(JOINTS))
        self._t = None
        self._q = None
        self._rate = np.zeros(len(JOINTS))

    def reference(self, t: float) -> np.ndarray:
        """The trajectory's joint angles [rad] at ``t`` [s]."""
        return np.array([np.interp(t, self.times, self.angles[:, i]) for i in range(len(JOINTS))])

    def __call__(self, t: float, angles=None) -> dict:
        if angles is None:
            raise ValueError("a closed-loop profile needs the measured joint angles at each call, "
                             "command(t, angles): run it with boomfmi.rig.run_excavator_offline")
        q = np.asarray(angles, float)
        e = self.reference(t) - q
        if self._t is not None and t > self._t:
            dt = t - self._t
            self._integral = np.clip(self._integral + self.ki * e * dt, -self.i_max, self.i_max)
            self._rate += (dt / (self.tau_d + dt)) * ((q - self._q) / dt - self._rate)
        self._t, self._q = t, q
        u = np.clip(CENTRE - (self.kp * e + self._integral - self.kd * self._rate), 0.0, 10.0)
        return {f"u_{j}": float(c) for j, c in zip(JOINTS, u)}


#: The operator's gains (kp [V/rad], ki [V/(rad s)], kd [V s/rad]) per joint (swing,
#: boom, arm, bucket): the upper structure's inertia on the swing's short crank wants a
#: softer, damped loop (with the boom's gains and no damping it swings through its
#: reference by 0.2 rad onto its stop).
OPERATOR_GAINS = ((6.0, 12.0, 12.0, 12.0), (4.0, 12.0, 12.0, 12.0), (1.5, 0.3, 0.3, 0.3))
#: The closed-loop dig's trajectory (swing, boom, arm, bucket [rad]; the machine starts
#: at mid-stroke, (0, 0.85, 1.50, 1.05)): turn to the trench while the boom lowers the
#: bucket to the ground plane, then drag the bucket through the soil, the arm pulling
#: in and the bucket curling while the boom's reference holds the tip 2 to 3 cm below
#: the surface and the upper structure keeps turning slowly (a trench along the swing's
#: arc), then lift and turn back.  The swing's reference stays within -0.15 .. +0.15 rad
#: of its +-0.43 rad range; no joint reaches a stop during the contact.
DIG_TRAJECTORY = (
    (0.0, (0.0, 0.85, 1.50, 1.05)),
    (1.5, (-0.10, 0.76, 1.35, 0.90)),
    (2.5, (-0.15, 0.70, 1.40, 0.92)),
    (7.0, (0.10, 0.69, 1.85, 1.32)),
    (8.5, (0.15, 0.90, 1.80, 1.40)),
    (10.0, (0.05, 0.88, 1.60, 1.20)),
)
#: The load-cell push's trajectory: the tip held mid-workspace while every joint slides
#: slowly back and forth around mid-stroke (each at its own pace, so that they seldom
#: stop together), as the machine does when it holds a pose against a push by hand.
PUSH_TRAJECTORY = (
    (0.0, (0.0, 0.85, 1.50, 1.05)),
    (1.0, (-0.12, 0.78, 1.40, 0.95)),
    (2.7, (0.14, 0.92, 1.66, 1.18)),
    (4.1, (-0.10, 0.77, 1.37, 0.92)),
    (5.9, (0.15, 0.93, 1.68, 1.20)),
    (7.4, (-0.14, 0.78, 1.39, 0.93)),
    (9.0, (0.10, 0.91, 1.62, 1.15)),
    (10.0, (0.0, 0.85, 1.50, 1.05)),
)


def closed_loop_dig(boom_raise: float = 0.0) -> JointTrajectoryController:
    """An operator's dig under closed-loop control (:data:`DIG_TRAJECTORY`, 10 s), the
    boom's reference raised by ``boom_raise`` [rad] (0.025: the reference tip 1 to 2 cm
    below the surface instead of 2 to 3 cm, as an operator digs hard ground: deeper asks
    more than the cylinders have and stalls the arm)."""
    pts = [(t, (q[0], q[1] + boom_raise, q[2], q[3])) for t, q in DIG_TRAJECTORY]
    return JointTrajectoryController(pts, kp=OPERATOR_GAINS[0], ki=OPERATOR_GAINS[1], kd=OPERATOR_GAINS[2])


def closed_loop_hold() -> JointTrajectoryController:
    """The tip held mid-workspace, every joint sliding slowly (:data:`PUSH_TRAJECTORY`, 10 s)."""
    return JointTrajectoryController(PUSH_TRAJECTORY, kp=OPERATOR_GAINS[0], ki=OPERATOR_GAINS[1], kd=OPERATOR_GAINS[2])


#: The tip force's benchmark scenarios: name -> (contact scenario, profile).  The first
#: three are the open-loop digging cycle's (the swing on its stop from 1.2 s to 7.5 s,
#: the boom, and in hard soil the bucket, pressed on theirs through most of the contact);
#: the others are what an operator produces: a closed-loop dig through soft and hard
#: soil with the swing off its stops and the joints sliding, and a load cell's push on the
#: tip held mid-workspace by the controller, the joints sliding slowly.
TIP_FORCE_SCENARIOS = {
    "soft_soil": ("soft_soil", digging_cycle),
    "hard_soil": ("hard_soil", digging_cycle),
    "prescribed_push": ("prescribed_push", digging_cycle),
    "closed_loop_soft": ("soft_soil", closed_loop_dig),
    "closed_loop_hard": ("hard_soil", lambda: closed_loop_dig(boom_raise=0.025)),
    "load_cell_push": ("mid_push", closed_loop_hold),
}


def tip_force_scenario(name: str):
    """``(TipContact, profile)`` of a named tip force scenario of :data:`TIP_FORCE_SCENARIOS`;
    ValueError listing the known names."""
    if name not in TIP_FORCE_SCENARIOS:
        raise ValueError(f"unknown tip force scenario {name!r}; known: {', '.join(TIP_FORCE_SCENARIOS)}")
    c, p = TIP_FORCE_SCENARIOS[name]
    return contact(c), p()


EXCAVATOR_PROFILES = {"digging_cycle": digging_cycle, "excavator_random_steps": excavator_random_steps,
                      "excavator_manoeuvres": excavator_manoeuvres, "excavator_excitation": excavator_excitation}


def excavator_profile(name: str) -> Callable[[float], dict]:
    """A named excavator profile (``{"u_<joint>": V}``); ValueError listing the known names."""
    if name not in EXCAVATOR_PROFILES:
        raise ValueError(f"unknown excavator experiment {name!r}; known: {', '.join(EXCAVATOR_PROFILES)}")
    return EXCAVATOR_PROFILES[name]()


__all__ = ["PAPER_LEVELS", "multistep", "paper_multistep", "holdout_multistep", "random_steps", "held", "slow_ramps",
           "manoeuvres", "sine_sweep", "MLS_TAPS", "mls", "pseudo_random_steps", "joystick", "dig", "PROFILES",
           "profile", "COMMAND_COLUMNS", "is_command_file", "command_samples", "command_file", "JOINTS", "CENTRE", "held_joints", "DIG_CYCLE",
           "digging_cycle", "per_joint", "excavator_random_steps", "excavator_manoeuvres", "excavator_excitation",
           "TipContact", "CONTACTS", "contact", "JointTrajectoryController", "OPERATOR_GAINS", "DIG_TRAJECTORY",
           "PUSH_TRAJECTORY", "closed_loop_dig", "closed_loop_hold", "TIP_FORCE_SCENARIOS", "tip_force_scenario",
           "EXCAVATOR_PROFILES", "excavator_profile"]
