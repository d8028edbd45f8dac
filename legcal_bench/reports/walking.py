"""Pictures of walks: an image strip of rendered frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_strip(frames: list[np.ndarray], path: str | Path, every_s: float, max_frames: int = 11) -> Path:
    """Frames side by side (every `every_s` seconds, at most `max_frames`), each labelled
    with its time, as one PNG (atomic)."""
    from PIL import Image, ImageDraw

    from legcal_bench.files.atomic import atomic_write

    frames = frames[:max_frames]
    h, w = frames[0].shape[:2]
    strip = Image.new("RGB", (w * len(frames), h), "white")
    draw = ImageDraw.Draw(strip)
    for k, f in enumerate(frames):
        strip.paste(Image.fromarray(f), (k * w, 0))
        draw.text((k * w + 8, 8), f"t = {k * every_s:.1f} s", fill=(0, 0, 0))
    return atomic_write(path, lambda fh: strip.save(fh, format="PNG"), mode="wb")
