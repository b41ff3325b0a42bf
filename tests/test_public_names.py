"""One meaning per name (issue 34, item 5): no module imports another package's private
(``_name``) names, every public module says what it exports (``__all__``, of names it
binds), a package binds no function under one of its modules' names, and ``UNITS`` is
one table (``boomfmi.units``) whose spelling every other unit map of ours uses.

The walks read the source (``ast``).  The import layering is checked by
``tests/test_recipe.py``.  ``python tests/test_public_names.py FILE...`` prints an
``__all__`` for each module: its public top-level definitions, to edit."""
from __future__ import annotations

import ast
import functools
import types
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "boomfmi"

#: (importing file, private name): imports across packages that files owned elsewhere
#: still make, each with its reason; the lead clears an entry when its owner is done (an
#: entry no longer needed fails the test, so the list only shrinks).
PRIVATE_ALLOWED: dict[tuple[str, str], str] = {}

#: Public modules without ``__all__`` yet, each owned by another change of issue 32/33/34 while
#: this one was made; the lead adds theirs (``python tests/test_public_names.py FILE`` prints
#: one) and clears the entry (an entry whose module has ``__all__`` fails the test).
ALL_PENDING: dict = {}

#: Modules still binding their own ``UNITS`` (a parameter -> unit map, not the unit table):
#: owned elsewhere; the lead renames them (``PARAMETER_UNITS``) and clears the entry.
UNITS_PENDING: dict = {}


def _modules(root: Path):
    """(path relative to ``root``'s parent, dotted name, is a package) of every module."""
    for f in sorted(root.rglob("*.py")):
        if "node_modules" in f.parts:
            continue
        parts = list(f.relative_to(root.parent).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        yield f, parts[:-1] if is_pkg else parts, is_pkg


@functools.lru_cache(maxsize=None)
def _parse(f: Path) -> ast.Module:
    return ast.parse(f.read_text(), str(f))


def _is_private(segment: str) -> bool:
    return segment.startswith("_") and not (segment.startswith("__") and segment.endswith("__"))


def _is_module(root: Path, dotted: list[str]) -> bool:
    path = root.parent.joinpath(*dotted)
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def private_imports(root: Path = PACKAGE) -> list[tuple[str, int, str]]:
    """(file relative to ``root``, line, dotted name) of each import of a private name or
    module (``_x``) from outside the package that holds it: ``from ..a.b import _x``,
    ``import a._m``, or ``m._x`` on a module ``m`` imported from another package.  A
    private name is its package's: ``boomfmi/_json.py`` is open to all of boomfmi,
    ``physics/linkage.py``'s ``_prepared`` to ``physics/`` only."""
    found = []
    for f, mod, is_pkg in _modules(root):
        here = mod if is_pkg else mod[:-1]
        tree = _parse(f)
        bound: dict[str, list[str]] = {}            # local name -> the module it is
        uses = []                                   # (line, dotted path)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = (here[:len(here) - node.level + 1] if node.level else [])
                target = target + (node.module.split(".") if node.module else [])
                for a in node.names:
                    full = target + [a.name]
                    uses.append((node.lineno, full))
                    if _is_module(root, full):
                        bound[a.asname or a.name] = full
            elif isinstance(node, ast.Import):
                for a in node.names:
                    full = a.name.split(".")
                    uses.append((node.lineno, full))
                    bound[a.asname or full[0]] = full if a.asname else full[:1]
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and _is_private(node.attr) and isinstance(node.value, ast.Name)
                    and node.value.id in bound):
                uses.append((node.lineno, bound[node.value.id] + [node.attr]))
        for line, full in uses:
            if full[0] != root.name:
                continue
            for i, segment in enumerate(full):
                if _is_private(segment):
                    home = full[:i] if (root.parent.joinpath(*full[:i]) / "__init__.py").is_file() else full[:i - 1]
                    if here[:len(home)] != home:            # outside the package that holds it
                        found.append((f.relative_to(root).as_posix(), line, ".".join(full)))
                    break
    return sorted(set(found))


def test_no_module_imports_another_packages_private_name():
    found = private_imports()
    allowed = {(where, dotted.rsplit(".", 1)[1]) for where, _, dotted in found} & set(PRIVATE_ALLOWED)
    bad = [f"src/boomfmi/{where}:{line}: imports {dotted}, private to its package: give it a public name "
           f"at its home" for where, line, dotted in found if (where, dotted.rsplit(".", 1)[1]) not in allowed]
    assert not bad, "\n".join(bad)
    stale = sorted(set(PRIVATE_ALLOWED) - allowed)
    assert not stale, f"PRIVATE_ALLOWED entries no longer needed (clear them): {stale}"


def test_the_private_import_walk_finds_each_kind(tmp_path):
    """The walk is not vacuous: a private name, a private module and an attribute of
    another package's module are found, with file and line; the same inside the package
    that holds them, or a package-wide private module, are not."""
    pkg = tmp_path / "boomfmi"
    for folder in ("a", "b"):
        (pkg / folder).mkdir(parents=True)
        (pkg / folder / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "_shared.py").write_text("x = 1\n")
    (pkg / "a" / "_inner.py").write_text("y = 1\n")
    (pkg / "a" / "m.py").write_text("def _helper():\n    pass\n")
    (pkg / "a" / "ok.py").write_text("from .m import _helper\nfrom . import _inner\nfrom .._shared import x\n")
    (pkg / "b" / "bad.py").write_text("from ..a.m import _helper\n"
                                      "def f():\n    from ..a import _inner\n"
                                      "    from ..a import m\n    return m._helper\n")
    assert private_imports(pkg) == [("b/bad.py", 1, "boomfmi.a.m._helper"), ("b/bad.py", 3, "boomfmi.a._inner"),
                                    ("b/bad.py", 5, "boomfmi.a.m._helper")]


def _bound_names(tree: ast.Module) -> set[str]:
    """Names a module binds at its top level (in ``if``/``try`` blocks too)."""
    names: set[str] = set()

    def visit(body):
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
                for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                    names.update(n.id for n in ast.walk(t) if isinstance(n, ast.Name))
            elif isinstance(node, (ast.Import, ast.ImportFrom)):
                names.update((a.asname or a.name).split(".")[0] for a in node.names)
            elif isinstance(node, (ast.If, ast.Try, ast.With, ast.For)):
                for field in ("body", "orelse", "finalbody"):
                    visit(getattr(node, field, []))
                for h in getattr(node, "handlers", []):
                    visit(h.body)
    visit(tree.body)
    return names


def module_all_problems(root: Path = PACKAGE, pending=ALL_PENDING) -> list[str]:
    """Each public module (no ``_`` in its path) without ``__all__``, with one that is not
    a literal list of strings, or naming what the module does not bind."""
    bad = []
    for f, mod, _ in _modules(root):
        rel = f.relative_to(root).as_posix()
        if any(_is_private(p) for p in mod):
            continue
        tree = _parse(f)
        alls = [n for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign))
                and any(isinstance(t, ast.Name) and t.id == "__all__"
                        for t in (n.targets if isinstance(n, ast.Assign) else [n.target]))]
        if not alls:
            if rel not in pending:
                bad.append(f"src/boomfmi/{rel}: a public module without __all__")
            continue
        if rel in pending:
            bad.append(f"src/boomfmi/{rel} has __all__ now: clear its entry in ALL_PENDING")
        value = alls[-1].value
        if not (isinstance(value, (ast.List, ast.Tuple))
                and all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in value.elts)):
            bad.append(f"src/boomfmi/{rel}:{alls[-1].lineno}: __all__ is not a literal list of names")
            continue
        listed = [e.value for e in value.elts]
        bound = _bound_names(tree)
        bad += [f"src/boomfmi/{rel}: __all__ names {n!r}, which the module does not define or import"
                for n in listed if n not in bound]
        bad += [f"src/boomfmi/{rel}: __all__ names {n!r} twice" for n in set(listed) if listed.count(n) > 1]
    return bad


def test_every_public_module_has_an_all_of_names_it_binds():
    bad = module_all_problems()
    assert not bad, "\n".join(bad)


def test_the_all_check_finds_a_missing_all_and_a_name_not_bound(tmp_path):
    pkg = tmp_path / "boomfmi"
    pkg.mkdir()
    (pkg / "__init__.py").write_text('__all__ = ["__version__"]\n__version__ = "0"\n')
    (pkg / "_private.py").write_text("x = 1\n")
    (pkg / "none.py").write_text("x = 1\n")
    (pkg / "wrong.py").write_text('from os import path\n__all__ = ["path", "gone"]\n')
    assert module_all_problems(pkg, {}) == [
        "src/boomfmi/none.py: a public module without __all__",
        "src/boomfmi/wrong.py: __all__ names 'gone', which the module does not define or import"]


def test_a_package_binds_no_other_thing_under_one_of_its_modules_names():
    """``boomfmi.diagnose.attribute`` was the function (re-exported by the package),
    so ``import boomfmi.diagnose.attribute as m`` gave a function, not the module."""
    bad = []
    for f, mod, is_pkg in _modules(PACKAGE):
        if not is_pkg:
            continue
        submodules = {p.stem for p in f.parent.glob("*.py")} | {p.parent.name for p in f.parent.glob("*/__init__.py")}
        where = f"src/boomfmi/{f.relative_to(PACKAGE).as_posix()}"
        tree = _parse(f)
        for node in tree.body:
            if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:   # not `from . import m`
                bad += [f"{where}:{node.lineno}: binds {a.asname or a.name!r} (from .{node.module}) under the name "
                        f"of its module {'.'.join(mod)}.{a.asname or a.name}"
                        for a in node.names if (a.asname or a.name) in submodules]
            elif not isinstance(node, (ast.Import, ast.ImportFrom)):
                bad += [f"{where}:{node.lineno}: defines {n!r}, the name of its module {'.'.join(mod)}.{n}"
                        for n in _bound_names(ast.Module(body=[node], type_ignores=[])) & submodules]
    assert not bad, "\n".join(bad)
    import boomfmi.diagnose.attribute as attribute_module
    import boomfmi.diagnose.localise as localise_module
    assert isinstance(attribute_module, types.ModuleType) and callable(attribute_module.attribute)
    assert isinstance(localise_module, types.ModuleType) and callable(localise_module.localise)


def _top_level_binds(f: Path, name: str) -> bool:
    return name in _bound_names(_parse(f))


def test_units_is_one_table_and_our_unit_maps_spell_units_as_it_does():
    """``UNITS`` is ``boomfmi.units``'s table of unit names (the FMUs' unit definitions);
    the maps of a parameter or a channel to its unit have names of their own and spell
    each unit as that table does (the bench wrote ``m^2``, ``N s/m``, ``kg/(s Pa)``)."""
    from boomfmi.bench.friction import PARAMETER_UNITS as FRICTION_UNITS
    from boomfmi.bench.leak import PARAMETER_UNITS as LEAK_UNITS
    from boomfmi.bench.report import DISPLAY
    from boomfmi.recording import EXCAVATOR_RIG_UNITS, RIG_UNITS
    from boomfmi.units import UNITS
    homes = sorted(f.relative_to(PACKAGE).as_posix() for f, _, _ in _modules(PACKAGE)
                   if _top_level_binds(f, "UNITS") and "UNITS" not in {
                       a.asname or a.name for n in _parse(f).body
                       if isinstance(n, ast.ImportFrom) for a in n.names})
    assert set(homes) - set(UNITS_PENDING) == {"units.py"}, f"UNITS defined in {homes}: one home, units.py"
    assert set(UNITS_PENDING) <= set(homes), f"UNITS_PENDING entries to clear: {set(UNITS_PENDING) - set(homes)}"
    for where, table in (("bench.friction.PARAMETER_UNITS", FRICTION_UNITS), ("bench.leak.PARAMETER_UNITS", LEAK_UNITS),
                         ("recording.RIG_UNITS", RIG_UNITS), ("recording.EXCAVATOR_RIG_UNITS", EXCAVATOR_RIG_UNITS)):
        odd = {k: u for k, u in table.items() if u not in UNITS}
        assert not odd, f"{where}: units not spelled as boomfmi.units.UNITS spells them: {odd}"
    for unit, (factor, shown) in DISPLAY.items():
        assert shown in UNITS.get(unit, ({}, {}))[1], f"bench.report.DISPLAY: {unit!r} -> {shown!r}: not units.UNITS'"
        assert UNITS[unit][1][shown] == (factor, 0.0), f"bench.report.DISPLAY[{unit!r}] is not units.UNITS' {shown}"


def test_holding_forces_are_the_linkages_bias_at_rest():
    """``physics.linkage.holding_forces`` (public: ``model.machine.holding_pressures`` used
    the linkage's private stepping terms) is the piston-coordinate bias at zero speed."""
    import numpy as np
    from boomfmi.physics.linkage import excavator_parameters, holding_forces, piston_dynamics
    ex = excavator_parameters()
    for share, payload in ((0.3, 0.0), (0.7, 1.5)):
        x = share * np.array([a.stroke for a in ex.actuators])
        _, bias, _ = piston_dynamics(x, np.zeros(4), payload, ex)
        assert holding_forces(x, payload, ex) == pytest.approx(list(bias), rel=1e-12, abs=1e-9)


def _options(parser) -> dict:
    """A parser's options and positionals, and its sub-commands' (recursively)."""
    import argparse
    out = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out.update({f"{name} {k}": v for name, p in action.choices.items() for k, v in _options(p).items()})
        else:
            out[action.dest + str(action.option_strings)] = (action.default, action.required, action.nargs)
    return out


def test_each_command_of_the_cli_has_its_own_parser_builder():
    """``cli.build_parser`` adds the options common to all, then calls one builder per
    command (``cli.COMMANDS``); each builder alone makes its command's whole parser."""
    import argparse
    from boomfmi import cli
    whole = cli.build_parser()
    commands = next(a for a in whole._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert [b.__name__ for b in cli.COMMANDS] == [f"_{name}_parser" for name in commands]
    for builder, (name, built) in zip(cli.COMMANDS, commands.items()):
        alone = argparse.ArgumentParser().add_subparsers()
        builder(alone)
        assert list(alone.choices) == [name], f"{builder.__name__} builds {list(alone.choices)}, not {name!r}"
        assert _options(alone.choices[name]) == _options(built), f"{builder.__name__}: not the whole parser's {name}"
    assert cli.build_parser().parse_args(["identify", "r.csv", "--out", "p.json"]).run is cli._identify


if __name__ == "__main__":          # an __all__ to start from: the module's public top-level definitions
    import sys
    for name in sys.argv[1:]:
        body = ast.parse(Path(name).read_text()).body
        defined = [n for node in body if not isinstance(node, (ast.Import, ast.ImportFrom))
                   for n in sorted(_bound_names(ast.Module(body=[node], type_ignores=[])))]
        public = list(dict.fromkeys(n for n in defined if not n.startswith("_")))
        print(f"# {name}\n__all__ = {public!r}".replace("'", '"'))
