"""Friction laws of a cylinder's seals as a test bench measures them (SI units).

A friction test holds a chamber at a gauge pressure ``p`` while a drive moves the rod at
velocity ``v``; a load cell measures the rod force ``F``, which holds the pressure force
``p A_eff`` and the load cell's offset ``F_0`` as well as the friction::

    F_f = F - p A_eff - F_0

Each law below is the paper's Eq. 9 (``load.friction_force``: at rest friction balances
the drive up to the static level, sliding it is the Coulomb level against the motion)
with viscous friction ``K_v v`` and with levels of its own, each level separate for the
two directions (``_pos`` for v > 0, ``_neg`` for v < 0, magnitudes >= 0):

- ``eq9``: constant static ``F_s`` and Coulomb ``F_d`` levels;
- ``stribeck``: the sliding level falls from the static level to the Coulomb level as
  the speed rises, ``F_d + (F_s - F_d) exp(-|v| / v_s)`` (``effects.stribeck_level``,
  the form of the model's ``stribeck_friction``);
- ``pressure``: the levels grow with the chamber pressure,
  ``F_d(p) = F_d0 + c_d p`` and ``F_s(p) = F_s0 + c_s p``, ``p`` gauge.

The bench fits them (``boomfmi.bench.friction``); the model's effects use the forms
they choose.
"""
from __future__ import annotations

from . import _xp as xp
from .load import friction_force
from .params import Load


def measured_friction(F, p, A_eff, F_0):
    """The friction F_f [N] in a rod force ``F`` [N] measured at gauge pressure ``p``
    [Pa]: ``F - p A_eff - F_0`` (effective area ``A_eff`` [m^2], load-cell offset
    ``F_0`` [N]); positive where it pushes like the pressure."""
    return F - p * A_eff - F_0


def directional(v, pos, neg):
    """A parameter with a value for each direction: ``pos`` where v > 0, ``neg`` where
    v < 0 (and where v = 0)."""
    return xp.where(v > 0, pos, neg)


def seal_friction(v, F_drive, F_s_pos, F_s_neg, F_d_pos, F_d_neg, K_v_pos, K_v_neg):
    """Eq. 9 with a level for each direction, plus viscous friction: the friction [N]
    (positive along +v) on a rod at velocity ``v`` [m/s] (exactly 0: at rest) under the
    drive ``F_drive`` [N] that friction must balance at rest.

    At rest with ``-F_s_neg <= F_drive <= F_s_pos`` it balances the drive; otherwise it
    is the Coulomb level of the direction of motion (of the drive at breakaway), and
    ``K_v v`` with the direction's ``K_v`` [N s/m] adds while sliding.  Levels may be
    arrays (a level per sample: :func:`pressure_level`, ``effects.stribeck_level``)."""
    up = (v > 0) | ((v == 0) & (F_drive > 0))
    pos = friction_force(v, F_drive, 0.0, Load(K_v=K_v_pos, F_s=F_s_pos, F_d=F_d_pos))
    neg = friction_force(v, F_drive, 0.0, Load(K_v=K_v_neg, F_s=F_s_neg, F_d=F_d_neg))
    return xp.where(up, pos, neg) + directional(v, K_v_pos, K_v_neg) * v


def pressure_level(p, level_0, c):
    """A friction level [N] growing with the gauge pressure ``p`` [Pa]: ``level_0 + c p``,
    ``level_0`` [N] at atmospheric pressure, ``c`` [N/Pa] (an effective area: the seal's
    contact band times its friction coefficient)."""
    return level_0 + c * p


__all__ = ["measured_friction", "directional", "seal_friction", "pressure_level"]
