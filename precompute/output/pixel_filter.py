"""Cycles' pixel filters, applied to a supersampled frame: the headless render's anti-aliasing.

Cycles draws each camera sample's offset from the pixel centre from a one-dimensional filter,
independently in x and y (``scene/film.cpp`` builds its importance table, ``kernel/camera``
reads it), so a pixel is the average of the radiance under the separable filter f(x) f(y).
With w the scene's ``filter_width`` in pixels, the three filters and their supports are

- ``BOX``: f = 1 on |x| ≤ w/2;
- ``GAUSSIAN``: f = exp(−8 x² / w²) on |x| ≤ 3w/2 (Cycles evaluates exp(−2 v²) with v = 6x / 3w);
- ``BLACKMAN_HARRIS``: the four-term Blackman–Harris window over |x| ≤ w,
  f = 0.35875 − 0.48829 cos t + 0.14128 cos 2t − 0.01168 cos 3t with t = 2π (x / 2w + ½)
  (Cycles' default, w = 1.5: ±1.5 px).

:func:`downsample` turns a frame rendered ``factor``× larger, over a window widened by
:func:`margin` pixels on each side, into the filtered frame: each output pixel is the
f(x) f(y)-weighted mean of the sub-pixel samples within the support (a separable matrix
product). The widened window lets border pixels see what lies beyond the frame, as Cycles'
rays do.

References
----------
Harris, F. J. (1978). On the use of windows for harmonic analysis with the discrete Fourier
transform. Proc. IEEE 66(1), 51–83 (the four-term window). Blender's Cycles,
``scene/film.cpp`` (filter_func_box / _gaussian / _blackman_harris, filter_table).
"""

from __future__ import annotations

import math

import numpy as np

from .. import _checks

__all__ = [
    "DEFAULT_FILTER",
    "DEFAULT_WIDTH",
    "FILTERS",
    "downsample",
    "filter_weight",
    "margin",
    "radius",
    "weights",
]

FILTERS = ("BOX", "GAUSSIAN", "BLACKMAN_HARRIS")
#: Cycles' defaults (``scene.cycles.pixel_filter_type``, ``filter_width``).
DEFAULT_FILTER = "BLACKMAN_HARRIS"
DEFAULT_WIDTH = 1.5
#: The four Blackman–Harris coefficients (Harris 1978, table 1, "4-term (−92 dB)").
BLACKMAN_HARRIS = (0.35875, 0.48829, 0.14128, 0.01168)


def radius(kind: str, width: float) -> float:
    """Half-width (pixels) of the filter's support: w/2 (box), 3w/2 (Gaussian), w (Blackman–Harris)."""
    _checks.choice("kind", kind, FILTERS)
    w = float(_checks.in_range("width", _checks.finite_array("width", width), lo=0.0, lo_open=True))
    return {"BOX": 0.5, "GAUSSIAN": 1.5, "BLACKMAN_HARRIS": 1.0}[kind] * w


def filter_weight(kind: str, width: float, x) -> np.ndarray:
    """f(x) of the filter at offsets ``x`` (pixels, any shape), 0 outside its support (unnormalised)."""
    r = radius(kind, width)
    x = np.asarray(x, dtype=float)
    if kind == "BOX":
        f = np.ones_like(x)
    elif kind == "GAUSSIAN":
        f = np.exp(-8.0 * x * x / (width * width))
    else:
        t = 2.0 * math.pi * (x / (2.0 * width) + 0.5)
        a0, a1, a2, a3 = BLACKMAN_HARRIS
        f = a0 - a1 * np.cos(t) + a2 * np.cos(2.0 * t) - a3 * np.cos(3.0 * t)
    return np.where(np.abs(x) <= r, f, 0.0)


def margin(kind: str, width: float) -> int:
    """Pixels to render beyond each edge of the frame so that border pixels see their whole support."""
    return int(math.ceil(radius(kind, width) - 0.5))


def weights(kind: str, width: float, size: int, factor: int, pad: int) -> np.ndarray:
    """(size, factor·(size + 2·pad)) resampling matrix of one axis, rows summing to 1.

    Sub-sample i of the widened, ``factor``× finer axis has its centre at (i + ½)/factor − pad in
    output pixels; output pixel p (centre p + ½) weights it by f(centre_i − p − ½). A support too
    narrow to hold any sub-sample centre (a box much narrower than 1/factor) takes the nearest.
    """
    size = _checks.positive_int("size", size)
    factor = _checks.positive_int("factor", factor)
    pad = _checks.positive_int("pad", pad, minimum=0)
    centres = (np.arange(factor * (size + 2 * pad)) + 0.5) / factor - pad
    offsets = centres[None, :] - (np.arange(size) + 0.5)[:, None]
    w = filter_weight(kind, width, offsets)
    empty = w.sum(axis=1) <= 0.0
    if np.any(empty):
        nearest = np.argmin(np.abs(offsets[empty]), axis=1)
        w[np.flatnonzero(empty), nearest] = 1.0
    return w / w.sum(axis=1, keepdims=True)


def downsample(image, kind: str, width: float, factor: int, pad: int) -> np.ndarray:
    """The filtered frame (H, W, C) of a ``factor``× supersampled image of the widened window.

    ``image``: (factor·(H + 2·pad), factor·(W + 2·pad), C), top row first; ``pad``: the margin in
    output pixels it was rendered with (:func:`margin`).
    """
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 3:
        raise ValueError(f"image must be (H, W, C), got shape {img.shape}")
    h, w = img.shape[0] // factor - 2 * pad, img.shape[1] // factor - 2 * pad
    if h < 1 or w < 1 or img.shape[0] != factor * (h + 2 * pad) or img.shape[1] != factor * (w + 2 * pad):
        raise ValueError(f"image shape {img.shape[:2]} is not factor {factor} × (frame + 2·{pad})")
    wy = weights(kind, width, h, factor, pad)
    wx = weights(kind, width, w, factor, pad)
    return np.einsum("ph,hwc,qw->pqc", wy, img, wx, optimize=True)
