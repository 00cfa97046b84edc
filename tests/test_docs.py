"""The README and docs pages: sane sizes, no paragraph written twice, links that resolve."""

import collections
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s#]+)(?:#[^)]*)?\)")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_page_is_prose_of_a_sane_size_without_repeated_paragraphs(page):
    # A botched scripted edit once inserted one paragraph between every character (10 MB).
    text = page.read_text()
    assert len(text) < 100_000, f"{page.name} is {len(text)} characters"
    paragraphs = [p for p in text.split("\n\n") if len(p) > 200]
    repeated = [p[:60] for p, n in collections.Counter(paragraphs).items() if n > 1]
    assert not repeated, f"{page.name} repeats: {repeated}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_relative_links_resolve(page):
    targets = [t for t in LINK.findall(page.read_text()) if "://" not in t]
    missing = [t for t in targets if not (page.parent / t).exists()]
    assert not missing, f"{page.name} links to missing files: {missing}"
