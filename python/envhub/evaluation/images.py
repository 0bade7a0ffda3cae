"""Images as the evaluation's protocols and policy servers resize them (a leaf module: the
benchmark's protocol and the servers' layouts both use it)."""

from __future__ import annotations

import numpy as np

__all__ = ["resize_with_pad"]


def resize_with_pad(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """`image` (H, W, C) uint8 scaled to fit (height, width), centred on black, as
    vla-eval's and OpenPI's `resize_with_pad` do."""
    if image.shape[:2] == (height, width):
        return image
    from PIL import Image

    pil = Image.fromarray(np.ascontiguousarray(image))
    w, h = pil.size
    ratio = max(w / width, h / height)
    rw, rh = int(w / ratio), int(h / ratio)
    resized = pil.resize((rw, rh), resample=Image.Resampling.BILINEAR)
    canvas = Image.new(resized.mode, (width, height), 0)
    canvas.paste(resized, (max(0, (width - rw) // 2), max(0, (height - rh) // 2)))
    return np.asarray(canvas)
