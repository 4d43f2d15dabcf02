"""Equirectangular HDRI environments: reading, geometry, downsampling, reference irradiance.

Geometry follows Blender's Environment Texture (``docs/conventions.md``): arrays are stored
top row first, shape (H, W, C); column c ↔ u = (c + ½)/W, φ = atan2(y, x) = 2π(½ − u)
(the image centre looks along +x, u = ¼ along +y); row r ↔ v = 1 − (r + ½)/H, θ = π(1 − v)
(the top row looks up, +z). A pixel subtends exactly (2π/W)(cos θ_top − cos θ_bottom).

The ``OpenEXR`` package is imported lazily in :func:`read_equirect`, so the geometry helpers
work where it is not installed (e.g. inside Blender).
"""

from __future__ import annotations

import os

import numpy as np

from .. import _checks

#: Pixels per block in :func:`irradiance_brute_force`: bounds the (normals × pixels) cosine
#: matrix to 200 × 65536 × 8 B ≈ 100 MB for the usual 200 normals.
_BRUTE_FORCE_CHUNK = 65536

__all__ = [
    "downsample",
    "equirect_azimuths",
    "equirect_directions",
    "equirect_lookup",
    "equirect_polar",
    "equirect_row_solid_angles",
    "equirect_solid_angles",
    "fibonacci_sphere",
    "irradiance_brute_force",
    "read_equirect",
]


# ----------------------------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------------------------


def _check_size(name: str, value) -> int:
    return _checks.positive_int(name, value, minimum=1)


def equirect_azimuths(width: int) -> np.ndarray:
    """φ of each column centre, φ_c = 2π(½ − (c + ½)/W) in radians, shape (W,)."""
    width = _check_size("width", width)
    u = (np.arange(width) + 0.5) / width
    return 2.0 * np.pi * (0.5 - u)


def equirect_polar(height: int) -> tuple[np.ndarray, np.ndarray]:
    """(cos θ_r, sin θ_r) of each row centre, θ_r = π (r + ½)/H (row 0 is the top), shape (H,)."""
    height = _check_size("height", height)
    theta = np.pi * (np.arange(height) + 0.5) / height
    return np.cos(theta), np.sin(theta)


def equirect_row_solid_angles(height: int, width: int) -> np.ndarray:
    """Solid angle of one pixel in each row, (2π/W)(cos θ_top − cos θ_bottom) in sr, shape (H,).

    Exact for the pixel's (θ, φ) rectangle; the rows sum to 4π/W.
    """
    height = _check_size("height", height)
    width = _check_size("width", width)
    edges = np.cos(np.pi * np.arange(height + 1) / height)
    return (2.0 * np.pi / width) * (edges[:-1] - edges[1:])


def equirect_solid_angles(height: int, width: int) -> np.ndarray:
    """Per-pixel solid angle in sr, shape (H, W); sums to 4π (to rounding)."""
    rows = equirect_row_solid_angles(height, width)
    return np.broadcast_to(rows[:, None], (rows.shape[0], int(width))).copy()


def equirect_directions(height: int, width: int) -> np.ndarray:
    """Unit direction of each pixel centre, shape (H, W, 3), in Blender world space (z up)."""
    cos_t, sin_t = equirect_polar(height)
    phi = equirect_azimuths(width)
    return np.stack(
        np.broadcast_arrays(
            sin_t[:, None] * np.cos(phi)[None, :],
            sin_t[:, None] * np.sin(phi)[None, :],
            cos_t[:, None],
        ),
        axis=-1,
    )


def equirect_lookup(image: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Bilinear radiance lookup in an equirect image (H, W, 3), conventions.md mapping.

    Wraps around in u; rows clamp at the poles. Used by the prefilter, the split sum's level
    lookup and the ground truth alike (glsl/tf_background_frag.glsl reads the same mapping).
    """
    h, w = image.shape[:2]
    d = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)
    theta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    x = u * w - 0.5
    y = theta / np.pi * h - 0.5
    x0 = np.floor(x).astype(int)
    y0 = np.clip(np.floor(y).astype(int), 0, h - 1)
    fx, fy = (x - x0)[..., None], np.clip(y - y0, 0.0, 1.0)[..., None]
    y1 = np.clip(y0 + 1, 0, h - 1)
    x0w, x1w = x0 % w, (x0 + 1) % w
    return (1 - fy) * ((1 - fx) * image[y0, x0w] + fx * image[y0, x1w]) + fy * (
        (1 - fx) * image[y1, x0w] + fx * image[y1, x1w]
    )


def fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` near-uniform unit vectors on the sphere (golden-angle spiral), shape (count, 3).

    z_k = 1 − (2k + 1)/count, φ_k = k · π(3 − √5).
    """
    count = _check_size("count", count)
    k = np.arange(count)
    z = 1.0 - (2.0 * k + 1.0) / count
    rho = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=-1)


# ----------------------------------------------------------------------------------------------
# I/O and resampling
# ----------------------------------------------------------------------------------------------


def _rgb_from_channels(channels: dict, path: str) -> np.ndarray:
    """Pick R, G, B out of an ``OpenEXR.File.channels()`` dict (grouped or separate)."""
    for key in ("RGB", "RGBA"):
        if key in channels:
            return np.asarray(channels[key].pixels)[..., :3]
    if all(c in channels for c in "RGB"):
        return np.stack([np.asarray(channels[c].pixels) for c in "RGB"], axis=-1)
    raise ValueError(f"path {path!r} has no R, G, B channels (found {sorted(channels)})")


def read_equirect(path) -> np.ndarray:
    """Read an equirectangular OpenEXR as float32 RGB, shape (H, W, 3), top row first.

    Alpha and other channels are dropped; NaN/Inf pixels are kept (:func:`sh.project_equirect`
    rejects and counts them).

    Parameters
    ----------
    path : str or os.PathLike

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    ValueError
        ``path`` is not a readable OpenEXR file, or has no R, G, B channels.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"path {path!r} does not exist")
    with open(path, "rb") as handle:
        magic = handle.read(4)
    if magic != b"\x76\x2f\x31\x01":  # OpenEXR magic number 20000630, little-endian
        raise ValueError(f"path {path!r} is not an OpenEXR file")
    import OpenEXR  # lazy: only needed for reading files

    try:
        exr = OpenEXR.File(path)
        channels = exr.channels()
    except Exception as exc:  # the binding raises RuntimeError/others for corrupt files
        raise ValueError(f"path {path!r} could not be read as OpenEXR: {exc}") from exc
    rgb = _rgb_from_channels(channels, path)
    if rgb.ndim != 3:
        raise ValueError(f"path {path!r} has unexpected pixel shape {rgb.shape}")
    return np.ascontiguousarray(rgb, dtype=np.float32)


def downsample(image, factor: int) -> np.ndarray:
    """Shrink an equirect image by an integer ``factor`` in each axis, conserving ∫ L dω.

    Each output pixel is the solid-angle-weighted mean of its factor × factor input block:
    within a block columns weigh equally and rows by their solid angle (cos θ_top − cos θ_bot),
    so Σ L_out dω_out = Σ L_in dω_in exactly for each block (a plain box average would
    over-weight the rows nearer the poles by up to ~factor² at the top row). NaN/Inf in a block
    propagate to its output pixel, which :func:`sh.project_equirect` then rejects.

    Parameters
    ----------
    image : array_like, shape (H, W, C) or (H, W)
        H and W must be multiples of ``factor``.
    factor : int
        ≥ 1.

    Returns
    -------
    ndarray, shape (H/factor, W/factor[, C]), float32 for float32 input, else float64.
    """
    factor = _checks.positive_int("factor", factor, minimum=1)
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must have shape (H, W, C) or (H, W), got {img.shape}")
    height, width = img.shape[:2]
    if height % factor or width % factor:
        raise ValueError(f"factor must divide the image size {height}×{width}, got {factor}")
    out_dtype = np.float32 if img.dtype == np.float32 else np.float64
    if factor == 1:
        return img.astype(out_dtype, copy=True)
    squeeze = img.ndim == 2
    data = img.astype(np.float64)[..., None] if squeeze else img.astype(np.float64)
    rows = equirect_row_solid_angles(height, width)  # (H,), the 2π/W factor cancels
    blocks = data.reshape(height // factor, factor, width // factor, factor, data.shape[-1])
    weights = rows.reshape(height // factor, factor)
    summed = np.einsum("ab,abcdk->ack", weights, blocks) / factor
    out = summed / weights.sum(axis=1)[:, None, None]
    if squeeze:
        out = out[..., 0]
    return out.astype(out_dtype)


# ----------------------------------------------------------------------------------------------
# Reference irradiance
# ----------------------------------------------------------------------------------------------


def irradiance_brute_force(image, normals) -> np.ndarray:
    """Irradiance E(n) = Σ_pixels L(ω) max(0, n·ω) dω of an equirect environment.

    The slow reference that SH irradiance is checked against: the same pixel-centre quadrature
    as :func:`sh.project_equirect`, but without truncating the clamped cosine to any band.

    Parameters
    ----------
    image : array_like, shape (H, W, C) or (H, W)
        Radiance, finite.
    normals : array_like, shape (N, 3)
        Unit normals (normalised here).

    Returns
    -------
    ndarray, shape (N, C) or (N,): irradiance in radiance units × sr.
    """
    img = _checks.finite_array("image", image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must have shape (H, W, C) or (H, W), got {img.shape}")
    n = _checks.finite_array("normals", normals)
    if n.ndim != 2 or n.shape[1] != 3:
        raise ValueError(f"normals must have shape (N, 3), got {n.shape}")
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    height, width = img.shape[:2]
    dirs = equirect_directions(height, width).reshape(-1, 3)
    d_omega = equirect_solid_angles(height, width).reshape(-1)
    radiance = img.reshape(height * width, -1) * d_omega[:, None]
    out = np.zeros((n.shape[0], radiance.shape[1]))
    for start in range(0, height * width, _BRUTE_FORCE_CHUNK):
        stop = start + _BRUTE_FORCE_CHUNK
        cosines = np.maximum(0.0, n @ dirs[start:stop].T)  # (N, chunk)
        out += cosines @ radiance[start:stop]
    return out[:, 0] if img.ndim == 2 else out
