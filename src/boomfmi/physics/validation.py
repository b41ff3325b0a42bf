"""Parameter checks shared by the FMUs, the reference solver and identification.

Each check raises :class:`ParameterError` naming the offending parameter, so an FMU
can turn it into an ``fmi2Error`` with a log message that a user can act on.
"""
from __future__ import annotations

import math


class ParameterError(ValueError):
    """A parameter value the physics cannot use.

    Attributes
    ----------
    name : str
        The parameter's name, as the FMU declares it (for example ``"M"``).
    value : float
        The rejected value.
    """

    def __init__(self, name: str, value, reason: str):
        self.name = name
        self.value = value
        super().__init__(f"parameter {name} = {value!r} is invalid: {reason}")


def require_finite(name: str, value: float) -> None:
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(name, value, "must be a finite number")


def require_positive(name: str, value: float) -> None:
    """Raise unless ``value`` is finite and > 0."""
    require_finite(name, value)
    if value <= 0.0:
        raise ParameterError(name, value, "must be > 0")


def require_non_negative(name: str, value: float) -> None:
    """Raise unless ``value`` is finite and >= 0."""
    require_finite(name, value)
    if value < 0.0:
        raise ParameterError(name, value, "must be >= 0")


__all__ = ["ParameterError", "require_finite", "require_positive", "require_non_negative"]
