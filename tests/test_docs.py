"""The product describes itself as it is: no development history and no dead links in tracked text files.

Every tracked text file (``git ls-files``: Markdown, Python, YAML, TOML, text, cfg, XML, interface
definitions, CITATION.cff; binary files are skipped) is read, CHANGELOG.md included, which is written
per capability. A file fails on words that speak of the project's own work periods or its tracker:

- the word for a work period (``sess`` + ``ion``, singular or plural, any case, as a whole word;
  no API the project uses has it in a name, so there is no exception);
- the word for a tracker entry (``iss`` + ``ue``, singular or plural) followed by a number, with or
  without ``#``;
- the word for a work turn (``tu`` + ``rn``, singular or plural) followed by a number, except when the
  number is an angle: followed by a degree sign, "deg", "degree(s)" or "rad" (a fillet sent blunt end
  first is turned by 180 deg, which describes how it lies, not when it was made).

Markdown files also fail on relative links that point at nothing: ``[text](path)``, ``![alt](path)``
and reference definitions ``[label]: path``, outside code blocks and inline code, resolved relative to
the file; http(s), mailto, other schemes and in-page ``#anchors`` are not checked. A target must be a
tracked file or a folder holding one, so a link to an output of ``make demo`` (not committed) fails too.

The patterns are built from pieces so that this file does not match itself.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path, PurePosixPath

import pytest
from conftest import REPO

TEXT_SUFFIXES = {".md", ".py", ".yaml", ".yml", ".toml", ".txt", ".cfg", ".xml", ".msg", ".srv", ".cff"}

WORK_PERIOD = re.compile(r"\b" + "sess" + r"ions?\b", re.IGNORECASE)
TRACKER = re.compile(r"\b" + "iss" + r"ues?\s*#?\s*\d+", re.IGNORECASE)
WORK_TURN = re.compile(r"\b" + "tu" + r"rns?\s+#?\d+(?:\.\d+)?(?!\d|\.\d|\s*(?:°|deg\b|degrees?\b|rad\b))",
                       re.IGNORECASE)
HISTORY = {"work period": WORK_PERIOD, "tracker reference": TRACKER, "work turn": WORK_TURN}

INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE_LINK = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s|$)")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
FENCE = re.compile(r"^\s{0,3}(```|~~~)")
INLINE_CODE = re.compile(r"`+[^`]*`+")


def tracked_files() -> list[str]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    return [name for name in out.decode().split("\0") if name]


TRACKED = tracked_files()
TRACKED_SET = set(TRACKED)
TRACKED_DIRS = {str(parent) for name in TRACKED for parent in PurePosixPath(name).parents}


def text_files() -> dict[str, str]:
    """Path -> text of every tracked text file that exists in the checkout (binary files skipped)."""
    files = {}
    for name in TRACKED:
        path = REPO / name
        if PurePosixPath(name).suffix.lower() not in TEXT_SUFFIXES or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data:
            continue
        try:
            files[name] = data.decode("utf-8")
        except UnicodeDecodeError:
            continue
    return files


FILES = text_files()


def history_hits(text: str) -> list[str]:
    hits = []
    for number, line in enumerate(text.splitlines(), 1):
        for what, pattern in HISTORY.items():
            for match in pattern.finditer(line):
                hits.append(f"{number}: {what} {match.group(0)!r}: {line.strip()[:120]}")
    return hits


def link_targets(text: str) -> list[tuple[int, str]]:
    """(line, target) of every inline or reference link outside code blocks and inline code."""
    targets, fenced = [], None
    for number, line in enumerate(text.splitlines(), 1):
        fence = FENCE.match(line)
        if fence:
            fenced = None if fenced == fence.group(1) else (fenced or fence.group(1))
            continue
        if fenced:
            continue
        prose = INLINE_CODE.sub("", line)
        targets += [(number, m.group(1)) for m in INLINE_LINK.finditer(prose)]
        reference = REFERENCE_LINK.match(prose)
        if reference:
            targets.append((number, reference.group(1)))
    return targets


def dead_links(name: str, text: str) -> list[str]:
    dead = []
    for number, target in link_targets(text):
        if target.startswith("#") or SCHEME.match(target):
            continue
        path = target.split("#", 1)[0].split("?", 1)[0]
        if not path:
            continue
        base = PurePosixPath(name).parent
        resolved = Path(base.as_posix(), path) if not path.startswith("/") else Path(path.lstrip("/"))
        try:
            relative = (REPO / resolved).resolve().relative_to(REPO.resolve()).as_posix()
        except ValueError:
            dead.append(f"{number}: {target} (outside the repository)")
            continue
        if relative not in TRACKED_SET and relative not in TRACKED_DIRS:
            dead.append(f"{number}: {target}")
    return dead


def test_tree_has_text_files():
    assert "README.md" in FILES and len(FILES) > 100


@pytest.mark.parametrize("name", sorted(FILES))
def test_no_development_history(name):
    hits = history_hits(FILES[name])
    assert not hits, f"{name} speaks of the project's work periods or tracker:\n" + "\n".join(hits)


@pytest.mark.parametrize("name", sorted(n for n in FILES if n.endswith(".md")))
def test_no_dead_relative_links(name):
    dead = dead_links(name, FILES[name])
    assert not dead, f"{name} links to files that are not in the repository:\n" + "\n".join(dead)


@pytest.mark.parametrize(("line", "hit"), [
    ("measured in " + "sess" + "ion 7", True),
    ("SESS" + "IONS of work", True),
    ("asked by " + "iss" + "ue 12", True),
    ("see " + "iss" + "ue #3", True),
    ("done in " + "tu" + "rn 2", True),
    ("a fillet sent blunt end first is a " + "tu" + "rn 180 deg about the vertical", False),
    ("tu" + "rned by 13° RMS", False),
    ("a " + "tu" + "rn 90° left", False),
    ("an open issue with the camera", False),
    ("possession", False),
])
def test_history_rule(line, hit):
    assert bool(history_hits(line)) is hit


def test_link_rule():
    text = "\n".join([
        "[ok](README.md) ![plot](docs/results/phi_vs_k.png) [anchor](#quick-start) [web](https://example.org)",
        "[gone](docs/nothing-here.md) `[code](not-a-link.md)`",
        "```", "[fenced](also-not-a-link.md)", "```",
        "[ref]: missing.md",
    ])
    assert dead_links("README.md", text) == ["2: docs/nothing-here.md", "6: missing.md"]
