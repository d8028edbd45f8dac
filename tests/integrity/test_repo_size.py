"""The generated outputs a checkout carries stay small (issue #43): the pages, tables,
figures and compact rows under leaderboard/ and reports/ together at most 10 MB. Raw
outputs (the leaderboard's cells, walk-eval's per-trial report.json, ...) are written
again by the command their page names and are not committed (.gitignore)."""

import subprocess
from pathlib import Path


REPO = Path(__file__).resolve().parents[2]
FOLDERS = ("leaderboard", "reports")
LIMIT_BYTES = 10_000_000


def _git(*args: str) -> list[str]:
    out = subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, check=True).stdout
    return [p for p in out.decode().split("\0") if p]


def committed_outputs() -> dict[str, int]:
    """Size of each file under FOLDERS a commit of this checkout would hold: tracked, or
    new and not ignored; only those on disk (a file deleted but not yet `git rm`ed does
    not count)."""
    names = set(_git("ls-files", "-z", "--", *FOLDERS))
    names |= set(_git("ls-files", "-z", "--others", "--exclude-standard", "--", *FOLDERS))
    return {n: (REPO / n).stat().st_size for n in sorted(names) if (REPO / n).is_file()}


def test_the_committed_outputs_stay_under_10_mb():
    # The tests run from a checkout (they are not installed): without git this fails, loudly.
    sizes = committed_outputs()
    total = sum(sizes.values())
    biggest = sorted(sizes.items(), key=lambda kv: -kv[1])[:10]
    assert sizes and total <= LIMIT_BYTES, (
        f"{total / 1e6:.2f} MB in {len(sizes)} files under {'/, '.join(FOLDERS)}/ (limit {LIMIT_BYTES / 1e6:.2f} MB); "
        "the biggest: " + ", ".join(f"{n} {s / 1e6:.2f} MB" for n, s in biggest))


def test_an_opaque_figure_is_saved_without_its_alpha_channel(tmp_path):
    """Figures are most of what is committed: an opaque one is written as RGB (the same
    pixels as matplotlib's RGBA, a tenth fewer bytes); a PNG with any transparency is
    left as it is."""
    import io

    import numpy as np
    from PIL import Image

    from legcal_bench.files.plots import opaque_png, pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(2, 1.5))
    ax.plot([0, 1, 2], [1, 0, 2])
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=50, metadata={"Software": None})
    rgba = Image.open(io.BytesIO(buf.getvalue()))
    path = save_figure(fig, tmp_path / "f.png", dpi=50)
    saved = Image.open(path)
    assert rgba.mode == "RGBA" and saved.mode == "RGB" and path.stat().st_size < len(buf.getvalue())
    assert np.array_equal(np.asarray(saved), np.asarray(rgba)[..., :3])
    clear = np.asarray(rgba).copy()
    clear[0, 0, 3] = 0
    out = io.BytesIO()
    Image.fromarray(clear).save(out, format="PNG")
    assert opaque_png(out.getvalue()) == out.getvalue()


def test_a_report_json_is_a_row_per_line_and_reads_back_the_same(tmp_path):
    import json

    from legcal_bench.files.reports import report_data, write_report

    data = {"made_by": "legcal-bench x", "rows": [{"b": 1.0000000000000002, "a": [1, 2]}, {"a": float("nan")}],
            "summary": [], "code": {"commit": "abc"}}
    write_report(tmp_path, "# page\n", data)
    text = report_data(tmp_path).read_text()
    back = json.loads(text)
    assert back["rows"][0] == data["rows"][0] and back["code"] == data["code"] and back["summary"] == []
    assert text.splitlines() == ["{", '"code":{"commit":"abc"},', '"made_by":"legcal-bench x",', '"rows":[',
                                 '{"a":[1,2],"b":1.0000000000000002},', '{"a":NaN}', "],", '"summary":[]', "}"]
