"""A person's appearance cue: a colour histogram of the mask's pixels.

Hue and saturation (12 × 4 bins) for the coloured pixels, plus 4 brightness bins for the
grey ones (saturation or value too low for hue to mean anything), normalised to sum 1, so
a shirt and trousers give a signature that survives distance and pose. Compared with the
Bhattacharyya distance (0 identical, 1 disjoint), as in classic person re-identification.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from common.geometry import FloatArray

HUE_BINS = 12
SAT_BINS = 4
GREY_BINS = 4
SIZE = HUE_BINS * SAT_BINS + GREY_BINS
#: Saturation and value (0-255) below which a pixel counts as grey.
MIN_SAT = 40
MIN_VAL = 40


def colour_histogram(
    rgb: NDArray[np.uint8], bbox: tuple[int, int, int, int], mask: NDArray[np.uint8]
) -> FloatArray | None:
    """The histogram of the pixels of `mask` (a crop of `bbox` = u0, v0, u1, v1) in `rgb`;
    None when the mask does not fit the image or selects fewer than 20 pixels."""
    u0, v0, u1, v1 = bbox
    h, w = rgb.shape[:2]
    if not (0 <= u0 < u1 <= w and 0 <= v0 < v1 <= h) or mask.shape != (v1 - v0, u1 - u0):
        return None
    crop = np.ascontiguousarray(rgb[v0:v1, u0:u1])
    pixels = cv2.cvtColor(crop, cv2.COLOR_RGB2HSV)[mask > 0]
    if len(pixels) < 20:
        return None
    hue, sat, val = (pixels[:, k].astype(int) for k in range(3))
    coloured = (sat >= MIN_SAT) & (val >= MIN_VAL)
    hist = np.zeros(SIZE)
    hb = np.minimum(hue[coloured] * HUE_BINS // 180, HUE_BINS - 1)
    sb = np.minimum((sat[coloured] - MIN_SAT) * SAT_BINS // (256 - MIN_SAT), SAT_BINS - 1)
    np.add.at(hist, hb * SAT_BINS + sb, 1.0)
    gb = np.minimum(val[~coloured] * GREY_BINS // 256, GREY_BINS - 1)
    np.add.at(hist, HUE_BINS * SAT_BINS + gb, 1.0)
    return hist / hist.sum()


def bhattacharyya(a: FloatArray, b: FloatArray) -> float:
    """Distance between two normalised histograms: 0 identical, 1 disjoint."""
    bc = float(np.sum(np.sqrt(np.clip(a, 0, None) * np.clip(b, 0, None))))
    return float(np.sqrt(max(0.0, 1.0 - min(bc, 1.0))))


def blend(model: FloatArray | None, new: FloatArray, rate: float = 0.2) -> FloatArray:
    """A track's appearance model after one more view (an exponential average)."""
    if model is None or model.shape != new.shape:
        return new.copy()
    out = (1.0 - rate) * model + rate * new
    return out / out.sum()
