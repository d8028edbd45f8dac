"""A report is a markdown page and the JSON it was made from, side by side (the JSON a
row per line, `rows_json`: compact enough to commit beside the page)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from legcal_bench.files.atomic import atomic_write_text, rows_json


def report_data(out: str | Path, name: str = "report") -> Path:
    """The JSON file of the report `write_report` writes into `out`."""
    return Path(out) / f"{name}.json"


def report_page(out: str | Path, name: str = "report") -> Path:
    """The markdown page of the report `write_report` writes into `out`."""
    return Path(out) / f"{name}.md"


def write_report(out: str | Path, markdown: str, data: Any, name: str = "report") -> str:
    """Write `<out>/<name>.md` and `<out>/<name>.json` atomically; returns the markdown."""
    out = Path(out)
    atomic_write_text(report_data(out, name), rows_json(data))
    atomic_write_text(report_page(out, name), markdown)
    return markdown
