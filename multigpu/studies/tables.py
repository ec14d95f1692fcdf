"""CSV and Markdown tables for the measurement reports (experiments, accuracy)."""

from __future__ import annotations

import csv
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
