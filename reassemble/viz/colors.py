"""Colours shared by every picture and output file (uint8 RGB)."""

from __future__ import annotations

import colorsys

import numpy as np

FRACTURE_RGB = np.array([214, 69, 50], np.uint8)
ORIGINAL_RGB = np.array([190, 190, 190], np.uint8)
BACKGROUND_RGB = np.array([255, 255, 255], np.uint8)

# diverging blue - white - red (ColorBrewer RdBu, reversed): concave < 0 < convex
_DIVERGING = np.array([[33, 102, 172], [103, 169, 207], [209, 229, 240], [247, 247, 247],
                       [253, 219, 199], [239, 138, 98], [178, 24, 43]], float)


def fragment_colors(n: int) -> np.ndarray:
    """(n, 3) uint8 distinct colours (hues a golden angle apart), the same for the same n."""
    return np.array([[round(255 * c) for c in colorsys.hsv_to_rgb((0.61803398875 * k) % 1.0, 0.55, 0.9)]
                     for k in range(n)], dtype=np.uint8)


def diverging(values: np.ndarray, limit: float) -> np.ndarray:
    """(n, 3) uint8 colours of ``values`` on a blue-white-red scale from -limit to +limit
    (clipped); NaN values are grey."""
    values = np.asarray(values, dtype=float)
    t = np.clip((np.nan_to_num(values) / max(limit, 1e-300) + 1.0) / 2.0, 0.0, 1.0) * (len(_DIVERGING) - 1)
    lo = np.minimum(np.floor(t).astype(int), len(_DIVERGING) - 2)
    w = (t - lo)[:, None]
    rgb = (1 - w) * _DIVERGING[lo] + w * _DIVERGING[lo + 1]
    rgb[~np.isfinite(values)] = ORIGINAL_RGB
    return np.round(rgb).astype(np.uint8)


def shade(rgb: np.ndarray, factor: float) -> np.ndarray:
    """``rgb`` (..., 3) uint8 darkened (factor < 1) or lightened towards white (factor > 1)."""
    rgb = np.asarray(rgb, dtype=float)
    out = rgb * factor if factor <= 1 else rgb + (255 - rgb) * (factor - 1)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


__all__ = ["BACKGROUND_RGB", "FRACTURE_RGB", "ORIGINAL_RGB", "diverging", "fragment_colors", "shade"]
