"""The studies' prose, kept as Markdown beside them (``studies/text/NAME.md``) and not in Python
strings: a results section's words are edited as the page they become.

A text file holds one or more parts, each opened by a ``<!-- part: KEY -->`` line; a part is a
``str.format`` template whose fields are the figures and tables the study measured (``{{`` and
``}}`` for a brace). ``prose(name, key, **fields)`` gives one part filled in.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

TEXT = Path(__file__).with_name("text")
PART = re.compile(r"^<!-- part: (?P<key>[\w-]+) -->\n", re.M)


@functools.cache
def parts(name: str) -> dict[str, str]:
    """The parts of ``studies/text/NAME.md`` by key, each without its marker line and the blank
    lines that end it."""
    text = (TEXT / f"{name}.md").read_text()
    marks = list(PART.finditer(text))
    return {m["key"]: text[m.end():(marks[i + 1].start() if i + 1 < len(marks) else len(text))].rstrip("\n")
            for i, m in enumerate(marks)}


def prose(name: str, key: str, **fields) -> str:
    """Part ``key`` of ``studies/text/NAME.md`` with its ``fields`` filled in."""
    return parts(name)[key].format(**fields)
