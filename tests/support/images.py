"""Reading the PNGs a page or a plot holds: decoded pixels, and how much of them is drawn."""

from __future__ import annotations

import base64
import io
import re

import numpy as np
from matplotlib import image as mpimg


def decode_png(png: bytes) -> np.ndarray:
    """RGB(A) floats in [0, 1], shape (height, width, channels)."""
    return mpimg.imread(io.BytesIO(png), format="png")


def ink(pixels: np.ndarray) -> dict[str, float]:
    """How much of an image is drawn: the fraction of pixels not white, and the fraction that
    are saturated colour (the dots and bars, not the black text and grey grid)."""
    rgb = pixels[..., :3]
    not_white = np.any(rgb < 0.95, axis=-1)
    saturation = rgb.max(axis=-1) - rgb.min(axis=-1)
    return {"drawn": float(not_white.mean()), "coloured": float((saturation > 0.3).mean())}


def embedded_pngs(page: str) -> list[bytes]:
    """The PNGs an HTML ``page`` embeds as base64 data URLs, in the page's order."""
    return [base64.b64decode(m) for m in re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)]
