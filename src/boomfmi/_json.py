"""Turn results holding NumPy scalars into what ``json.dumps`` writes."""
from __future__ import annotations

import numpy as np


def plain(obj):
    """``obj`` with NumPy scalars as Python numbers and tuples as lists, recursively."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj
