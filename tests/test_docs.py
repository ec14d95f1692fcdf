"""The docs cite only files that exist in the repository."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "models" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
CITED = re.compile(r"(?<![\w/.-])((?:multigpu|tests|launch|docs|models|\.ci)/[\w./-]*\w)")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_cited_paths_exist(page):
    text = page.read_text()
    missing = []
    for path in set(CITED.findall(text)):
        if "*" in path or path.startswith("docs/results/") and "/" in path[len("docs/results/"):]:
            continue  # globs and per-run outputs (not in git)
        if not (ROOT / path).exists() and not (page.parent / path).exists():
            missing.append(path)
    links = [m for m in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text) if not m.startswith("http")]
    missing += [m for m in links if not (page.parent / m).exists()]
    assert not missing, f"{page.name} cites missing files: {sorted(missing)}"
