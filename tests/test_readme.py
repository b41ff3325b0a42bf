"""The README's code blocks run as written (issue 36).

* Every ``boomfmi`` command line in any fenced block of the README (and of the docs pages
  the README's sections moved to) is parsed by the real command-line parser
  (``boomfmi.cli.build_parser``): a wrong option or a missing argument fails here, and
  every one calls ``.venv/bin/boomfmi`` (a bare ``boomfmi`` is not on PATH).
* The README's ``python`` blocks are run.
* The guide ("Diagnose your machine") is run block by block in a fresh folder, with the
  substitutions of ``GUIDE_SUBSTITUTIONS`` only (shorter runs, a free port), and the
  DAQ files its import block reads made from the recordings its record block made.
"""
from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: the docs pages that hold the README's moved sections (their commands are parsed too)
MOVED = ("running", "hosts", "rig", "teleoperation", "view", "identify", "diagnose", "campaign-guide", "bench",
         "fmus")
GUIDE = "Diagnose your machine"
#: what the test changes in the guide's lines before running them, and why: (pattern, replacement)
GUIDE_SUBSTITUTIONS = (
    (r"(boomfmi record .*)$", r"\1 --stop 3"),             # 3 s of each recording, not the profile's 12 s
    (r"(boomfmi simulate .*)$", r"\1 --stop 1"),           # 1 s of each profile's command
    (r"\b47800\b", "{port}"),                              # a free port: other tests serve rigs too
)
CONTROL = {";", "&&", "||", "|", "&", "(", ")", "$(", "`"}
SHELL_WORDS = {"do", "then", "else", "time", "!"}


def fenced_blocks(text: str) -> list[tuple[str, str, str]]:
    """Every fenced block of a Markdown text: (language, code, the ``##`` section it is in)."""
    out, section, block, lang, indent = [], "", None, "", 0
    for line in text.splitlines():
        stripped = line.lstrip()
        if block is None:
            if line.startswith("## "):
                section = line[3:].strip()
            elif stripped.startswith("```"):
                block, lang, indent = [], stripped[3:].strip(), len(line) - len(stripped)
        elif stripped.startswith("```"):
            out.append((lang, textwrap.dedent("\n".join(block)) + "\n", section))
            block = None
        else:
            block.append(line[indent:] if line[:indent].isspace() else line)
    assert block is None, "an unclosed fenced block"
    return out


def shell_lines(code: str) -> list[str]:
    """The logical lines of a shell block: backslash continuations joined."""
    return code.replace("\\\n", " ").splitlines()


def boomfmi_commands(code: str) -> list[list[str]]:
    """Every ``boomfmi`` command of a shell block as its words (comments, pipes, ``&``,
    ``;`` and loop keywords taken off)."""
    commands = []
    for line in shell_lines(code):
        lex = shlex.shlex(line, posix=True, punctuation_chars=";&|()`")
        lex.whitespace_split, lex.commenters = True, "#"
        words, segment = list(lex), []
        for w in words + [";"]:
            if w in CONTROL or set(w) <= set(";&|()`"):
                while segment and (segment[0] in SHELL_WORDS or re.fullmatch(r"\w+=.*", segment[0])):
                    segment.pop(0)
                if segment and Path(segment[0]).name == "boomfmi":
                    commands.append(segment)
                segment = []
            else:
                segment.append(w)
    return commands


def readme_blocks():
    return fenced_blocks(README.read_text())


def all_commands():
    """(where, words) of every boomfmi command in the shell blocks of the README and of the
    pages its sections moved to; a command in a block not marked ``sh`` is an error."""
    pages = [("README.md", README)] + [(f"docs/{name}.md", ROOT / "docs" / f"{name}.md") for name in MOVED]
    found = []
    for label, page in pages:
        for lang, code, section in fenced_blocks(page.read_text()):
            if lang in ("sh", "bash"):
                found += [(f"{label}, {section or 'top'}", cmd) for cmd in boomfmi_commands(code)]
            else:
                hidden = re.findall(r"(?m)^\s*(?:\S*/)?boomfmi .*", code)
                assert not hidden, f"{label}: a command in a block marked {lang!r}, not sh: {hidden}"
    return found


def parse(words: list[str]) -> str | None:
    """None where the real parser takes the command, else what it says; an option it would
    take only as an abbreviation is refused too (the README spells each one out)."""
    import argparse
    from boomfmi.cli import build_parser
    parser = build_parser()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            parser.parse_args(words)
        except SystemExit as e:
            return err.getvalue().strip() or f"exit {e.code}"
    known, rest = set(parser._option_string_actions), list(words)
    while rest:                                   # descend into the sub-command the words name
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        word = rest.pop(0)
        if subs and word in subs[0].choices:
            parser = subs[0].choices[word]
            known |= set(parser._option_string_actions)
    spelled = [w.split("=")[0] for w in words if w.startswith("--")]
    wrong = [w for w in spelled if w not in known]
    return f"not an option of its command (abbreviated?): {', '.join(wrong)}" if wrong else None


def test_the_block_reader_finds_commands_and_a_wrong_option_fails_the_parser():
    code = ("for r in a b; do\n  .venv/bin/boomfmi identify $r.csv --out p.json   # comment\ndone\n"
            "X=1 .venv/bin/boomfmi rig serve --port 1 \\\n    --lockstep &\nsleep 1; boomfmi check build/fmus\n")
    assert boomfmi_commands(code) == [[".venv/bin/boomfmi", "identify", "$r.csv", "--out", "p.json"],
                                      [".venv/bin/boomfmi", "rig", "serve", "--port", "1", "--lockstep"],
                                      ["boomfmi", "check", "build/fmus"]]
    assert parse(["identify", "a.csv", "--out", "p.json"]) is None
    assert "unrecognized arguments: --machne" in parse(["identify", "a.csv", "--machne", "m.json", "--out", "p.json"])
    assert "abbreviated?): --machin" in parse(["identify", "a.csv", "--machin", "m.json", "--out", "p.json"])
    assert "--holdout" in parse(["diagnose", "a.csv", "--out", "d"])


def test_every_boomfmi_command_in_the_readme_and_its_moved_pages_parses():
    commands = all_commands()
    guide = [c for where, c in commands if where.endswith(GUIDE)]
    assert len(commands) > 30 and len(guide) >= 8, (len(commands), len(guide))
    bad = [f"{where}: {shlex.join(cmd)}: {why}" for where, cmd in commands if (why := parse(cmd[1:]))]
    assert not bad, "\n".join(bad)
    bare = [f"{where}: {shlex.join(cmd)}" for where, cmd in commands if cmd[0] != ".venv/bin/boomfmi"]
    assert not bare, "call .venv/bin/boomfmi (a bare boomfmi is not on PATH):\n" + "\n".join(bare)


def test_the_readme_fits_in_400_lines_with_its_two_setup_commands_and_links_that_exist():
    text = README.read_text()
    assert len(text.splitlines()) <= 400
    setup = [code for lang, code, section in readme_blocks() if section.startswith("Set-up")]
    assert setup and "./run.sh " in setup[0] and "./test.sh " in setup[0]
    pages = [(README, text)] + [(ROOT / "docs" / f"{n}.md", (ROOT / "docs" / f"{n}.md").read_text()) for n in MOVED]
    for page, body in pages:
        for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", re.sub(r"`[^`\n]*`", "", body)):
            if not target.startswith("http"):
                assert (page.parent / target).exists(), f"{page.name}: a link to {target}, which does not exist"


def checkout_links(tmp_path: Path, build: Path) -> None:
    """A working folder where the README's relative paths hold: .venv, build, examples."""
    (tmp_path / ".venv").symlink_to(ROOT / ".venv")
    (tmp_path / "build").symlink_to(build)
    (tmp_path / "examples").symlink_to(ROOT / "examples")


def test_the_readme_s_python_blocks_run(tmp_path, ssp_path):
    checkout_links(tmp_path, ssp_path.parent.resolve())
    blocks = [code for lang, code, _ in readme_blocks() if lang == "python"]
    assert len(blocks) >= 3
    for code in blocks:
        proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, f"{code}\n{proc.stderr[-3000:]}"


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def guided(code: str, port: int) -> str:
    lines = []
    for line in shell_lines(code):
        for pattern, replacement in GUIDE_SUBSTITUTIONS:
            line = re.sub(pattern, replacement.format(port=port), line)
        lines.append(line)
    return "\n".join(lines) + "\n"


def write_daq_files(folder: Path, names) -> None:
    """The DAQ files the guide's import block reads, made from the recordings its record
    block made, in the layout its map names: ';', a header, ms, gauge bar, degrees."""
    from boomfmi.recording import read_recording
    for name in names:
        data = read_recording(folder / f"{name}.csv").data
        rows = [f"{1e3 * t:.3f};{u:.5f};{pa / 1e5:.7f};{pb / 1e5:.7f};{math.degrees(al):.7f}"
                for t, u, pa, pb, al in data[["t", "u", "p_a", "p_b", "alpha"]].to_numpy()]
        (folder / f"daq_{name}.csv").write_text("Zeit;Befehl;pA;pB;Winkel\n" + "\n".join(rows) + "\n")


@pytest.mark.slow
def test_the_guide_runs_as_written_on_the_virtual_rig(tmp_path, ssp_path):
    """Describe, choose and record (the virtual rig, 3 s each), import, identify, diagnose:
    every block of the guide as written but for GUIDE_SUBSTITUTIONS; the machine described
    reaches every recording's sidecar, and the effect-free rig gets nothing to fix."""
    blocks = [code for lang, code, section in readme_blocks() if section == GUIDE and lang == "sh"]
    assert len(blocks) == 4, blocks
    checkout_links(tmp_path, ssp_path.parent.resolve())
    env = {**os.environ, "PATH": f"{ROOT / '.venv' / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
           "BOOMFMI_BUILD": str(ssp_path.parent.resolve())}
    env.pop("BOOMFMI_LINK_KEY", None)
    port = free_port()
    outputs = []
    for i, code in enumerate(blocks):
        if "recording import" in code:
            write_daq_files(tmp_path, ("fit1", "fit2", "hold"))
        script = "set -e\n" + guided(code, port)
        proc = subprocess.Popen(["bash", "-c", script], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
        try:
            out, err = proc.communicate(timeout=180)
        finally:                                  # the block's own rig, should `kill %1` not have ended it
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
        assert proc.returncode == 0, f"block {i + 1}:\n{script}\n{out[-2000:]}\n{err[-3000:]}"
        assert "Traceback" not in err and "assuming" not in out + err, err
        outputs.append(out)
    machine = json.loads((tmp_path / "machine.json").read_text())
    assert set(machine["units"]) == set(machine["rig"])
    assert {"t", "u"} <= set((tmp_path / "random_steps.csv").read_text().splitlines()[0].split(","))
    assert "rig listening" in outputs[1] and "rig stopped" in outputs[1]        # started, and stopped by kill %1
    for name in ("fit1", "fit2", "hold"):
        side = json.loads((tmp_path / f"{name}.json").read_text())          # the import's sidecar
        assert side["rig"]["L"] == pytest.approx(machine["rig"]["L"]) and "wrote" in outputs[2]
    params = json.loads((tmp_path / "params.json").read_text())
    assert params["params"]["K_v"]["value"] > 0
    diagnosis = json.loads((tmp_path / "diag" / "diagnosis.json").read_text())
    assert diagnosis["verdict"] == [], diagnosis["verdict"]
    report = (tmp_path / "diag" / "report.html").read_text()
    assert re.search(r'<p class="act">Nothing to fix: the model matches the machine', report)
