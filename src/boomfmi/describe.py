"""Describe a built FMU's interface as a Markdown table; ``docs/interfaces.md`` is every
FMU's (:func:`interfaces_document`, written by ``python build_fmus.py --write-references``
and compared with the built FMUs by ``tests/test_recipe.py``)."""
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


#: where the FMUs' interfaces are documented, relative to the repository
INTERFACES_DOC = "docs/interfaces.md"


def interfaces_document(paths) -> str:
    """The text of ``docs/interfaces.md``: the effect options (from the catalogue), then
    :func:`interface_table` of every FMU in ``paths``, by name."""
    from .model.catalogue import EFFECTS
    options = "\n".join(f"- `{e.name}` ({', '.join(f'`{e.fmu}.{p.option}`' for p in e.parameters)}): {e.summary}"
                         for e in EFFECTS.values())
    head = ("# FMU interfaces\n\n"
            "Generated from the built FMUs by `python build_fmus.py --write-references` (each table is "
            "`boomfmi describe build/fmus/NAME.fmu`); `tests/test_recipe.py` fails where this file is not "
            "what the FMUs declare.\n\n"
            "Each unmodelled effect of `shared/spec/effects.md` is an option of the FMU it belongs to, off "
            "by default so that the paper's model stays the baseline, switched on by its parameters (from an "
            "SSP parameter set, `--params`); their descriptions begin with the effect's name.  The options "
            "are declared from the catalogue of effects (`src/boomfmi/model/catalogue.py`); their forms are "
            "in `src/boomfmi/physics/effects.py`:\n\n" + options + "\n")
    return head + "".join("\n" + interface_table(p) for p in sorted(paths, key=lambda p: Path(p).stem))


__all__ = ["interface_table", "INTERFACES_DOC", "interfaces_document"]
