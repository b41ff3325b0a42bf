"""Describe a built FMU's interface as a Markdown table (used for the README)."""
from __future__ import annotations

from pathlib import Path

from .system.instance import model_description


def interface_table(path) -> str:
    """Markdown table of an FMU's variables: name, causality, unit, start, bounds, meaning."""
    md = model_description(path)
    order = {"input": 0, "output": 1, "parameter": 2}
    rows = ["| variable | causality | unit | start | min..max | description |",
            "|---|---|---|---|---|---|"]
    for v in sorted(md.modelVariables, key=lambda v: order.get(v.causality, 3)):
        bounds = ""
        if v.min is not None or v.max is not None:
            bounds = f"{v.min if v.min is not None else ''}..{v.max if v.max is not None else ''}"
        feeds = ""
        if v.causality == "output":
            out = next(u for u in md.outputs if u.variable is v)
            feeds = (" (feeds through from " + ", ".join(d.name for d in out.dependencies) + ")"
                     if out.dependencies else " (state: no direct feedthrough)")
        start = "" if v.start is None else v.start
        rows.append(f"| `{v.name}` | {v.causality} | {v.unit or ''} | {start} | {bounds} | "
                    f"{v.description}{feeds} |")
    return f"### `{Path(path).stem}`: {md.description}\n\n" + "\n".join(rows) + "\n"
