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
from .policy import GRID_HATS, LOBE_GRID_SAMPLES, MIN_COS
from .radiance_grid import _bilinear, _check_shape, coordinates, mirror_frames, node_weights, view_angles

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


def _lobe_views(roughness: float, panorama, shape, rotation, samples):
    """Per view-angle node j of ``shape`` whose lobe has quadrature nodes: (j, θo, weights (S,),
    u (S,), the panorama along each node's ωi from every (H, W, Ψ) cell (the cell's rows e1, e2,
    r turned by ``rotation`` into the content): an iterator of (a slice of the nodes, radiance
    (s, H·W·Ψ, 3)) in blocks of at most :data:`BLOCK_LOOKUPS` lookups)."""
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
    step = max(1, BLOCK_LOOKUPS // frames.shape[0])

    def blocks(coef, count):
        for start in range(0, count, step):
            part = slice(start, start + step)
            d = np.einsum("sk,nkc->snc", coef[part], frames)  # (S, N, 3)
            yield part, _lookup(flat, ph, pw, d.reshape(-1, 3)).reshape(d.shape)

    for j, theta in enumerate(view_angles(t)):
        wi, weight, u = node_samples(roughness, float(theta), samples)
        if u.size == 0:
            continue
        # ωi in the view-aligned frame (x = cos θo e1 − sin θo r, y = e2, z = n = sin θo e1 +
        # cos θo r) as a combination of the cell's rows (e1, e2, r)
        c, s = float(np.cos(theta)), float(np.sin(theta))
        coef = np.stack([wi[:, 0] * c + wi[:, 2] * s, wi[:, 1], wi[:, 2] * c - wi[:, 0] * s], -1)
        yield j, theta, weight, u, blocks(coef.astype(np.float32), u.size)


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
    rows = np.zeros(1, dtype=int)
    out = np.zeros((t, h * w * p, 3), dtype=np.float32)
    for j, theta, weight, u, blocks in _lobe_views(roughness, panorama, shape, rotation, samples):
        zeros = np.zeros(u.size, dtype=int)
        colour = film_at(film, film.reflectance, (zeros, zeros, np.zeros(u.size)), u)  # (S, 3[, 3])
        cos_o = np.array([max(float(np.cos(theta)), MIN_COS)])
        ms = film_at(film, film.multiscatter, (rows, rows, np.zeros(1)), cos_o)[0]
        acc = np.zeros((h * w * p, 3), dtype=np.float64)
        for part, radiance in blocks:
            if film.spectral:
                acc += np.einsum("s,soc,snc->no", weight[part], colour[part], radiance)
            else:
                acc += np.einsum("s,sc,snc->nc", weight[part], colour[part], radiance)
        out[j] = acc * ms * float(scale)
    grid = out.reshape(t, h, w, p, 3).transpose(0, 3, 1, 2, 4)  # (T, Ψ, H, W, 3)
    return np.ascontiguousarray(np.maximum(grid, 0.0).reshape(t * p, h, w, 3), dtype=np.float32)


# ----------------------------------------------------------------------------------------------
# A film-free basis: the grid of any thickness (a varying film's)
# ----------------------------------------------------------------------------------------------
def hat_weights(u, hats: int = GRID_HATS) -> np.ndarray:
    """(hats, N): the piecewise-linear hats over u ∈ [0, 1] at nodes k / (hats − 1) at ``u``."""
    u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
    x = u * (hats - 1)
    k = np.minimum(np.floor(x).astype(int), hats - 2)
    t = x - k
    out = np.zeros((int(hats), u.size))
    out[k, np.arange(u.size)] += 1.0 - t
    out[k + 1, np.arange(u.size)] += t
    return out


def build_basis(
    roughness: float, panorama, shape, rotation=None, scale: float = 1.0, samples=LOBE_GRID_SAMPLES
):
    """The film-free grid of a varying film: ((T + 1)·Ψ, H, K·(W + 2), 3) float32, K = GRID_HATS.

    Hat k's columns k·(W + 2) + 1 … k·(W + 2) + W of layer j·Ψ + ψ (a column of padding each
    side, the mirror cells' wrap, so a bilinear read repeats within the hat: an array texture
    holds at most 2048 layers) hold H_k = Σ_s w_s b_k(u_s) L_env(ω_s), b_k the hat of
    u node k / (K − 1) (:func:`hat_weights`): the lobe's integral with the film's reflectance
    F(u) linear between its values at the nodes, so that a film of any thickness d reads
    Σ_k F(u_k, d) H_k (:func:`lookup_basis`, times its multiple-scattering factor). Texel
    (row 0, column j) of the last Ψ layers holds the first and last hat that view node j's lobe
    reaches (the shader reads those alone). Parameters as :func:`build` without the film."""
    w, h, t, p = _check_shape(shape)
    if w < t:
        raise ValueError(f"a basis grid needs W ≥ T to hold its hat ranges, got {shape}")
    k_count = GRID_HATS
    out = np.zeros((k_count, t, h * w * p, 3), dtype=np.float32)
    ranges = np.zeros((t, 2), dtype=np.float32)
    for j, _theta, weight, u, blocks in _lobe_views(roughness, panorama, shape, rotation, samples):
        basis = (hat_weights(u, k_count) * weight).astype(np.float32)  # (K, S)
        used = np.flatnonzero(np.abs(basis).sum(axis=1) > 0.0)
        ranges[j] = (used.min(), used.max())
        acc = np.zeros((k_count, h * w * p, 3), dtype=np.float64)
        for part, radiance in blocks:
            acc += np.einsum("ks,snc->knc", basis[:, part], radiance)
        out[:, j] = acc * float(scale)
    data = out.reshape(k_count, t, h, w, p, 3).transpose(1, 4, 2, 0, 3, 5)  # (T, Ψ, H, K, W, 3)
    padded = np.concatenate([data[..., -1:, :], data, data[..., :1, :]], axis=4)  # REPEAT per hat
    grid = padded.reshape(t * p, h, k_count * (w + 2), 3)
    table = np.zeros((p, h, k_count * (w + 2), 3), dtype=np.float32)
    table[0, 0, :t, :2] = ranges
    return np.ascontiguousarray(np.concatenate([grid, table]), dtype=np.float32)


def lookup_basis(grid, normals, views, film, rows, azimuths: int, rotation=None, scale: float = 1.0):
    """A varying film's SH half per pixel from a :func:`build_basis` grid: (N, 3).

    ``film`` (its FilmTable) at the thickness ``rows`` of :func:`.lamps.thickness_lerp`; per view
    node j each hat's block read as :func:`.radiance_grid.lookup` reads a grid (bilinear in the
    mirror direction, linear in ψ) and weighted by F(u_k), summed over the hats view node j's
    lobe reaches, then linear in θo, times the film's multiple-scattering factor at cos θo
    (tf_grid_basis.glsl)."""
    g = np.asarray(grid, dtype=float)
    p, k_count = int(azimuths), GRID_HATS
    t = g.shape[0] // p - 1
    w = g.shape[2] // k_count - 2
    ranges = np.rint(g[t * p, 0, :t, :2]).astype(int)
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    v = np.asarray(views, dtype=float).reshape(-1, 3)
    if rotation is not None:
        q = np.asarray(rotation, dtype=float).reshape(3, 3)
        n, v = n @ q.T, v @ q.T
    u, tt, theta_pos, psi_pos = coordinates(n, v, (w, g.shape[1], t, p))
    j0, wj, k0, k1, wk = node_weights(theta_pos, psi_pos, t, p)

    def at(j):
        total = np.zeros((n.shape[0], 3))
        for k in range(k_count):
            used = (ranges[j, 0] <= k) & (k <= ranges[j, 1])
            if not used.any():
                continue
            layer = j * p
            x = (k * (w + 2) + 1 + u * w) / g.shape[2]  # within hat k's padded columns
            h_k = (1 - wk) * _bilinear(g, layer + k0, x, tt) + wk * _bilinear(g, layer + k1, x, tt)
            colour = film_at(film, film.reflectance, rows, np.full(n.shape[0], k / (k_count - 1)))
            value = np.einsum("noc,nc->no", colour, h_k) if film.spectral else colour * h_k
            total += np.where(used[:, None], value, 0.0)
        return total

    cos_o = np.clip(np.sum(n * v, axis=-1), MIN_COS, 1.0)
    ms = film_at(film, film.multiscatter, rows, cos_o)
    return float(scale) * ((1 - wj) * at(j0) + wj * at(j0 + 1)) * ms
