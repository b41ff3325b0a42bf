"""Turn results holding NumPy scalars into what ``json.dumps`` writes as JSON."""
from __future__ import annotations

import json
import math

import numpy as np


def plain(obj):
    """``obj`` with NumPy scalars as Python numbers, tuples and arrays as lists, and a
    number that is not finite (an interval nobody could give) as ``None``, recursively:
    what any JSON reader takes (JSON has no NaN or Infinity; Python's ``json`` would
    write them, and strict readers refuse the file)."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [plain(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def dumps(obj, **kwargs) -> str:
    """``json.dumps`` of :func:`plain` ``(obj)``, refusing anything that is still not JSON."""
    return json.dumps(plain(obj), allow_nan=False, **kwargs)


def read_object(path, keys, what: str, error):
    """The JSON object in the file ``path`` (a ``pathlib.Path``), checked: it exists, is
    JSON, is an object, and holds only ``keys``.  A fault raises ``error(path, message)``
    (the caller's error type), the message naming ``what`` the file is."""
    if not path.is_file():
        raise error(path, f"no such {what}")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise error(path, f"the {what} is not valid JSON: {e}") from None
    if not isinstance(doc, dict):
        raise error(path, f"the {what} must hold a JSON object")
    for k in doc:
        if k not in keys:
            raise error(path, f"unknown key {k!r}; a {what} may hold {', '.join(keys)}")
    return doc
