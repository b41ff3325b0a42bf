"""Boom geometry: cylinder length, the cylinder's angle phi and the boom angle alpha
(the paper's Eq. 10 to 12).

The paper's Eq. 12 prints ``cos(a)``; the boom angle alpha is meant.
"""
from __future__ import annotations

import math

from . import _xp as xp
from .params import Geometry
from .validation import ParameterError, require_non_negative, require_positive


def cylinder_length(x, geom: Geometry = Geometry()):
    """Cylinder length l = x + l_min [m] (Eq. 11)."""
    return x + geom.l_min


def phi_from_x(x, geom: Geometry = Geometry()):
    """Angle phi [rad] between the cylinder axis and the horizontal (Eq. 10)::

        phi = pi - arcsin(h/a) - arccos((a^2 + l^2 - b^2) / (2 a l))
    """
    a, b, h, _ = geom
    l = cylinder_length(x, geom)
    return math.pi - math.asin(h / a) - xp.arccos((a * a + l * l - b * b) / (2.0 * a * l))


def alpha_from_x(x, geom: Geometry = Geometry()):
    """Boom angle alpha [rad] at piston position ``x`` [m] (Eq. 12 solved for alpha)::

        alpha = arccos((a^2 + b^2 - l^2) / (2 a b))
    """
    a, b, _, _ = geom
    l = cylinder_length(x, geom)
    return xp.arccos((a * a + b * b - l * l) / (2.0 * a * b))


def x_from_alpha(alpha, geom: Geometry = Geometry()):
    """Piston position x [m] from the boom angle ``alpha`` [rad] (Eq. 12)::

        x = sqrt(a^2 + b^2 - 2 a b cos(alpha)) - l_min
    """
    a, b, _, l_min = geom
    return xp.sqrt(a * a + b * b - 2.0 * a * b * xp.cos(alpha)) - l_min


def check_geometry(geom: Geometry, L: float) -> None:
    """Raise :class:`ParameterError` unless Eq. 10 to 12 are defined over the stroke.

    Needs a, b, l_min > 0, 0 <= h <= a (so arcsin(h/a) exists) and a triangle with
    sides a, b, l for every l in [l_min, l_min + L] (|a - b| <= l <= a + b), so that
    both arccos arguments lie in [-1, 1].
    """
    a, b, h, l_min = geom
    require_positive("a", a)
    require_positive("b", b)
    require_positive("l_min", l_min)
    require_non_negative("h", h)
    if h > a:
        raise ParameterError("h", h, f"must not exceed a = {a:g} m (arcsin(h/a) in Eq. 10)")
    if l_min < abs(a - b):
        raise ParameterError(
            "l_min", l_min,
            f"the cylinder at x = 0 is shorter than |a - b| = {abs(a - b):g} m, so Eq. 10 is undefined")
    if l_min + L > a + b:
        raise ParameterError(
            "l_min", l_min,
            f"the cylinder at x = L is longer than a + b = {a + b:g} m, so Eq. 10 is undefined")


def linkage_points(alpha, geom: Geometry = Geometry()):
    """The linkage's pivots in the boom's plane [m], for drawing it (Eq. 10 to 12).

    The boom pivot O is the origin, x horizontal (away from the machine), y up.  The
    cylinder's base pivot C lies ``a`` from O and ``h`` below it; the rod's pivot R on
    the boom lies ``b`` from O, at the angle ``alpha`` from OC (so |CR| is the cylinder
    length l of Eq. 11 and the cylinder's angle to the horizontal is phi of Eq. 10).
    Returns ``(C, R)`` with C = (C_x, C_y) and R = (R_x, R_y); ``alpha`` [rad] may be
    an array, and then R's coordinates are arrays.
    """
    a, b, h, _ = geom
    beta = math.asin(h / a)                   # OC below the horizontal
    C = (a * math.cos(beta), -h)
    R = (b * xp.cos(alpha - beta), b * xp.sin(alpha - beta))
    return C, R



__all__ = ["cylinder_length", "phi_from_x", "alpha_from_x", "x_from_alpha", "check_geometry", "linkage_points"]
