"""Every relative link of the project's own Markdown pages (every .md file git tracks,
but the docs of the upstream crates copied under patches/ and wan/patches/) leads to a
file of the repository, and every `#anchor` to a heading of the page it names (GitHub's
heading slugs). No page of README.md and docs/ points outside the repository (a clone
has nothing beside it)."""

import re
import subprocess
import unicodedata
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
# The copies of upstream crates keep their own docs as released (patches/README.md and
# wan/patches/README.md, ours, are scanned).
VENDORED = re.compile(r"^(wan/)?patches/[^/]+/")


def project_pages():
    """The tracked .md files, but the vendored crates': git's list, so that build output
    and untracked files are not pages."""
    listed = subprocess.run(["git", "-C", str(REPO), "ls-files", "-z", "*.md"], capture_output=True, check=True)
    names = [n for n in listed.stdout.decode().split("\0") if n and not VENDORED.match(n)]
    return [REPO / n for n in sorted(names)]


PAGES = project_pages()
# The reader's pages: BENCHMARKS.md compares with the seed's node by name, a measurement,
# not a pointer to material outside the repository.
READER_PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]

# [text](target) and ![alt](target); the target has no spaces or parentheses here.
LINK = re.compile(r"\]\(([^()\s]+)\)")
FENCE = re.compile(r"^\s*(```|~~~)")
CODE_SPAN = re.compile(r"`[^`\n]*`")


def without_fences(text):
    """The page with its fenced code blocks blanked (a `# comment` there is no heading)."""
    lines, in_fence = [], False
    for line in text.split("\n"):
        if FENCE.match(line):
            in_fence = not in_fence
            lines.append("")
        else:
            lines.append("" if in_fence else line)
    return "\n".join(lines)


def prose(text):
    """The page without code blocks and code spans (a `](x)` in code is not a link)."""
    return CODE_SPAN.sub("", without_fences(text))


def links(text):
    return LINK.findall(prose(text))


def slug(heading):
    """GitHub's anchor of a heading: lower case, markup and punctuation dropped (letters,
    digits, `_` and `-` kept), spaces to `-`."""
    text = heading.strip().lower()
    return "".join(
        "-" if c == " " else c
        for c in text
        if c in " -_" or unicodedata.category(c)[0] in "LN"
    )


def anchors(page):
    """The anchors of a Markdown page's headings, with GitHub's -1, -2 for repeats."""
    seen, out = {}, set()
    for line in without_fences(page.read_text(encoding="utf-8")).split("\n"):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def test_slug_follows_github():
    assert slug("Kinematics (tool point `tool0` in `base_link`)") == (
        "kinematics-tool-point-tool0-in-base_link"
    )
    assert slug("Other arms (the Jaco)") == "other-arms-the-jaco"
    assert slug("1. Build the bundle on the PC") == "1-build-the-bundle-on-the-pc"
    assert links("[a](x.md) `[b](y.md)`\n```\n[c](z.md)\n```\n![d](e.png)") == ["x.md", "e.png"]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(page):
    text = page.read_text(encoding="utf-8")
    found = links(text)
    broken = []
    for target in found:
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target}: no file {dest}")
            continue
        try:
            dest.relative_to(REPO)
        except ValueError:
            broken.append(f"{target}: outside the repository")
            continue
        if anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target}: no heading with anchor #{anchor} in {dest.name}")
    assert not broken, f"{page.relative_to(REPO)}:\n  " + "\n  ".join(broken)


@pytest.mark.parametrize("page", READER_PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_nothing_points_outside_the_repository(page):
    text = page.read_text(encoding="utf-8")
    for needle in ("../shared", "INTERFACES.md", "ROBOT.md", "seed report", "the seed's"):
        assert needle not in text, f"{page.relative_to(REPO)} mentions {needle!r}"
