"""Elementary functions that take a Python float or a NumPy array.

The physics is written once and must serve two callers: an FMU, which steps one
scalar state a thousand times a second (where a NumPy ufunc on a float costs ~1 us
and ``math`` costs ~50 ns), and identification or diagnosis, which evaluate the same
equations on whole arrays of samples or parameter sets.  Each helper here picks
``math`` for a float and NumPy for anything else.
"""
from __future__ import annotations

import math

import numpy as np

SCALARS = (float, int, np.float64)   #: NumPy's float64 scalar (what indexing an array gives) is one too
_BOOLS = (bool, np.bool_)


def sqrt(x):
    return math.sqrt(x) if type(x) in SCALARS else np.sqrt(x)


def exp(x):
    return math.exp(x) if type(x) in SCALARS else np.exp(x)


def cos(x):
    return math.cos(x) if type(x) in SCALARS else np.cos(x)


def sin(x):
    return math.sin(x) if type(x) in SCALARS else np.sin(x)


def arccos(x):
    return math.acos(x) if type(x) in SCALARS else np.arccos(x)


def arcsin(x):
    return math.asin(x) if type(x) in SCALARS else np.arcsin(x)


def maximum(x, y):
    if type(x) in SCALARS and type(y) in SCALARS:
        return x if x >= y else y
    return np.maximum(x, y)


def minimum(x, y):
    if type(x) in SCALARS and type(y) in SCALARS:
        return x if x <= y else y
    return np.minimum(x, y)


def clip(x, lo, hi):
    if type(x) in SCALARS and type(lo) in SCALARS and type(hi) in SCALARS:
        return lo if x < lo else (hi if x > hi else x)
    return np.clip(x, lo, hi)


def where(cond, a, b):
    if type(cond) in _BOOLS:
        return a if cond else b
    return np.where(cond, a, b)


def sign(x):
    if type(x) in SCALARS:
        return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)
    return np.sign(x)


def abs_(x):
    return abs(x) if type(x) in SCALARS else np.abs(x)
