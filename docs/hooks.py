"""MkDocs hooks: the generated pages, made at build time from their sources so that a
built site cannot hold a stale copy.

- `reference/cli.md`: the command line, from the parser (`legcal_bench.cli.reference`).
- `results/...`: the committed leaderboard (`leaderboard/`: its generated pages and
  plots), under the same relative paths, so its own links hold.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "leaderboard"


def on_files(files: Files, config) -> Files:
    from legcal_bench.cli.reference import markdown

    files.append(File.generated(config, "reference/cli.md", content=markdown()))
    for path in sorted(RESULTS.rglob("*")):
        if path.suffix in (".md", ".png") and path.is_file():
            files.append(File.generated(config, f"results/{path.relative_to(RESULTS).as_posix()}",
                                        abs_src_path=str(path)))
    return files
