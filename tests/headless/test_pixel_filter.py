"""Cycles' pixel filters on a supersampled frame (precompute/output/pixel_filter.py), the headless AA.

The filter shapes are Cycles' own definitions (scene/film.cpp), written out again here; the
downsampling is checked against a brute-force double loop over output pixels and sub-samples.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from precompute.output import pixel_filter


def cycles_filter(kind: str, width: float, x):
    """Cycles' filter functions as film.cpp defines them: the table's width is widened (Gaussian
    ×3, Blackman–Harris ×2) and the function is evaluated on [−W/2, W/2] of that width W."""
    x = np.abs(np.asarray(x, dtype=float))
    if kind == "BOX":
        big = width
        f = np.ones_like(x)
    elif kind == "GAUSSIAN":
        big = 3.0 * width
        v = x * 6.0 / big
        f = np.exp(-2.0 * v * v)
    else:
        big = 2.0 * width
        v = 2.0 * math.pi * (x / big + 0.5)
        f = 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v)
    return np.where(x <= 0.5 * big, f, 0.0)


@pytest.mark.parametrize("kind", pixel_filter.FILTERS)
@pytest.mark.parametrize("width", [0.5, 1.0, 1.5, 2.7])
def test_filters_are_cycles_definitions(kind, width):
    """Our pixel filters equal Cycles' definitions (box, Gaussian, Blackman–Harris) and vanish beyond their
    radius, so edges match Cycles' anti-aliasing."""
    x = np.linspace(-5.0, 5.0, 2001)
    np.testing.assert_allclose(
        pixel_filter.filter_weight(kind, width, x), cycles_filter(kind, width, x), atol=1e-15
    )
    r = pixel_filter.radius(kind, width)
    assert np.all(pixel_filter.filter_weight(kind, width, x[np.abs(x) > r]) == 0.0)


def test_default_is_blackman_harris_of_plus_minus_one_and_a_half_pixels():
    kind, width = pixel_filter.DEFAULT_FILTER, pixel_filter.DEFAULT_WIDTH
    assert (kind, width) == ("BLACKMAN_HARRIS", 1.5) and pixel_filter.radius(kind, width) == 1.5
    f = pixel_filter.filter_weight(kind, width, np.array([0.0, 1.5, -1.5]))
    assert f[0] == pytest.approx(1.0, abs=1e-12)  # the four coefficients sum to 1
    assert f[1] == f[2] == pytest.approx(6e-5, abs=1e-6)  # the window's foot at ±w
    assert [
        pixel_filter.margin(k, w) for k, w in (("BLACKMAN_HARRIS", 1.5), ("GAUSSIAN", 1.5), ("BOX", 1.0))
    ] == [
        1,
        2,
        0,
    ]


def test_box_of_one_pixel_is_the_block_mean():
    rng = np.random.default_rng(3)
    img = rng.random((4 * 6, 4 * 9, 3))
    out = pixel_filter.downsample(img, "BOX", 1.0, 4, 0)
    np.testing.assert_allclose(out, img.reshape(6, 4, 9, 4, 3).mean(axis=(1, 3)), atol=1e-14)


@pytest.mark.parametrize(
    ("kind", "width", "factor"), [("BLACKMAN_HARRIS", 1.5, 4), ("GAUSSIAN", 1.5, 3), ("BOX", 2.0, 2)]
)
def test_downsample_is_the_separable_filtered_mean_of_the_subsamples(kind, width, factor):
    rng = np.random.default_rng(7)
    h, w = 5, 7
    pad = pixel_filter.margin(kind, width)
    img = rng.random((factor * (h + 2 * pad), factor * (w + 2 * pad), 2))
    out = pixel_filter.downsample(img, kind, width, factor, pad)
    ys = (np.arange(img.shape[0]) + 0.5) / factor - pad
    xs = (np.arange(img.shape[1]) + 0.5) / factor - pad
    ref = np.zeros((h, w, 2))
    for py in range(h):
        for px in range(w):
            f = np.outer(cycles_filter(kind, width, ys - py - 0.5), cycles_filter(kind, width, xs - px - 0.5))
            ref[py, px] = np.einsum("ij,ijc->c", f, img) / f.sum()
    np.testing.assert_allclose(out, ref, atol=1e-12)
    # Every output pixel's support fits inside the widened window: no weight was cut off.
    full = pixel_filter.weights(kind, width, w, factor, pad)
    raw = cycles_filter(kind, width, xs[None, :] - (np.arange(w) + 0.5)[:, None])
    np.testing.assert_allclose(raw.sum(axis=1), raw.sum(axis=1)[0])
    np.testing.assert_allclose(full.sum(axis=1), 1.0)


def test_a_constant_frame_stays_constant_and_an_edge_is_anti_aliased():
    img = np.full((4 * 12, 4 * 12, 3), 0.25)
    np.testing.assert_allclose(pixel_filter.downsample(img, "BLACKMAN_HARRIS", 1.5, 4, 1), 0.25, atol=1e-14)
    # A vertical edge at x = 4.3 px of the 10 px frame: the filtered row ramps over the support.
    xs = (np.arange(4 * 12) + 0.5) / 4 - 1
    edge = np.broadcast_to((xs > 4.3).astype(float)[None, :, None], (48, 48, 1))
    row = pixel_filter.downsample(edge, "BLACKMAN_HARRIS", 1.5, 4, 1)[5, :, 0]
    assert np.all(np.diff(row) >= -1e-15) and row[0] == pytest.approx(0.0) and row[-1] == pytest.approx(1.0)
    assert 2 <= np.count_nonzero((row > 0.01) & (row < 0.99)) <= 3  # ±1.5 px: a 2–3 px ramp


def test_bad_arguments_are_named():
    """The pixel filter refuses an unknown kind, a zero width or a bad factor with that argument named."""
    with pytest.raises(ValueError, match="kind"):
        pixel_filter.radius("MITCHELL", 1.0)
    with pytest.raises(ValueError, match="width"):
        pixel_filter.radius("BOX", 0.0)
    with pytest.raises(ValueError, match="factor"):
        pixel_filter.downsample(np.zeros((9, 9, 3)), "BOX", 1.0, 4, 0)
