"""The brute-force ground truth and the sphere scenes it, the CLI and the benchmarks render.

``shade_reference`` uses no SH at all: per pixel, the exact spectral BRDF integrated against the
environment map by half-vector quadrature; it is what the baked tables and the shader's numpy
mirror (precompute/shading/) are checked against. Scenes here are a sphere seen by a pinhole
camera, for the CLI preview, the accuracy benchmark and the tests: :func:`render_sphere` shades
it with the SH path, the combined split-sum + SH path or the ground truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import brdf, constants
from ..bakes import bake
from ..colour.film_colour import film_rgb_matrices
from ..sh import projection
from ..shading.frame import view_aligned_frame
from ..shading.policy import lighting_window
from ..shading.sh_sum import shade_sh
from ..shading.split_sum import shade_combined
from ..world.hdri import downsample, equirect_lookup


# ----------------------------------------------------------------------------------------------
# Ground truth: no SH
# ----------------------------------------------------------------------------------------------
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
        out += _reference_diffuse(material, image, frames, vv, u_grid, r_grid, wl, g, rg)
    return np.maximum(out.reshape(shape + (3,)), 0.0)


def _reference_diffuse(material, image, frames, views, u_grid, r_grid, wl, g, rg, n: int = 64):
    """The diffuse base by cosine-weighted quadrature. Spectral: seen through the film both ways;
    per channel: Cycles' layering, Base Color × (1 − max_c F_c(θo)) (single scattering)."""
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
    if material.colour_mode == "per_channel":
        film = np.einsum("ukk->uk", rg)
        albedo = np.asarray(material.base_color, dtype=float) / np.pi
        for p in range(frames.shape[0]):
            cos_o = float(np.clip(frames[p, 2] @ views[p], 0.0, 1.0))
            weight = 1.0 - np.max(film[int(round(cos_o * (u_grid.size - 1)))])
            out[p] = albedo * weight * (wd @ equirect_lookup(image, d @ frames[p]))
        return out
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
    :class:`precompute.world.prefilter.Prefiltered`) is given; or the brute-force ground truth when
    ``reference_material`` is given.
    """
    out = equirect_lookup(image, view.rays)
    m = view.mask
    if reference_material is not None:
        out[m] = shade_reference(reference_material, image, view.normals[m], view.views[m], thickness_nm)
    elif prefiltered is not None:
        out[m] = shade_combined(
            result, world_coeffs, prefiltered, view.normals[m], view.views[m], thickness_nm
        )
    else:
        out[m] = shade_sh(result, world_coeffs, view.normals[m], view.views[m], thickness_nm)
    return out


def prepare_environment(image: np.ndarray, l_max: int, max_width: int = 512, roughness: float | None = None):
    """Downsample (solid-angle exact) to ≤ max_width and project to SH; returns (image, coeffs).

    With ``roughness`` the coefficients are windowed by
    :func:`precompute.shading.policy.lighting_window`.
    """
    while image.shape[1] > max_width:
        image = downsample(image, 2)
    coeffs = projection.project_equirect(image, l_max)
    if roughness is not None:
        coeffs = coeffs * lighting_window(l_max, roughness)[:, None]
    return image, coeffs
