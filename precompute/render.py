"""Per-pixel shading with baked tables, in numpy: the shader's reference and a spectral ground truth.

``shade_sh`` does exactly what ``glsl/`` does per pixel (and is what the GLSL is tested
against): build the view-aligned frame, rotate the World's SH into it with z-y-z Euler angles
(y-rotations as fixed ±90° x-rotations around a z-rotation, Kautz, Sloan & Snyder 2002 §4), look
the table up at θo (and thickness) with linear interpolation, and sum M_i · L_i.

``shade_reference`` is the brute-force ground truth with no SH at all: per pixel, the exact
spectral BRDF integrated against the environment map by half-vector quadrature.

Scenes here are a sphere seen by a pinhole camera, for the CLI preview, the accuracy benchmark
and the tests.
"""

from __future__ import annotations

import functools
import math
import struct
import zlib
from dataclasses import dataclass

import numpy as np

from . import bake, brdf, constants, sh
from .hdri import downsample

#: sin β below which the normal is treated as ±z (gimbal): the z-y-z split is then a single
#: z-rotation. 1e-7 rad is far below any table or texture resolution.
GIMBAL_SIN = 1e-7


# ----------------------------------------------------------------------------------------------
# Frames and SH rotation
# ----------------------------------------------------------------------------------------------
def view_aligned_frame(normals, views) -> np.ndarray:
    """Rows (x, y, z) of the view-aligned frame, shape (…, 3, 3): z = n, x = normalise(v − n(n·v)).

    When v ∥ n the BRDF slice is rotationally symmetric, so any x works; we take the tangent
    closest to world +x (or +y when n ∥ x) so the result is continuous and never NaN.
    """
    n = np.asarray(normals, dtype=float)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    v = np.asarray(views, dtype=float)
    t = v - n * np.sum(n * v, axis=-1, keepdims=True)
    tl = np.linalg.norm(t, axis=-1, keepdims=True)
    helper = np.where(np.abs(n[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    fallback = helper - n * np.sum(n * helper, axis=-1, keepdims=True)
    t = np.where(tl > 1e-9, t, fallback)
    x = t / np.linalg.norm(t, axis=-1, keepdims=True)
    y = np.cross(n, x)
    return np.stack([x, y, n], axis=-2)


def zyz_from_frame(frame) -> tuple[np.ndarray, ...]:
    """(cos, sin) of a, b, c with frame = Rz(a) Ry(b) Rz(c); each array of shape (…).

    From the matrix entries: cos b = r22, a = atan2(r12, r02), c = atan2(r21, −r20). At the poles
    (sin b ≈ 0) c = 0 and a carries the whole z-rotation.
    """
    r = np.asarray(frame)
    cb = np.clip(r[..., 2, 2], -1.0, 1.0)
    sb = np.sqrt(np.maximum(0.0, 1.0 - cb * cb))
    pole = sb < GIMBAL_SIN
    ax, ay = r[..., 0, 2], r[..., 1, 2]
    cx, cy = -r[..., 2, 0], r[..., 2, 1]
    # Pole: R = Rz(a + c) (b = 0) or Rz(a) Ry(π) Rz(c) (b = π, r00 = −cos(a − c)).
    px = np.where(cb > 0, r[..., 0, 0], -r[..., 0, 0])
    py = np.where(cb > 0, r[..., 1, 0], -r[..., 1, 0])
    ax, ay = np.where(pole, px, ax), np.where(pole, py, ay)
    cx, cy = np.where(pole, 1.0, cx), np.where(pole, 0.0, cy)
    na = np.hypot(ax, ay)
    nc = np.hypot(cx, cy)
    return ax / na, ay / na, cb, sb, cx / nc, cy / nc


def rotate_z_batch(coeffs, cos_t, sin_t, l_max: int) -> np.ndarray:
    """Turn per-pixel SH coefficients (…, K, C) by Rz(θ).

    Each pair (c_m, s_m) → (c cos mθ − s sin mθ, c sin mθ + s cos mθ), as ``sh.rotation_z``.
    """
    out = np.array(coeffs, copy=True)
    cm, sm = np.ones_like(cos_t), np.zeros_like(cos_t)
    for m in range(1, l_max + 1):
        cm, sm = cm * cos_t - sm * sin_t, sm * cos_t + cm * sin_t  # cos mθ, sin mθ by recurrence
        for l in range(m, l_max + 1):
            pos, neg = l * (l + 1) + m, l * (l + 1) - m
            c, s = coeffs[..., pos, :], coeffs[..., neg, :]
            out[..., pos, :] = c * cm[..., None] - s * sm[..., None]
            out[..., neg, :] = c * sm[..., None] + s * cm[..., None]
    return out


@functools.lru_cache(maxsize=16)
def x_rotation_bands(l_max: int, sign: int) -> tuple[np.ndarray, ...]:
    """Band blocks of the SH rotation for Rx(sign · 90°): constants the shader keeps in its UBO."""
    t = sign * 0.5 * np.pi
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(t), -math.sin(t)], [0.0, math.sin(t), math.cos(t)]])
    return tuple(sh.rotation_bands(l_max, rx))


def apply_bands(bands, coeffs) -> np.ndarray:
    """Apply block-diagonal band matrices to (…, K, C) coefficients."""
    out = np.empty_like(coeffs)
    for l, block in enumerate(bands):
        sl = slice(l * l, (l + 1) * (l + 1))
        out[..., sl, :] = np.einsum("ij,...jc->...ic", block, coeffs[..., sl, :])
    return out


def local_coefficients(world_coeffs, frames, l_max: int) -> np.ndarray:
    """Radiance SH in each pixel's frame, (…, K, C): rotation(frame) @ world, the z-y-z way.

    rotation(Rz(a) Ry(b) Rz(c)) = Z(a) · X(−90°) · Z(b) · X(+90°) · Z(c), applied right to left,
    because Ry(b) = Rx(−90°) Rz(b) Rx(90°).
    """
    ca, sa, cb, sb, cc, sc = zyz_from_frame(frames)
    k = (l_max + 1) ** 2
    c = np.broadcast_to(np.asarray(world_coeffs)[:k], ca.shape + (k, np.shape(world_coeffs)[-1]))
    c = rotate_z_batch(c, cc, sc, l_max)
    c = apply_bands(x_rotation_bands(l_max, +1), c)
    c = rotate_z_batch(c, cb, sb, l_max)
    c = apply_bands(x_rotation_bands(l_max, -1), c)
    return rotate_z_batch(c, ca, sa, l_max)


# ----------------------------------------------------------------------------------------------
# Table lookup and shading
# ----------------------------------------------------------------------------------------------
def _lerp_index(value, count: int):
    """Lower index and weight for linear interpolation of a sample position in [0, count − 1]."""
    pos = np.clip(value, 0.0, count - 1.0)
    i0 = np.minimum(np.floor(pos).astype(int), max(count - 2, 0))
    return i0, pos - i0


def lookup(table: np.ndarray, cos_o, thickness_position=None) -> np.ndarray:
    """Interpolate a table (T, A, K, 3[, 3]) at per-pixel θo and thickness position, → (…, K, 3[, 3]).

    θo = acos(n·v) is mapped to the uniform 0…90° axis; ``thickness_position`` is the
    fractional row in [0, T − 1] (0 when the table has one row).
    """
    t_count, a_count = table.shape[:2]
    theta = np.arccos(np.clip(cos_o, 0.0, 1.0))
    a0, wa = _lerp_index(theta / (0.5 * np.pi) * (a_count - 1), a_count)
    if t_count == 1 or thickness_position is None:
        t0, wt = np.zeros_like(a0), np.zeros_like(wa)
        t_count = max(t_count, 2)
        table = np.concatenate([table, table]) if table.shape[0] == 1 else table
    else:
        t0, wt = _lerp_index(np.broadcast_to(thickness_position, a0.shape), t_count)
    a1, t1 = np.minimum(a0 + 1, a_count - 1), np.minimum(t0 + 1, table.shape[0] - 1)
    extra = (None,) * (table.ndim - 2)
    wa, wt = wa[(...,) + extra], wt[(...,) + extra]
    return (1 - wt) * ((1 - wa) * table[t0, a0] + wa * table[t0, a1]) + wt * (
        (1 - wa) * table[t1, a0] + wa * table[t1, a1]
    )


def shade_sh(result: bake.BakeResult, world_coeffs, normals, views, thickness_nm=None) -> np.ndarray:
    """Scene-linear RGB per pixel (…, 3) from a baked table and world-space radiance SH (≥ K, 3)."""
    l_max = result.sh_order
    frames = view_aligned_frame(normals, views)
    local = local_coefficients(np.asarray(world_coeffs, dtype=float), frames, l_max)
    kept = local[..., bake.coefficient_indices(l_max), :]  # (…, K, 3)
    cos_o = np.sum(frames[..., 2, :] * np.asarray(views), axis=-1)
    pos = None
    if thickness_nm is not None and result.thicknesses_nm.size > 1:
        lo, hi = result.thicknesses_nm[0], result.thicknesses_nm[-1]
        pos = (np.asarray(thickness_nm, dtype=float) - lo) / (hi - lo) * (result.thicknesses_nm.size - 1)
    m = lookup(result.data, cos_o, pos)
    if m.ndim == kept.ndim + 1:  # spectral: 3×3 per coefficient
        out = np.einsum("...ikc,...ic->...k", m, kept)
    else:  # per channel
        out = np.einsum("...ik,...ik->...k", m, kept)
    return np.maximum(out, 0.0)


# ----------------------------------------------------------------------------------------------
# Ground truth: no SH
# ----------------------------------------------------------------------------------------------
def equirect_lookup(image: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Bilinear radiance lookup in an equirect image (H, W, 3), conventions.md mapping."""
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


def film_rgb_matrices(material, thickness_nm=None, samples: int = 4097):
    """RG(u): Σ_λ R(u, λ) G[λ] as (samples, 3, 3) on a uniform u grid, for the ground truth."""
    from .optics import reflectance

    p = bake.plan(material)
    wl, g = bake.spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    d = material.thicknesses()
    if thickness_nm is not None and d:
        d = [float(thickness_nm)] + d[1:]
    method = "glassner2000" if material.model == "glassner2000" else "exact"
    u = np.linspace(0.0, 1.0, samples)
    r = reflectance(material.indices(), d, wl, u, method=method)
    rg = bake.clamp_film_rgb(np.einsum("uw,wkc->ukc", r, g), material.colour_mode)
    return u, rg, r, wl, g


def shade_reference(material, image, normals, views, thickness_nm=None, n_theta: int = 128, n_phi: int = 128):
    """Brute-force spectral render (…, 3): per pixel ∫ L(ωi) f(ωi, ωo, λ) cosθi dωi, no SH.

    Single scattering only (``material.multiscatter`` is not applied: this is the truth the
    table's single-scattering lobe is checked against). Half-vector quadrature of the exact
    microfacet BRDF (same measure as the bake), the film's
    3×3 colour matrices tabulated finely in u (4097 samples, linear), radiance looked up
    bilinearly in the equirect image. The diffuse base, if any, by cosine-weighted quadrature.
    """
    frames = view_aligned_frame(normals, views)
    shape = frames.shape[:-2]
    frames = frames.reshape(-1, 3, 3)
    vv = np.broadcast_to(np.asarray(views, dtype=float), shape + (3,)).reshape(-1, 3)
    u_grid, rg, r_grid, wl, g = film_rgb_matrices(material, thickness_nm)
    alpha = float(brdf.alpha_from_roughness(material.roughness))
    h, w = brdf.ggx_importance_grid(alpha, n_theta, n_phi)
    out = np.zeros((frames.shape[0], 3))
    for p in range(frames.shape[0]):
        f = frames[p]
        cos_o = float(np.clip(f[2] @ vv[p], constants.MIN_COS, 1.0))
        wo = np.array([math.sqrt(max(0.0, 1 - cos_o * cos_o)), 0.0, cos_o])
        u = h @ wo
        wi = 2 * u[:, None] * h - wo
        ok = (u > 0) & (wi[:, 2] > 0)
        if not np.any(ok):
            continue
        g2 = brdf.G2_smith_height_correlated(np.maximum(wi[ok, 2], constants.MIN_COS), cos_o, alpha)
        weight = g2 * u[ok] / (cos_o * h[ok, 2]) * w[ok]
        radiance = equirect_lookup(image, wi[ok] @ f)  # local → world: rows of f are the axes
        idx = np.clip(np.rint(u[ok] * (u_grid.size - 1)).astype(int), 0, u_grid.size - 1)
        out[p] = np.einsum("n,nkc,nc->k", weight, rg[idx], radiance)
    if material.base_color is not None:
        out += _reference_diffuse(material, image, frames, vv, u_grid, r_grid, wl, g)
    return np.maximum(out.reshape(shape + (3,)), 0.0)


def _reference_diffuse(material, image, frames, views, u_grid, r_grid, wl, g, n: int = 64):
    mu, wmu = np.polynomial.legendre.leggauss(n)
    mu, wmu = 0.5 * (mu + 1), 0.5 * wmu
    phi = 2 * np.pi * (np.arange(2 * n) + 0.5) / (2 * n)
    s = np.sqrt(1 - mu * mu)
    d = np.stack(
        np.broadcast_arrays(s[:, None] * np.cos(phi), s[:, None] * np.sin(phi), mu[:, None]), -1
    ).reshape(-1, 3)
    wd = np.repeat(wmu * mu, 2 * n) * (2 * np.pi / (2 * n))
    base = bake.base_spectrum(material, wl) / np.pi
    idx_mu = np.clip(np.rint(np.repeat(mu, 2 * n) * (u_grid.size - 1)).astype(int), 0, u_grid.size - 1)
    out = np.zeros((frames.shape[0], 3))
    for p in range(frames.shape[0]):
        cos_o = float(np.clip(frames[p, 2] @ views[p], 0.0, 1.0))
        r_o = r_grid[int(round(cos_o * (u_grid.size - 1)))]
        spec = (1 - r_grid[idx_mu]) * (1 - r_o) * base  # (N, W)
        radiance = equirect_lookup(image, d @ frames[p])
        out[p] = np.einsum("n,nw,wkc,nc->k", wd, spec, g, radiance)
    return out


# ----------------------------------------------------------------------------------------------
# A sphere seen by a pinhole camera
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SphereView:
    """G-buffer of a unit sphere at the origin, camera on −y looking at +y, z up (Blender's front view)."""

    mask: np.ndarray
    normals: np.ndarray
    views: np.ndarray
    rays: np.ndarray


def sphere_view(
    width: int = 96, height: int = 96, distance: float = 4.0, fov_deg: float = 32.0, supersample: int = 1
) -> SphereView:
    """G-buffer of the sphere; with ``supersample`` s the buffers hold s×s samples per pixel
    (shape (H·s, W·s)), to be averaged back with :func:`box_downsample`."""
    cam = np.array([0.0, -distance, 0.0])
    half = math.tan(math.radians(fov_deg) / 2)
    width, height = width * supersample, height * supersample
    xs = ((np.arange(width) + 0.5) / width * 2 - 1) * half * width / max(width, height)
    zs = (1 - (np.arange(height) + 0.5) / height * 2) * half * height / max(width, height)
    x, z = np.meshgrid(xs, zs)
    rays = np.stack([x, np.ones_like(x), z], -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    b = rays @ cam
    c = cam @ cam - 1.0
    disc = b * b - c
    mask = disc > 0
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    p = cam + t[..., None] * rays
    normals = p / np.maximum(np.linalg.norm(p, axis=-1, keepdims=True), 1e-12)
    views = -rays
    return SphereView(mask, normals, views, rays)


def box_downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """Average factor × factor blocks (pixel-area integration of a supersampled render)."""
    if factor == 1:
        return image
    h, w = image.shape[0] // factor, image.shape[1] // factor
    return image.reshape(h, factor, w, factor, -1).mean(axis=(1, 3)).reshape((h, w) + image.shape[2:])


def render_sphere(
    result,
    image,
    world_coeffs,
    view: SphereView,
    thickness_nm=None,
    reference_material=None,
    prefiltered=None,
):
    """Sphere over the environment background.

    The SH path alone; the combined split-sum + SH path when ``prefiltered`` (a
    :class:`prefilter.Prefiltered`) is given; or the brute-force ground truth when
    ``reference_material`` is given.
    """
    from . import prefilter

    out = equirect_lookup(image, view.rays)
    m = view.mask
    if reference_material is not None:
        out[m] = shade_reference(reference_material, image, view.normals[m], view.views[m], thickness_nm)
    elif prefiltered is not None:
        out[m] = prefilter.shade_combined(
            result, world_coeffs, prefiltered, view.normals[m], view.views[m], thickness_nm
        )
    else:
        out[m] = shade_sh(result, world_coeffs, view.normals[m], view.views[m], thickness_nm)
    return out


#: The lighting SH is Lanczos-windowed (Sloan 2008) with a width that grows with roughness,
#: w = (l_max + 1)(1 + WINDOW_WIDTH_PER_ROUGHNESS · r): glossy lobes keep the truncated bands of
#: HDR suns at nearly full weight and ring (negative lobes clamp to black), so they need the
#: narrow window; rough lobes already suppress high bands, and a narrow window over-blurs them.
#: Measured against Cycles at l = 8 (mean ΔE2000 of the combined path; benchmarks/cycles_compare
#: cases): no window / Lanczos 9 / 11 / 13 / 16 — courtyard r 0.5: 3.52 / 3.24 / 2.85 / 2.83 /
#: 2.93; forest r 0.5: 2.17 / 1.27 / 1.16 / 1.24 / 1.43; studio r 0.6: 4.30 / 4.62 / 3.89 / 3.73 /
#: 3.77; sunset r 0.6: 0.68 / 0.92 / 0.72 / 0.65 / 0.61; courtyard r 0.3: 4.21 / 3.68 / 3.70 /
#: 3.78 / 3.89 (the old rule, Hanning 9 below 0.5 and none above: 3.83 at r 0.3, 3.52 at 0.5).
WINDOW_WIDTH_PER_ROUGHNESS = 0.9


def lighting_window(l_max: int, roughness: float) -> np.ndarray:
    """Per-coefficient factors applied to the World's SH for a material of this roughness."""
    r = min(max(float(roughness), 0.0), 1.0)
    return sh.window(l_max, "lanczos", (l_max + 1.0) * (1.0 + WINDOW_WIDTH_PER_ROUGHNESS * r))


def prepare_environment(image: np.ndarray, l_max: int, max_width: int = 512, roughness: float | None = None):
    """Downsample (solid-angle exact) to ≤ max_width and project to SH; returns (image, coeffs).

    With ``roughness`` the coefficients are windowed by :func:`lighting_window`.
    """
    while image.shape[1] > max_width:
        image = downsample(image, 2)
    coeffs = sh.project_equirect(image, l_max)
    if roughness is not None:
        coeffs = coeffs * lighting_window(l_max, roughness)[:, None]
    return image, coeffs


# ----------------------------------------------------------------------------------------------
# Image output
# ----------------------------------------------------------------------------------------------
def srgb_encode(linear: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Blender's "Standard" view: scale by 2^exposure, clamp to [0, 1], sRGB OETF (IEC 61966-2-1)."""
    x = np.clip(np.asarray(linear) * 2.0**exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _png_filtered_row(data: np.ndarray, r: int) -> bytes:
    """Row r with the PNG filter (None, Sub or Up) of least Σ|signed residual| (libpng's heuristic).

    Natural images compress to about half with Sub/Up instead of None.
    """
    row = data[r].astype(np.int16).ravel()
    left = np.concatenate([np.zeros(3, np.int16), row[:-3]])
    up = data[r - 1].astype(np.int16).ravel() if r > 0 else np.zeros_like(row)
    options = [(0, row), (1, (row - left) % 256), (2, (row - up) % 256)]

    def cost(residual):
        return int(np.abs(np.where(residual > 127, residual - 256, residual)).sum())

    kind, best = min(options, key=lambda o: cost(o[1]))
    return bytes([kind]) + best.astype(np.uint8).tobytes()


def write_png(path, rgb_display: np.ndarray) -> None:
    """8-bit RGB PNG from display-referred values in [0, 1] (minimal writer: per-row filter, zlib, CRC)."""
    data = np.clip(np.rint(np.asarray(rgb_display) * 255), 0, 255).astype(np.uint8)
    h, w = data.shape[:2]
    raw = b"".join(_png_filtered_row(data, r) for r in range(h))

    def chunk(tag, payload):
        return struct.pack(">I", len(payload)) + tag + payload + struct.pack(">I", zlib.crc32(tag + payload))

    png = (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )
    with open(path, "wb") as fh:
        fh.write(png)


def write_exr(path, rgb_linear: np.ndarray) -> None:
    """Scene-linear float32 RGB OpenEXR."""
    import OpenEXR

    rgb = np.ascontiguousarray(np.asarray(rgb_linear, dtype=np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"RGB": rgb}).write(str(path))
