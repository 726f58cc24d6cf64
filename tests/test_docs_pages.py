"""The user guide's pages and the README's first screen stay what a newcomer needs.

The guide (docs/guide/) has one page per family, each in the guide's toctree and each
starting with when to use that family; the README's first screen (title and intro,
the two commands, the quick start, the method table, the demo's picture and the
guide links) stays under 400 words, its links to docs point at files that exist,
and its quick start runs. Sphinx is not run here (``make docs`` builds the site).
"""

import re
import runpy
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
GUIDE = DOCS / "guide"
README = ROOT / "README.md"

#: the README's first-screen sections; the first other "## " heading after them ends it
FIRST_SCREEN = ("Two commands", "Quick start", "Which method when", "The demo's maps",
                "Guide")
#: a section another part of the project owns; not counted if it appears
NOT_COUNTED = ("Install",)
MAX_WORDS = 400


def _toctree(text):
    """The entries of an RST file's toctree directives."""
    entries = []
    for block in re.findall(r"\.\. toctree::\n((?:[ \t]+.*\n|\n)+)", text):
        for line in block.splitlines():
            line = line.strip()
            if line and not line.startswith(":"):
                entries.append(line)
    return entries


def _sections(text):
    """(heading, body) for the part before the first "## " heading and each section."""
    parts = re.split(r"^## (.*)\n", text, flags=re.M)
    return [(None, parts[0])] + list(zip(parts[1::2], parts[2::2]))


def readme_first_screen():
    """The README's first screen, as text (the sections up to the first reference one)."""
    out = []
    for heading, body in _sections(README.read_text()):
        if heading is None or heading in FIRST_SCREEN:
            out.append(("" if heading is None else f"## {heading}\n") + body)
        elif heading in NOT_COUNTED:
            continue
        else:
            break
    return "".join(out)


def readme_words():
    """Words of the README's first screen, counted as ``wc -w`` counts them."""
    return len(readme_first_screen().split())


GUIDE_PAGES = sorted(p.stem for p in GUIDE.glob("*.rst") if p.stem != "index")


def test_guide_is_in_the_index():
    assert "guide/index" in _toctree((DOCS / "index.rst").read_text())
    assert not (DOCS / "user_guide.rst").exists()


def test_every_guide_page_is_in_the_guide_toctree():
    assert len(GUIDE_PAGES) >= 10
    assert sorted(_toctree((GUIDE / "index.rst").read_text())) == GUIDE_PAGES


@pytest.mark.parametrize("page", GUIDE_PAGES)
def test_guide_page_starts_with_when_to_use(page):
    text = (GUIDE / f"{page}.rst").read_text()
    # label, title, underline, then the first paragraph
    m = re.match(r"\.\. _guide-[a-z-]+:\n\n(.+)\n(=+)\n\n(.*)", text)
    assert m, f"{page}.rst must start with a label and a title"
    assert len(m.group(2)) == len(m.group(1))
    assert m.group(3).startswith("**When to use.**"), page


@pytest.mark.parametrize("page", GUIDE_PAGES + ["index"])
def test_guide_doc_links_resolve(page):
    text = (GUIDE / f"{page}.rst").read_text()
    for target in re.findall(r":doc:`(?:[^`<]*<)?([^`>]+)>?`", text):
        path = DOCS / (target[1:] if target.startswith("/") else f"guide/{target}")
        assert path.with_suffix(".rst").exists(), (page, target)


def test_readme_first_screen_is_short():
    words = readme_words()
    assert words < MAX_WORDS, f"README's first screen has {words} words"
    text = readme_first_screen()
    for part in ("make demo", "make test", "```python", "| when to use it |", "```\n"):
        assert part in text or part.replace("| ", "").replace(" |", "") in text, part


def test_readme_links_to_docs_exist():
    for target in re.findall(r"\]\(((?:docs|tools)/[^)#]+)\)", README.read_text()):
        assert (ROOT / target).exists(), target


@pytest.mark.slow
def test_readme_quick_start_runs(tmp_path, monkeypatch):
    code = re.search(r"## Quick start\n\n```python\n(.*?)```", README.read_text(), re.S)
    assert code and len(code.group(1).splitlines()) <= 10
    script = tmp_path / "quick_start.py"
    script.write_text(code.group(1))
    monkeypatch.chdir(tmp_path)
    ns = runpy.run_path(str(script))
    assert ns["centers"].shape[1] == 3
    assert (tmp_path / "room.bt").stat().st_size > 0


if __name__ == "__main__":   # python tests/test_docs_pages.py: print the count
    print(f"README first screen: {readme_words()} words (limit {MAX_WORDS})")
