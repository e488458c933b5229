"""The documents' links: every ``[text](#anchor)`` and ``[text](docs/FILE.md#anchor)`` in the
README and docs/ names a heading that exists (GitHub's slugs), and every linked file exists."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def slug(heading):
    """GitHub's anchor for a markdown heading: lower case, punctuation but ``-`` and ``_``
    dropped, spaces to ``-`` (``The `max_spacing` guard: a bound`` ->
    ``the-max_spacing-guard-a-bound``)."""
    text = heading.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path):
    out, seen = set(), {}
    fence = False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fence = not fence
        if fence or not line.startswith("#"):
            continue
        base = slug(line.lstrip("#"))
        n = seen.get(base, 0)  # repeated headings get -1, -2, ...
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def test_slugs_are_githubs():
    assert slug(" The `max_spacing` guard: a bound, not a floor (2026-12-04, night)") == \
        "the-max_spacing-guard-a-bound-not-a-floor-2026-12-04-night"
    assert slug("Real files: where the core's time goes") == "real-files-where-the-cores-time-goes"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_links_name_headings_that_exist(doc):
    text = doc.read_text()
    bad = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if target.startswith(("http://", "https://", "mailto:")):
            continue
        file, _, anchor = target.partition("#")
        path = doc if not file else (doc.parent / file)
        if not path.exists():
            bad.append(f"{target}: no such file")
            continue
        if anchor and path.suffix == ".md" and anchor not in anchors(path):
            bad.append(f"{target}: no such heading in {path.name}")
    assert not bad, f"{doc.name}: " + "; ".join(bad)
