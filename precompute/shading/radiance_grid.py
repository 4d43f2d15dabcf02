"""The outgoing-radiance grid: the SH half of a constant-thickness film, tabulated once per World
and material and read per pixel at a cost that does not grow with the SH order (numpy twin of
glsl/tf_radiance_grid.glsl).

The SH path's radiance towards the viewer depends on the normal n and the view v: four degrees of
freedom. The grid holds it over (r, θo, ψ): the mirror direction r = 2 (n·v) n − v (equirect, W × H
cells, as the prefilter), the view angle θo (T nodes over 0…90°, as the table) and the view
azimuth ψ about r (Ψ nodes, periodic), as in Ramamoorthi & Hanrahan's (2002) frequency-space
environment maps: in these coordinates a rough lobe stays centred on its cell while θo only
changes its shape and colour. A pixel reads four cells (θo and ψ interpolated by hand, r by the
texture's bilinear filter): the cost of a split-sum lookup, whatever l_max.

Cell (i, h, j, k): φ_r = 2π (0.5 − (i + ½)/W), θ_r = π (h + ½)/H, θo = (π/2) j/(T − 1),
ψ = 2π k/Ψ; with G = Rz(φ_r) Ry(θ_r) Rz(ψ) (columns e1, e2, r) the normal is
n = sin θo e1 + cos θo r and the view v = sin 2θo e1 + cos 2θo r; the view-aligned frame of that
(n, v) has rows x = cos θo e1 − sin θo r, y = e2, z = n, i.e. frame = Ry(θo)ᵀ Gᵀ. So the pixel's
local SH is D(Ry(θo)ᵀ) · D(Gᵀ) L: the second factor is one rotation per (r, ψ) (49 k), the first
twelve fixed matrices folded into the table (:func:`build`). Each node equals
:func:`.sh_sum.shade_sh` at its (n, v) (tests/drawing/test_radiance_grid.py).

References
----------
- Ramamoorthi, R. & Hanrahan, P. (2002). Frequency space environment map rendering. ACM TOG
  21(3), SIGGRAPH.
"""

from __future__ import annotations

import collections
import functools
import threading

import numpy as np

from ..bakes import bake, kernel
from ..bakes.progress import checkpoint
from .policy import GRID_AZIMUTHS, grid_shape
from .sh_rotation import apply_bands, local_coefficients, rotate_z_batch, x_rotation_bands
from .table import lookup as table_lookup


def _check_shape(shape) -> tuple[int, int, int, int]:
    w, h, t, p = (int(x) for x in shape)
    if w < 2 or h < 2 or t < 2 or p < 2:
        raise ValueError(f"grid shape (W, H, T, Ψ) must be ≥ 2 each, got {tuple(shape)}")
    return w, h, t, p


def mirror_frames(shape) -> np.ndarray:
    """Rows (e1, e2, r) of G = Rz(φ_r) Ry(θ_r) Rz(ψ) per (h, i, k) cell: shape (H, W, Ψ, 3, 3)."""
    w, h, _t, p = _check_shape(shape)
    phi = 2.0 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    theta = np.pi * (np.arange(h) + 0.5) / h
    psi = 2.0 * np.pi * np.arange(p) / p
    th, ph, ps = np.meshgrid(theta, phi, psi, indexing="ij")  # (H, W, Ψ)
    r = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    a1 = np.stack([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), -np.sin(th)], -1)
    a2 = np.stack([-np.sin(ph), np.cos(ph), np.zeros_like(ph)], -1)
    e1 = np.cos(ps)[..., None] * a1 + np.sin(ps)[..., None] * a2
    e2 = -np.sin(ps)[..., None] * a1 + np.cos(ps)[..., None] * a2
    return np.stack([e1, e2, r], axis=-2)


def view_angles(count: int) -> np.ndarray:
    """θo of the grid's view nodes, uniform over 0…π/2 inclusive (as the table's)."""
    return 0.5 * np.pi * np.arange(int(count)) / (int(count) - 1)


def cell_geometry(shape) -> tuple[np.ndarray, np.ndarray]:
    """(normals, views) of every node, shape (T, Ψ, H, W, 3) each (the layout of :func:`build`)."""
    frames = mirror_frames(shape)  # (H, W, Ψ, 3, 3)
    e1, r = frames[..., 0, :], frames[..., 2, :]
    theta = view_angles(shape[2])[:, None, None, None, None]
    e1, r = np.moveaxis(e1, 2, 0)[None], np.moveaxis(r, 2, 0)[None]  # (1, Ψ, H, W, 3)
    n = np.sin(theta) * e1 + np.cos(theta) * r
    v = np.sin(2 * theta) * e1 + np.cos(2 * theta) * r
    return n, v


@functools.lru_cache(maxsize=8)
def _view_rotations(count: int, l_max: int) -> np.ndarray:
    """D(Ry(θo_j)ᵀ) at the grid's ``count`` view nodes, (T, K, K): the SH rotation into the frame
    with rows (cos θ, 0, −sin θ), ŷ, (sin θ, 0, cos θ) (a view-aligned frame relative to G). They
    depend on the node count and order alone, so every grid of that shape reuses them.
    Read-only."""
    k = (l_max + 1) ** 2
    theta = view_angles(count)
    c, s = np.cos(theta), np.sin(theta)
    zero, one = np.zeros_like(c), np.ones_like(c)
    frames = np.stack(
        [np.stack([c, zero, -s], -1), np.stack([zero, one, zero], -1), np.stack([s, zero, c], -1)], -2
    )  # (T, 3, 3)
    rotations = np.ascontiguousarray(local_coefficients(np.eye(k)[None], frames[:, None], l_max)[:, 0])
    rotations.flags.writeable = False
    return rotations


def folded_table(result: bake.BakeResult, count: int) -> np.ndarray:
    """The table at the grid's θo nodes with the view rotation folded in, (K, T, C_out, C_in).

    E[q, j, o, c] = Σ_i M_i(θo_j)[o, c] D(Ry(θo_j)ᵀ)[kept_i, q]: the pixel's radiance at node j is
    Σ_q Σ_c E[q, j, o, c] · Q[q, c] with Q the SH in G's frame. Per-channel tables give
    C_out = C_in = 3 with zeros off the diagonal. Thickness row 0 (a constant thickness).
    """
    l_max = result.sh_order
    kept = kernel.coefficient_indices(l_max)
    rotations = _view_rotations(int(count), l_max)[:, kept]  # (T, K_kept, K)
    m = table_lookup(result.data[:1], np.cos(view_angles(count)))  # (T, K_kept, 3[, 3])
    if m.ndim == 3:  # per channel → diagonal 3×3
        m = m[..., :, None] * np.eye(3)
    return np.einsum("jioc,jiq->qjoc", m, rotations)


#: World parts of recent grids (:func:`_turned_world`), by the windowed SH's bytes and the shape.
_TURNED: collections.OrderedDict = collections.OrderedDict()
_TURNED_SIZE = 2
_TURNED_LOCK = threading.Lock()


def _turned_world(coeffs: np.ndarray, w: int, h: int, l_max: int) -> np.ndarray:
    """B per mirror direction, (H·W, 3K) float32: the windowed World SH turned by
    X(−90°) Z(−θ_r) X(+90°) Z(−φ_r) for every (θ_r, φ_r) cell (:func:`build`'s first factor).

    It depends on the World (its content and the film's window) and not on the film, so a
    thickness or IOR edit of a film under the same World reuses it: kept for the last
    :data:`_TURNED_SIZE` Worlds (8–14 MiB each at l = 12). Read-only.
    """
    k = (l_max + 1) ** 2
    key = (np.ascontiguousarray(coeffs[:k, :3]).tobytes(), w, h, l_max)
    with _TURNED_LOCK:
        found = _TURNED.get(key)
        if found is not None:
            _TURNED.move_to_end(key)
            return found
    phi = 2.0 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    theta = np.pi * (np.arange(h) + 0.5) / h
    turned = rotate_z_batch(np.broadcast_to(coeffs[:k, :3], (w, k, 3)), np.cos(-phi), np.sin(-phi), l_max)
    turned = apply_bands(x_rotation_bands(l_max, +1), turned)
    turned = np.broadcast_to(turned, (h, w, k, 3))
    turned = rotate_z_batch(turned, np.cos(-theta)[:, None], np.sin(-theta)[:, None], l_max)
    turned = apply_bands(x_rotation_bands(l_max, -1), turned)  # (H, W, K, 3): B per mirror direction
    turned = np.ascontiguousarray(turned.reshape(h * w, k * 3), dtype=np.float32)
    turned.flags.writeable = False
    with _TURNED_LOCK:
        _TURNED[key] = turned
        while len(_TURNED) > _TURNED_SIZE:
            _TURNED.popitem(last=False)
    return turned


def build(result: bake.BakeResult, world_coeffs, shape=None) -> np.ndarray:
    """The grid of a constant-thickness table under windowed World SH (≥ K, 3): (T·Ψ, H, W, 3)
    float32, layer j·Ψ + k holding θo node j and view azimuth k (the texture's layout), each node
    :func:`.sh_sum.shade_sh` at its :func:`cell_geometry` (clamped at 0). ``shape`` (W, H, T, Ψ):
    default policy.grid_shape of the table's view angles.

    Separable: a cell's frame Gᵀ = Rz(−ψ) Ry(−θ_r) Rz(−φ_r), so D(Gᵀ) = Z(−ψ) X(−90°) Z(−θ_r)
    X(+90°) Z(−φ_r) (:mod:`.sh_rotation`). The SH is turned for the W columns, then for the H·W
    mirror directions (:func:`_turned_world`, kept per World); Z(−ψ) moves into the folded table
    (Σ_q (Z B)_q E_q = Σ_q B_q (Zᵀ E)_q, Zᵀ = Z(+ψ)), so the grid is, per output channel, one
    (Ψ·T, 3K) × (3K, H·W) float32 product written straight into the texture's layout: ≈ 0.9 G
    multiply-adds at l = 12 in all (float32 sums of 3K terms: ~1e-7 of the peak, below the
    texture's own rounding). A :func:`~precompute.bakes.progress.checkpoint` after each step (≲ 20 ms)
    lets a superseded build stop.
    """
    w, h, t, p = _check_shape(grid_shape(result.data.shape[1]) if shape is None else shape)
    l_max = result.sh_order
    k = (l_max + 1) ** 2
    coeffs = np.asarray(world_coeffs, dtype=float)
    if coeffs.ndim != 2 or coeffs.shape[0] < k or coeffs.shape[1] < 3:
        raise ValueError(f"world_coeffs must be (≥ {k}, 3) for l_max {l_max}, got {coeffs.shape}")
    turned = _turned_world(coeffs, w, h, l_max)  # (H·W, 3K)
    checkpoint()  # a bake's worker builds a grid after its table: cancellable between steps
    psi = 2.0 * np.pi * np.arange(p) / p
    folded = folded_table(result, t).reshape(k, t * 9)  # E[q, (j, o, c)]
    by_psi = rotate_z_batch(np.broadcast_to(folded, (p, k, t * 9)), np.cos(psi), np.sin(psi), l_max)
    by_psi = by_psi.reshape(p, k, t, 3, 3)  # [k, q, j, o, c]
    grid = np.empty((t * p, h * w, 3), dtype=np.float32)
    for o in range(3):  # rows (j, k), columns (q, c): the layer order j·Ψ + k
        table = by_psi[..., o, :].transpose(2, 0, 1, 3).reshape(t * p, k * 3)
        grid[:, :, o] = np.ascontiguousarray(table, np.float32) @ turned.T
        checkpoint()
    np.maximum(grid, 0.0, out=grid)
    return grid.reshape(t * p, h, w, 3)


def texels(grid) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """(rgba, (W, H, T, Ψ)): a (T·Ψ, H, W, 3) grid as its texture's texels, (T·Ψ, H, W, 4)
    float32 with alpha 0, checked: Ψ = policy.GRID_AZIMUTHS, T ≥ 2, every value finite. Made
    where the grid was built (a worker, the bake helper), so the main thread only uploads
    (the padding took 5–16 ms of the upload's 13–35 ms at 16–48 view angles)."""
    data = np.asarray(grid, dtype=np.float32)
    p = GRID_AZIMUTHS
    if data.ndim != 4 or data.shape[3] != 3 or data.shape[0] % p or data.shape[0] < 2 * p:
        raise ValueError(f"radiance grid must be (T·{p}, H, W, 3) with T ≥ 2, got {data.shape}")
    t, h, w = data.shape[0] // p, data.shape[1], data.shape[2]
    if not np.all(np.isfinite(data)):
        raise ValueError("the radiance grid holds non-finite values")
    rgba = np.zeros(data.shape[:3] + (4,), dtype=np.float32)
    rgba[..., :3] = data
    return rgba, (w, h, t, p)


def coordinates(normals, views, shape) -> tuple[np.ndarray, ...]:
    """(u, t, θo position, ψ position) of each pixel, as tf_radiance_grid.glsl computes them.

    From the view-aligned frame (x, n) and (cos θo, sin θo) normalised, cos θo ≥ 0: r = cos θo n −
    sin θo x, e1 = cos θo x + sin θo n; u = ½ − φ_r/2π, t = θ_r/π (equirect texture coordinates);
    θo position in [0, T − 1]; ψ position = atan2(e1·a2, e1·a1)/2π · Ψ in [0, Ψ).
    """
    from .frame import view_aligned_frame

    n = np.asarray(normals, dtype=float)
    v = np.asarray(views, dtype=float)
    frames = view_aligned_frame(n, v)
    x, z = frames[..., 0, :], frames[..., 2, :]
    c = np.maximum(np.sum(z * v, axis=-1), 0.0)
    s = np.linalg.norm(v - z * np.sum(z * v, axis=-1, keepdims=True), axis=-1)
    norm = np.hypot(c, s)
    c, s = (
        np.where(norm > 1e-30, c / np.maximum(norm, 1e-30), 1.0),
        np.where(norm > 1e-30, s / np.maximum(norm, 1e-30), 0.0),
    )
    r = c[..., None] * z - s[..., None] * x
    e1 = c[..., None] * x + s[..., None] * z
    rho = np.hypot(r[..., 0], r[..., 1])
    ok = rho * rho > 1e-30
    cp = np.where(ok, r[..., 0] / np.where(ok, rho, 1.0), 1.0)
    sp = np.where(ok, r[..., 1] / np.where(ok, rho, 1.0), 0.0)
    u = 0.5 - np.arctan2(r[..., 1], r[..., 0]) / (2.0 * np.pi)
    t = np.arccos(np.clip(r[..., 2], -1.0, 1.0)) / np.pi
    along = r[..., 2] * (e1[..., 0] * cp + e1[..., 1] * sp) - e1[..., 2] * rho  # e1·a1
    across = e1[..., 1] * cp - e1[..., 0] * sp  # e1·a2
    views_count, azimuths = int(shape[2]), int(shape[3])
    theta_pos = np.arctan2(s, c) / (0.5 * np.pi) * (views_count - 1)
    psi_pos = np.mod(np.arctan2(across, along) / (2.0 * np.pi) * azimuths, azimuths)
    return u, t, theta_pos, psi_pos


def node_weights(theta_pos, psi_pos, views_count: int, azimuths: int) -> tuple:
    """(j0, wj, k0, k1, wk): the view-angle node below each pixel's θo position and the weight of
    the one above ((N, 1)), the azimuths either side of its ψ position and the weight of the
    second, as tf_radiance_grid.glsl's tf_grid_at interpolates them."""
    j0 = np.minimum(np.floor(np.clip(theta_pos, 0, views_count - 1)).astype(int), views_count - 2)
    wj = (np.clip(theta_pos, 0, views_count - 1) - j0)[:, None]
    k0 = np.minimum(np.floor(psi_pos).astype(int), azimuths - 1)
    wk = (psi_pos - k0)[:, None]
    return j0, wj, k0, np.mod(k0 + 1, azimuths), wk


def _bilinear(grid: np.ndarray, layers, u, t) -> np.ndarray:
    """GL LINEAR filtering of ``grid`` (L, H, W, 3) in per-pixel ``layers`` at (u, t): REPEAT in
    u, EXTEND in t."""
    _n, h, w, _c = grid.shape
    x = np.asarray(u) * w - 0.5
    y = np.asarray(t) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    wx, wy = (x - x0)[..., None], (y - y0)[..., None]
    i0 = np.mod(x0.astype(int), w)
    i1 = np.mod(i0 + 1, w)
    j0 = np.clip(y0.astype(int), 0, h - 1)
    j1 = np.clip(y0.astype(int) + 1, 0, h - 1)
    a = grid[layers, j0, i0] * (1 - wx) + grid[layers, j0, i1] * wx
    b = grid[layers, j1, i0] * (1 - wx) + grid[layers, j1, i1] * wx
    return a * (1 - wy) + b * wy


def lookup(
    grid: np.ndarray, normals, views, azimuths: int = GRID_AZIMUTHS, rotation=None, scale: float = 1.0
) -> np.ndarray:
    """The SH half per pixel from a :func:`build` grid (T·Ψ, H, W, 3) of ``azimuths`` = Ψ: (…, 3).

    Four layers (θo nodes j0, j0 + 1 × azimuths k0, k0 + 1 mod Ψ), each bilinear in the mirror
    direction; θo and ψ interpolated linearly (tf_radiance_grid.glsl, which reads T as the
    texture's layers ÷ Ψ).

    ``rotation`` Q (3×3 orthogonal, None: identity) and ``scale`` s: the grid was built from the
    World's *content* SH and the World is that content turned and scaled, L(d) = s · L_c(Q d)
    (the lighting buffer's ``world`` block, as the prefilter lookup). A BRDF depends only on
    the angles between n, v and the light, so the World's outgoing radiance is s times the
    content's at (Q n, Q v): a World strength or rotation edit rebuilds no grid.
    """
    if rotation is not None:
        q = np.asarray(rotation, dtype=float).reshape(3, 3)
        normals = np.asarray(normals, dtype=float) @ q.T
        views = np.asarray(views, dtype=float) @ q.T
    return float(scale) * _lookup(grid, normals, views, azimuths)


def _lookup(grid: np.ndarray, normals, views, azimuths: int) -> np.ndarray:
    g = np.asarray(grid, dtype=float)
    if g.ndim != 4 or g.shape[0] % int(azimuths):
        raise ValueError(f"a grid is (T·{azimuths}, H, W, 3), got {g.shape}")
    shape = (g.shape[2], g.shape[1], g.shape[0] // int(azimuths), int(azimuths))
    _w, _h, views_count, azimuths = _check_shape(shape)
    u, t, theta_pos, psi_pos = coordinates(normals, views, shape)
    flat = [np.ravel(a) for a in (u, t, theta_pos, psi_pos)]
    u, t, theta_pos, psi_pos = flat
    j0, wj, k0, k1, wk = node_weights(theta_pos, psi_pos, views_count, azimuths)

    def fetch(j, k):
        return _bilinear(g, j * azimuths + k, u, t)

    lo = (1 - wk) * fetch(j0, k0) + wk * fetch(j0, k1)
    hi = (1 - wk) * fetch(j0 + 1, k0) + wk * fetch(j0 + 1, k1)
    out = (1 - wj) * lo + wj * hi
    return out.reshape(np.shape(normals)[:-1] + (3,))
