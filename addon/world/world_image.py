"""A World image's pixels as the SH projection reads them: decoded to scene linear, downsampled.

:func:`image_pixels` reads an Environment Texture's pixels (no copy of Blender's buffer) and
says how to make them linear RGB in the working space (sRGB decoding, a 3 × 3 matrix between
linear spaces; other colour spaces are not converted here: ``Fallback``, the World is then
rendered as a panorama); :func:`project_image` projects an equirect onto SH in strips, each
downsampled (solid-angle correct) to at most :data:`MAX_PROJECTION_WIDTH` first. Used by
:mod:`.world` (the read on the main thread, the projection anywhere).
"""

from __future__ import annotations

import numpy as np

from ...precompute.sh import projection
from ...precompute.world import hdri
from .world_nodes import Fallback

__all__ = ["MAX_PROJECTION_WIDTH", "image_pixels", "project_image", "srgb_to_linear"]

#: Images wider than this are downsampled (solid-angle-correct, :func:`hdri.downsample`) before
#: projection. 1024 px across 2π resolves bands far beyond the l ≤ 12 the preview uses.
MAX_PROJECTION_WIDTH = 1024

_LINEAR_SPACES = ("Linear Rec.709", "Linear Rec.2020", "ACEScg")


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding (the piecewise curve of Blender's "sRGB" space)."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((np.maximum(v, 0.04045) + 0.055) / 1.055) ** 2.4)


def _rgb_matrix(source: str, target: str) -> np.ndarray | None:
    """Linear RGB → RGB matrix between two working spaces, or None if it cannot be built here."""
    if source == target:
        return np.eye(3)
    try:  # a failed import of the spectral code must not break the World's SH
        from ...precompute.colour import rgb_spaces
    except ImportError:
        return None
    try:
        return rgb_spaces.rgb_to_rgb_matrix(source, target)
    except ValueError:
        return None


# ----------------------------------------------------------------------------------------------
# Pixels
# ----------------------------------------------------------------------------------------------


def image_pixels(image, space: str):
    """The image's pixels and how to make them scene linear; raises Fallback or OSError.

    Returns ``(rgb, convert)``: ``rgb`` a float32 (H, W, 3) view, top row first, onto the
    buffer read from Blender (no copy), and ``convert`` None or a function that turns a block
    of it into linear RGB in ``space`` (applied block by block, to bound memory).
    """
    width, height = image.size[:]
    channels = image.channels
    if width == 0 or height == 0 or not image.has_data:
        raise OSError("no pixels could be loaded")
    buf = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(buf)
    pixels = buf.reshape(height, width, channels)[::-1]  # Blender stores the bottom row first
    if channels >= 3:
        rgb = pixels[..., :3]
    else:  # grey (and grey + alpha) images
        rgb = np.broadcast_to(pixels[..., :1], (height, width, 3))
    if image.is_float:  # Blender converts float buffers to scene linear when it loads them
        return rgb, None
    name = image.colorspace_settings.name
    if image.colorspace_settings.is_data or name == "Non-Color":
        return rgb, None  # data: the numbers are used as they are
    if name == "sRGB":
        decode, primaries = srgb_to_linear, "Linear Rec.709"
    elif name in _LINEAR_SPACES:
        decode, primaries = None, name
    else:
        raise Fallback(f"image color space '{name}'")
    matrix = _rgb_matrix(primaries, space)
    if matrix is None:
        raise Fallback(f"image color space '{name}' in working space '{space}'")
    if decode is None and primaries == space:
        return rgb, None

    def convert(block: np.ndarray) -> np.ndarray:
        linear = decode(block) if decode is not None else block.astype(np.float64)
        return linear @ matrix.T if primaries != space else linear

    return rgb, convert


def _downsample_factor(height: int, width: int) -> int:
    """Smallest integer factor dividing both sizes that brings the width to ≤ MAX_PROJECTION_WIDTH."""
    start = max(1, -(-width // MAX_PROJECTION_WIDTH))
    for factor in range(start, 4 * start + 1):
        if height % factor == 0 and width % factor == 0:
            return factor
    return 1  # no divisor nearby: project at full resolution (exact, only slower)


#: Pixels converted and downsampled at a time (bounds the float64 temporaries to ~100 MB).
_BLOCK_PIXELS = 1 << 22


def project_image(rgb: np.ndarray, l_max: int, convert=None) -> tuple[np.ndarray, int, np.ndarray]:
    """Project a top-first equirect (after ``convert``), downsampled to ≤ MAX_PROJECTION_WIDTH.

    Returns the coefficients, the rejected pixel count and the downsampled image (float64).

    The image is processed in strips of whole columns: :func:`hdri.downsample` weighs rows by
    their solid angle, and a column strip keeps every row, so each strip's result is exactly
    that part of the whole image's. NaN/Inf pixels are set to zero and counted at full size.
    """
    height, width = rgb.shape[:2]
    factor = _downsample_factor(height, width)
    step = max(factor, (_BLOCK_PIXELS // max(height, 1)) // factor * factor)
    small = np.empty((height // factor, width // factor, 3), dtype=np.float64)
    rejected = 0
    for c0 in range(0, width, step):
        c1 = min(width, c0 + step)
        block = rgb[:, c0:c1]
        if convert is not None:
            block = convert(block)
        good = np.isfinite(block).all(axis=-1)
        if not good.all():
            rejected += int(good.size - np.count_nonzero(good))
            block = np.where(good[..., None], block, 0.0)
        small[:, c0 // factor : c1 // factor] = hdri.downsample(block, factor)
    coeffs, info = projection.project_equirect(small, l_max, return_info=True)
    return coeffs, rejected + int(info["rejected_pixels"]), small
