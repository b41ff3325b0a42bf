"""The test bench: friction and leak-down tests of a cylinder, read from foreign files
(``boomfmi.foreign``), fitted with the laws of ``physics.friction_laws`` and
``physics.leak_laws``, scored, and written as JSON, plots and HTML.

    run_friction(FIT, HOLD, area, opts, out)   -> out/friction.json, friction.html, *.png
    run_leak(RUNS, volume, opts, out)          -> out/leak.json, leak.png
"""
from __future__ import annotations

from pathlib import Path

from .._json import dumps, plain
from ..outputs import OutputSet
from .friction import bench_friction
from .leak import bench_leak, parse_pressure
from .report import friction_html, friction_plots, leak_plot

__all__ = ["run_friction", "run_leak", "parse_pressure", "quantity"]


def quantity(text: str, unit: str, option: str) -> float:
    """A command-line value in SI units: a plain number is taken in ``unit``; one with
    a unit (``490.9 mm^2``, ``0.5 L``) is converted by pint."""
    try:
        return float(text)
    except ValueError:
        pass
    import pint

    from ..foreign import units
    try:
        q = units().Quantity(text)
        return float(q.to(unit).magnitude)
    except (pint.errors.PintError, ValueError, AttributeError, TypeError, AssertionError) as e:
        raise ValueError(f"{option} {text!r}: give a number in {unit} or a quantity with a unit of the same "
                         f"dimension ({e})") from None


def run_friction(fit_paths, hold_paths, area: float, opts: dict, out, split: bool = False,
                 smooth: float | None = None, n_boot: int | None = None, progress=None) -> dict:
    """Run the friction bench and write ``friction.json``, ``friction.html``,
    ``friction_velocity.png`` and ``friction_pressure.png`` into ``out``."""
    kwargs = {k: v for k, v in (("smooth", smooth), ("n_boot", n_boot)) if v is not None}
    doc = bench_friction(fit_paths, hold_paths, area, opts, split=split, progress=progress, **kwargs)
    with OutputSet(Path(out)) as files:
        pngs = friction_plots(doc, files.path)
        doc.pop("_data")
        doc = plain(doc)
        files.path("friction.json").write_text(dumps(doc, indent=2))
        friction_html(doc, pngs, files.path("friction.html"))
    return doc


def run_leak(paths, volume: float, opts: dict, out, p_start: float | None = None, start: float | None = None,
             progress=None) -> dict:
    """Run the leak-down bench and write ``leak.json`` and ``leak.png`` into ``out``."""
    doc = bench_leak(paths, volume, opts, p_start=p_start, start=start, progress=progress)
    curves = doc.pop("_curves")
    with OutputSet(Path(out)) as files:
        leak_plot(doc, curves, files.path("leak.png"))
        doc = plain(doc)
        files.path("leak.json").write_text(dumps(doc, indent=2))
    return doc
