"""The documentation: the site builds with every warning an error, relative links resolve, and the commands the
README shows exist with the options shown.

(a) ``mkdocs build --strict`` into a temporary folder (mkdocs comes with the ``docs`` extra, which the set-up
installs, so that the test never skips under ``make test``); (b) every relative link of README.md and
docs/**/*.md points to an existing file, and its anchor to a heading of that file; (c) every
``mpc-actuator <command>`` line of the README's shell blocks names a subcommand of
:func:`harness.cli.build_parser`, and every option shown for it is one that subcommand accepts.
"""
from __future__ import annotations

import contextlib
import importlib.util
import io
import re
import subprocess
import sys
import unicodedata
from pathlib import Path

import pytest

from harness.cli import build_parser

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
DOCS = REPO / "docs"
PAGES = [README] + sorted(DOCS.rglob("*.md"))

FENCE = re.compile(r"^(```|~~~)")
LINK = re.compile(r"(?<!!)\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
INLINE_CODE = re.compile(r"`[^`]*`")
OPTION = re.compile(r"(?<![\w-])--[A-Za-z][\w-]*")


def prose_lines(text: str):
    """(line number, line) outside fenced code blocks, inline code removed."""
    fenced = False
    for n, line in enumerate(text.splitlines(), 1):
        if FENCE.match(line.lstrip()):
            fenced = not fenced
            continue
        if not fenced:
            yield n, INLINE_CODE.sub("", line)


def slug(heading: str) -> str:
    """The anchor Python-Markdown's toc extension gives a heading (its default slugify)."""
    text = re.sub(r"[`*_]", "", heading)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)   # a link in a heading keeps its text
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(path: Path) -> set[str]:
    found: dict[str, int] = {}
    out = set()
    fenced = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line.lstrip()):
            fenced = not fenced
            continue
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m and not fenced:
            s = slug(m.group(1))
            k = found.get(s, 0)
            out.add(s if k == 0 else f"{s}_{k}")   # toc's suffix for repeated headings
            found[s] = k + 1
    return out


def broken_links(path: Path) -> list[str]:
    """Relative links of one Markdown file whose file or anchor does not exist."""
    bad = []
    for n, line in prose_lines(path.read_text(encoding="utf-8")):
        for target in LINK.findall(line):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):   # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            dest = (path.parent / file_part).resolve() if file_part else path
            where = f"{path.relative_to(REPO)}:{n}: {target}"
            if not dest.exists():
                bad.append(f"{where} (no such file)")
            elif anchor and (dest.suffix != ".md" or anchor not in anchors(dest)):
                bad.append(f"{where} (no heading with anchor #{anchor} in {dest.relative_to(REPO)})")
    return bad


def shown_commands(text: str) -> list[tuple[int, str]]:
    """(line number, command line with its continuation lines) of every ``mpc-actuator ...`` in sh blocks."""
    commands: list[tuple[int, str]] = []
    in_sh = False
    continuing = False
    for n, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if FENCE.match(stripped):
            in_sh = not in_sh and stripped[3:].strip() in ("sh", "bash", "shell", "console")
            continuing = False
            continue
        if not in_sh:
            continue
        code = re.split(r"\s#\s|\s#$", " " + line)[0]   # drop a trailing comment
        if code.strip().startswith("mpc-actuator "):
            commands.append((n, code.strip()))
            continuing = True
        elif continuing and line[:1].isspace() and code.strip().startswith("["):
            commands[-1] = (commands[-1][0], commands[-1][1] + " " + code.strip())
        else:
            continuing = False
    return commands


def help_text(*args: str) -> str | None:
    """What ``build_parser().parse_args([*args, "--help"])`` prints, or None when argparse refuses the arguments
    (an unknown subcommand); argparse's public interface only, no private attributes."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            build_parser().parse_args([*args, "--help"])
        except SystemExit as stop:
            return out.getvalue() if stop.code == 0 else None
    raise AssertionError(f"--help did not exit: {args}")


def subcommand_options() -> dict[str, set[str]]:
    """{subcommand: the options it accepts}, read from the help texts."""
    top = help_text()
    names = re.search(r"\{([\w,-]+)\}", top).group(1).split(",")
    return {name: set(OPTION.findall(help_text(name))) for name in names}


def command_problems(text: str, source: str) -> list[str]:
    subs = subcommand_options()
    problems = []
    for n, command in shown_commands(text):
        words = command.split()
        name = words[1] if len(words) > 1 else ""
        if name not in subs:
            problems.append(f"{source}:{n}: `mpc-actuator {name}` is not a subcommand (have: {', '.join(subs)})")
            continue
        for option in OPTION.findall(command):
            if option not in subs[name]:
                problems.append(f"{source}:{n}: `mpc-actuator {name}` does not accept {option}")
    return problems


@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None,
                    reason="mkdocs is not installed (the 'docs' extra; `make test` installs it)")
def test_site_builds_strictly(tmp_path):
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stdout}\n{done.stderr}"
    assert (tmp_path / "site" / "index.html").is_file()
    assert (tmp_path / "site" / "api" / "jobs" / "index.html").is_file()


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(REPO)) for p in PAGES])
def test_relative_links_resolve(page):
    assert broken_links(page) == []


def test_readme_commands_exist_with_their_options():
    text = README.read_text(encoding="utf-8")
    commands = shown_commands(text)
    assert len(commands) >= 10, "the README's command block was not found"
    shown = {c.split()[1] for _, c in commands}
    assert {"run", "generate", "diagnose", "uncertainty", "design"} <= shown
    assert command_problems(text, "README.md") == []


@pytest.mark.parametrize("page", sorted(DOCS.rglob("*.md")), ids=lambda p: str(p.relative_to(REPO)))
def test_docs_commands_exist_with_their_options(page):
    assert command_problems(page.read_text(encoding="utf-8"), str(page.relative_to(REPO))) == []


def test_readme_is_a_front_door():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 250
