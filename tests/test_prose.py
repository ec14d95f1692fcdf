"""The studies' words (``studies/text/*.md``) and the code that fills them: every part a study
asks for exists, every part is asked for, and each call gives exactly the fields its part names
(a study's page is built at the end of a long run: a missing field must fail here, not there).
Also the printed tables' helper (``tables.Columns``)."""

import ast
import string
from pathlib import Path

from multigpu.studies import prose as prose_module
from multigpu.studies.tables import Columns

STUDIES = Path(prose_module.__file__).parent


def _calls() -> list[tuple[str, str, set[str], str]]:
    """(name, key, keyword fields, where) of every ``prose(...)`` call in the studies."""
    out = []
    for f in sorted(STUDIES.glob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "prose":
                name, key = (a.value for a in node.args[:2])
                out.append((name, key, {k.arg for k in node.keywords}, f"{f.name}:{node.lineno}"))
    return out


def _fields(template: str) -> set[str]:
    return {f.split(".")[0].split("[")[0] for _, f, _, _ in string.Formatter().parse(template) if f}


def test_every_part_asked_for_exists_and_gets_its_fields():
    calls = _calls()
    assert calls
    for name, key, given, where in calls:
        parts = prose_module.parts(name)
        assert key in parts, f"{where}: no part {key!r} in text/{name}.md"
        assert given == _fields(parts[key]), f"{where}: fields {sorted(given)} for {sorted(_fields(parts[key]))}"


def test_every_part_is_asked_for():
    asked = {(n, k) for n, k, _, _ in _calls()}
    for f in sorted((STUDIES / "text").glob("*.md")):
        for key in prose_module.parts(f.stem):
            assert (f.stem, key) in asked, f"text/{f.name}: part {key!r} is never used"


def test_a_part_is_its_text_without_the_marker_and_trailing_blank_lines(tmp_path, monkeypatch):
    (tmp_path / "t.md").write_text("<!-- part: a -->\nOne {x}.\n\nTwo.\n\n<!-- part: b -->\n Lead space {{kept}}.\n")
    monkeypatch.setattr(prose_module, "TEXT", tmp_path)
    prose_module.parts.cache_clear()
    try:
        assert prose_module.prose("t", "a", x=1) == "One 1.\n\nTwo."
        assert prose_module.prose("t", "b") == " Lead space {kept}."
    finally:
        prose_module.parts.cache_clear()


def test_columns_print_header_and_rows_at_each_columns_width_and_side():
    t = Columns(("scene", "scene", "<6"), ("ms", "wall ms", "8.2f"), ("n", "n", "3d"), ("note", "note", ">5"))
    assert t.header() == "scene   wall ms   n  note"
    assert t.row({"scene": "plant", "ms": 3.14159, "n": 7, "note": "x"}) == "plant      3.14   7     x"
    assert t.row({"scene": "city", "ms": 10.0, "n": 12}) == "city      10.00  12      "  # a missing key: blank
    assert len(t.header()) == len(t.row({"scene": "a", "ms": 1.0, "n": 1, "note": "b"}))
