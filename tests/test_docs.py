"""The documentation stays navigable: the README short (what geocert is, the two commands, one
example per interface, links; the rest is in docs/ by topic), and every relative link in the
README, CHANGELOG and docs/ pointing to a file that exists, so moving a page breaks a test rather
than a reader's click."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README_MAX_LINES = 220
# [text](target): the target up to whitespace or ")", an optional "title" ignored.
LINK = re.compile(r"\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def documents() -> list[Path]:
    return [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md")),
            *sorted((ROOT / "bench" / "results").glob("*.md"))]


def broken_links(path: Path) -> list[str]:
    """The relative links of a markdown file whose target file does not exist (web addresses,
    mail addresses and anchors within the page are not checked)."""
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    broken = []
    for target in LINK.findall(text):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue
        file = target.split("#", 1)[0]
        if not (path.parent / file).exists():
            broken.append(target)
    return broken


def test_the_readme_is_short():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines: move detail to docs/"


def test_every_relative_link_points_to_a_file():
    found = {str(path.relative_to(ROOT)): broken_links(path) for path in documents() if path.exists()}
    assert {name: links for name, links in found.items() if links} == {}


def test_the_link_finder_sees_a_broken_link(tmp_path):
    (tmp_path / "there.md").write_text("x")
    page = tmp_path / "page.md"
    page.write_text("[ok](there.md) [ok too](there.md#part) [web](https://example.org/x.md) "
                    "[anchor](#top) [gone](missing.md) [gone too](sub/missing.md#part)\n"
                    "```\n[in a fence](fenced.md)\n```\n")
    assert broken_links(page) == ["missing.md", "sub/missing.md#part"]


def command_options(command: str) -> set[str]:
    """The options ``geocert COMMAND`` accepts, as its own --help lists them."""
    import contextlib
    import io

    import pytest

    from geocert.app.cli import main

    shown = io.StringIO()
    with contextlib.redirect_stdout(shown), pytest.raises(SystemExit):
        main([command, "--help"])
    return set(re.findall(r"(?<![\w-])(--[a-z][a-z-]*)", shown.getvalue())) - {"--help"}


def test_the_command_line_section_names_every_option_each_command_accepts():
    """docs/api.md's "Command line" lists every option of every command (``--api-processes``
    was accepted by ``geocert serve`` and missing there)."""
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    section = text.split("## Command line", 1)[1].split("\n## ", 1)[0]
    missing = {command: sorted(option for option in command_options(command) if option not in section)
               for command in ("solve", "verify", "serve", "worker", "openapi", "webhook-secret")}
    assert {command: options for command, options in missing.items() if options} == {}
