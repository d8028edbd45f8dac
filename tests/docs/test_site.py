"""The documentation site builds in strict mode (`make docs`): a broken link, a page
missing from the nav's files or a failing generated page fails here. The generated pages
(the command line from the parser, the results from the committed leaderboard) are made
at build time by docs/hooks.py, so a built site cannot hold a stale copy; the test also
checks they are there and hold what they are generated from."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_the_site_builds_strict_with_its_generated_pages(tmp_path):
    site = tmp_path / "site"
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)], cwd=REPO,
                         capture_output=True, text=True, env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"})
    assert run.returncode == 0, run.stderr[-4000:]
    cli = (site / "reference" / "cli" / "index.html").read_text()
    from legcal_bench.cli.groups import grouped_commands

    for command in grouped_commands():  # every command documented, from the parser
        assert f"legcal-bench {command}" in cli, command
    results = (site / "results" / "index.html").read_text()
    assert "legcal-bench leaderboard" in results  # the committed leaderboard's page
    assert (site / "guides" / "benchmark" / "index.html").is_file() and (site / "log-import" / "index.html").is_file()
