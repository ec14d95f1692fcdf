"""CSV and Markdown tables for the measurement reports (experiments, accuracy)."""

from __future__ import annotations

import csv
import re
from pathlib import Path


def write_csv(path: Path, rows: list[dict], fmt: str = ".6g") -> None:
    """``rows`` (dicts with the same keys) as CSV; floats in ``fmt`` (6 significant digits)."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (format(v, fmt) if isinstance(v, float) else v) for k, v in r.items()})


def md_table(rows: list[dict], cols: list[tuple[str, str, str]]) -> str:
    """Markdown table of ``rows`` with ``cols`` = (key, header, format spec or '')."""
    head = "| " + " | ".join(h for _, h, _ in cols) + " |"
    sep = "|" + "|".join("---:" for _ in cols) + "|"
    body = ["| " + " | ".join(format(r[k], f) if f else str(r[k]) for k, _, f in cols) + " |" for r in rows]
    return "\n".join([head, sep, *body])


class Columns:
    """A table printed a row at a time, as a benchmark measures its rows: each column is (key,
    header, spec), the spec a format spec with its width ('8.3f', '>9', '<6': left-aligned); a
    header takes its column's width and side. The one way the studies print a table."""

    def __init__(self, *cols: tuple[str, str, str]):
        self.cols = cols

    @staticmethod
    def _side(spec: str) -> tuple[str, int]:
        m = re.match(r"([<>^]?)[+\- ]?0?(\d*)", spec)
        return (m.group(1) or ">"), int(m.group(2) or 0)

    def header(self) -> str:
        return " ".join(f"{h:{side}{width}}" for _, h, spec in self.cols for side, width in [self._side(spec)])

    def row(self, values: dict) -> str:
        """A row from ``values`` by key (a key missing: blank at the column's width)."""
        return " ".join(format(values[k], spec) if k in values else " " * self._side(spec)[1]
                        for k, _, spec in self.cols)
