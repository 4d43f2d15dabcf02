"""The outgoing-radiance grid integrated over the film's exact lobe, without SH.

:func:`precompute.shading.radiance_grid.build` fills the grid from the SH sum, whose l = 12
truncation blurs and rings a lobe of roughness 0.2–0.45 (GGX α = 0.04–0.2) and whose split-sum
partner reads one film colour per pixel. Here each node (mirror direction r, view angle θo, view
azimuth ψ; the layout, coordinates and lookup of :mod:`.radiance_grid`, read by
tf_radiance_grid.glsl unchanged) is the single-scattering integral itself,

    L(n, v) = ms(θo) Σ_s w_s F(u_s) L_env(ω_s),

over GGX half-vector quadrature nodes (:func:`precompute.brdf.ggx_importance_grid`, the measure
of :func:`precompute.output.render.shade_reference`): F the film's reflectance at each node's u = v·h
(per channel, or its 3×3 matrix), ms the multiple-scattering factor the bake applies, L_env the
World's panorama (the lamps lifted out when they are shaded per direction). The film's colour
thus changes across the lobe as it does in Cycles (docs/tuning.md#lobe-grid).

Pure numpy; float32 lookups, one θo node at a time.
"""

from __future__ import annotations

import numpy as np

from .. import brdf
from .lamps import film_at
from .policy import LOBE_GRID_SAMPLES, MIN_COS
from .radiance_grid import _check_shape, mirror_frames, view_angles

#: Panorama lookups per numpy block in :func:`build` (bounds the temporaries to ≈ 100 MB).
BLOCK_LOOKUPS = 2_000_000


def _lookup(flat: np.ndarray, height: int, width: int, d: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a flattened equirect panorama at unit directions ``d`` (N, 3), the
    mapping of :func:`precompute.world.hdri.equirect_lookup` (wrap in u, rows clamped), in float32."""
    x = (0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2.0 * np.pi)) * width - 0.5
    y = np.arccos(np.clip(d[:, 2], -1.0, 1.0)) / np.pi * height - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx = (x - x0)[:, None]
    fy = np.clip(y - y0, 0.0, 1.0)[:, None]
    i0 = x0.astype(np.int64) % width
    i1 = (i0 + 1) % width
    j0 = np.clip(y0.astype(np.int64), 0, height - 1) * width
    j1 = np.clip(y0.astype(np.int64) + 1, 0, height - 1) * width
    top = flat[j0 + i0] * (1 - fx) + flat[j0 + i1] * fx
    bottom = flat[j1 + i0] * (1 - fx) + flat[j1 + i1] * fx
    return top * (1 - fy) + bottom * fy


def node_samples(roughness: float, theta: float, samples=LOBE_GRID_SAMPLES):
    """The quadrature of one view angle: (ωi (S, 3) in the view-aligned frame, weights (S,), u (S,)).

    Half-vectors of ``ggx_importance_grid`` (nθ × nφ); ωi = reflect(ωo, h), kept above the
    surface; weight G₂ u / (cos θo cos θh) w (the measure of render.shade_reference), so that
    Σ weight F(u) L(ωi) is the single-scattering radiance.
    """
    alpha = float(brdf.alpha_from_roughness(roughness))
    h, w = brdf.ggx_importance_grid(alpha, int(samples[0]), int(samples[1]))
    cos_o = max(float(np.cos(theta)), MIN_COS)
    wo = np.array([np.sqrt(max(0.0, 1.0 - cos_o * cos_o)), 0.0, cos_o])
    u = h @ wo
    wi = 2.0 * u[:, None] * h - wo
    ok = (u > 0.0) & (wi[:, 2] > 0.0)
    g2 = brdf.G2_smith_height_correlated(np.maximum(wi[ok, 2], MIN_COS), cos_o, alpha)
    return wi[ok], g2 * u[ok] / (cos_o * h[ok, 2]) * w[ok], u[ok]


def build(
    film, roughness: float, panorama, shape, rotation=None, scale: float = 1.0, samples=LOBE_GRID_SAMPLES
):
    """The grid of a constant-thickness film under an equirect ``panorama``: (T·Ψ, H, W, 3) float32.

    Parameters
    ----------
    film : precompute.colour.film_colour.FilmTable
        The film's reflectance F(u) and multiple-scattering factor (thickness row 0).
    roughness : float
        Blender roughness r (GGX α = r²).
    panorama : array_like, shape (h, w, 3)
        The World's radiance, top row first, in the content's frame (the lamps lifted out where
        they are shaded per direction).
    shape : (W, H, T, Ψ)
        Mirror cells, view-angle nodes and view azimuths (:mod:`.radiance_grid`'s layout).
    rotation : array_like, shape (3, 3), optional
        Q (content direction = Q · world direction), as the split sum's lookup.
    scale : float
        The World's strength.
    samples : (int, int)
        GGX quadrature nodes (θ × φ) per node (policy.LOBE_GRID_SAMPLES).
    """
    w, h, t, p = _check_shape(shape)
    image = np.asarray(panorama, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] < 3:
        raise ValueError(f"panorama must be (h, w, 3), got {image.shape}")
    ph, pw = image.shape[:2]
    flat = np.ascontiguousarray(image[..., :3].reshape(-1, 3))
    frames = mirror_frames((w, h, t, p)).reshape(-1, 3, 3)  # rows e1, e2, r per (H, W, Ψ) cell
    if rotation is not None:
        frames = frames @ np.asarray(rotation, dtype=float).T  # each row turned into the content
    frames = frames.astype(np.float32)
    rows = np.zeros(1, dtype=int)
    out = np.zeros((t, frames.shape[0], 3), dtype=np.float32)
    step = max(1, BLOCK_LOOKUPS // frames.shape[0])
    for j, theta in enumerate(view_angles(t)):
        wi, weight, u = node_samples(roughness, float(theta), samples)
        count = u.size
        if count == 0:
            continue
        zeros = np.zeros(count, dtype=int)
        colour = film_at(film, film.reflectance, (zeros, zeros, np.zeros(count)), u)  # (S, 3[, 3])
        cos_o = np.array([max(float(np.cos(theta)), MIN_COS)])
        ms = film_at(film, film.multiscatter, (rows, rows, np.zeros(1)), cos_o)[0]
        # ωi in the view-aligned frame (x = cos θo e1 − sin θo r, y = e2, z = n = sin θo e1 +
        # cos θo r) as a combination of the cell's rows (e1, e2, r)
        c, s = float(np.cos(theta)), float(np.sin(theta))
        coef = np.stack([wi[:, 0] * c + wi[:, 2] * s, wi[:, 1], wi[:, 2] * c - wi[:, 0] * s], -1)
        coef = coef.astype(np.float32)
        acc = np.zeros((frames.shape[0], 3), dtype=np.float64)
        for start in range(0, count, step):
            part = slice(start, start + step)
            d = np.einsum("sk,nkc->snc", coef[part], frames)  # (S, N, 3)
            radiance = _lookup(flat, ph, pw, d.reshape(-1, 3)).reshape(d.shape)
            if film.spectral:
                acc += np.einsum("s,soc,snc->no", weight[part], colour[part], radiance)
            else:
                acc += np.einsum("s,sc,snc->nc", weight[part], colour[part], radiance)
        out[j] = acc * ms * float(scale)
    grid = out.reshape(t, h, w, p, 3).transpose(0, 3, 1, 2, 4)  # (T, Ψ, H, W, 3)
    return np.ascontiguousarray(np.maximum(grid, 0.0).reshape(t * p, h, w, 3), dtype=np.float32)
