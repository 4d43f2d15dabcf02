"""A closed thin wall's reflections inside it (numpy twin of ``tf_inside_step`` and ``tf_wall_inside``).

Seen through a bubble, the far wall reflects the World back into the bubble: that light must
still leave through the wall it meets next, and part of it is reflected again, and again.
The walls' draw (:mod:`.transmit`) gives the far wall's reflection as if it left freely:
S·r·L along d₁ = reflect(−v, n). Cycles traces the rest, and over a bubble in front of a studio
HDRI the lamps seen after two and three reflections inside are coloured arcs worth 1.3 mean
ΔE2000 (docs/transparent-films.md).

The path inside is traced on the **sphere about the object's origin through the far wall's
point** p₁ (exact for a spherical bubble, the shape a closed soap film takes; the same
stand-in as solid glass without its buffers, :mod:`.refract`). A thin wall does not bend the
ray, so from p₁ the ray d₁ crosses a chord to p₂ = p₁ + t d₁, t = −2 (p₁ − c)·d₁, is reflected
there about the sphere's normal, and so on; on a sphere every hit is met at the same angle. At
each hit the film has its own thickness: the per-vertex thickness parameter's least-squares
linear fit over the mesh (:func:`mesh_inside`; exact where it is linear in position, the
benchmark's Map Range over x), evaluated at the hit. Where the fit explains less than
:data:`.policy.INSIDE_MIN_EXPLAINED` of the thickness's variance (a noise: the Soap Film
preset's) the thickness at the other hits is not known and the reflections inside are left out
(:attr:`Inside.drawn`): read at the fit's mean thickness they took the soap bubble sample scene
from 12.07 to 12.20 mean ΔE2000. With R_k, T_k the wall's reflectance and transmittance at hit
k (:func:`.transmit.wall`: R = S·r):

    far wall's reflection  S₁r₁·L(d₁)  →  S₁r₁·L(d₁)·T₂ + R₁·(R₂T₃·L(d₂) + R₂R₃T₄·L(d₃) + …)

to :data:`.policy.INSIDE_ORDERS` reflections after the first (:func:`inside_reflections`
returns the factor T₂ and the bracket). L is the prefiltered World at the film's roughness
(the draw's split sum); Blender's light objects and, where the prefilter has lifted them out
(roughness from level ``policy.LAMP_LEVEL`` of the ladder), the World's lamps are not in the
later reflections. Only a closed mesh (every edge shared by two triangles of the slot) has an
inside; an open sheet's back face is just its other side.

Pure numpy; never imports ``bpy``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import transmit
from .lamps import thickness_lerp
from .policy import INSIDE_MIN_EXPLAINED, INSIDE_ORDERS

__all__ = ["Inside", "inside_path", "inside_reflections", "mesh_inside", "world_fit"]


@dataclass(frozen=True)
class Inside:
    """What a wall's mesh offers its reflections inside: ``closed`` (every edge shared by two
    triangles), ``fit`` (4,): the thickness parameter ≈ fit[:3]·p + fit[3] over object-space
    positions p (zeros for a constant thickness), and ``explained``: the share of the thickness's
    variance the fit explains (R²; 1 for a constant thickness)."""

    closed: bool
    fit: tuple = (0.0, 0.0, 0.0, 0.0)
    explained: float = 1.0

    @property
    def drawn(self) -> bool:
        """Whether the draw adds the reflections inside: a closed mesh whose thickness the fit
        explains (:data:`.policy.INSIDE_MIN_EXPLAINED`; a noise is not: module docstring)."""
        return self.closed and self.explained >= INSIDE_MIN_EXPLAINED


def _welded(positions: np.ndarray) -> np.ndarray:
    """Per-corner ids (int64) equal where the corners share a position exactly (the corners of
    one vertex): a sort of the positions' bits (0.2 s for a million corners)."""
    bits = np.ascontiguousarray(np.asarray(positions, dtype=np.float32).reshape(-1, 3)).view(np.uint32)
    order = np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0]))
    ordered = bits[order]
    new = np.ones(len(ordered), dtype=bool)
    new[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    ids = np.empty(len(ordered), dtype=np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids


def _closed(ids: np.ndarray) -> bool:
    """Whether every edge of the (F, 3) triangles of vertex ``ids`` is shared by exactly two."""
    edges = np.sort(np.concatenate([ids[:, [0, 1]], ids[:, [1, 2]], ids[:, [2, 0]]]), axis=1)
    edges = edges[edges[:, 0] != edges[:, 1]]  # degenerate triangles' collapsed edges
    if edges.shape[0] == 0:
        return False
    keys = np.sort(edges[:, 0] * (int(ids.max()) + 1) + edges[:, 1])
    starts = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1], [True]]))
    return bool(np.all(np.diff(starts) == 2))


#: Corners a thickness fit reads at most (every k-th beyond): the fit of a million corners is as
#: good from a tenth of them, and the batch build stays short.
FIT_CORNERS = 100_000


def mesh_inside(positions, triangles, thickness=None) -> Inside:
    """:class:`Inside` of a mesh given per corner: (V, 3) ``positions``, (F, 3) ``triangles``
    (corner indices) and the optional (V,) ``thickness`` parameter in [0, 1]. About 0.4 s for a
    million corners (the batch build, not a draw)."""
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tris.shape[0] == 0:
        return Inside(False)
    closed = _closed(_welded(positions)[tris])
    if thickness is None:
        return Inside(closed)
    step = max(1, len(thickness) // FIT_CORNERS)
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)[::step]
    th = np.asarray(thickness, dtype=np.float64).reshape(-1)[::step]
    ok = np.isfinite(th)
    if ok.sum() < 4:
        return Inside(closed, (0.0, 0.0, 0.0, float(np.nanmean(th)) if ok.any() else 0.5))
    design = np.concatenate([pos[ok], np.ones((int(ok.sum()), 1))], axis=1)
    coefficients = np.linalg.lstsq(design, th[ok], rcond=None)[0]
    total = float(np.sum((th[ok] - th[ok].mean()) ** 2))
    residual = float(np.sum((design @ coefficients - th[ok]) ** 2))
    explained = 1.0 if total <= 1e-12 * ok.sum() else max(0.0, 1.0 - residual / total)
    return Inside(closed, tuple(float(c) for c in coefficients), explained)


def world_fit(fit, model) -> np.ndarray:
    """The object-space ``fit`` (4,) over world positions under the 4×4 ``model`` matrix:
    g·M⁻¹(p − o) + a = (M⁻ᵀ g)·p + (a − (M⁻ᵀ g)·o)."""
    fit = np.asarray(fit, dtype=np.float64).reshape(4)
    m = np.asarray(model, dtype=np.float64).reshape(4, 4)
    g = np.linalg.pinv(m[:3, :3]).T @ fit[:3]
    return np.array([*g, fit[3] - g @ m[:3, 3]])


def inside_path(points, directions, centre, orders: int = INSIDE_ORDERS + 1) -> list:
    """The ray inside the sphere about ``centre`` through ``points`` (N, 3), leaving them along
    ``directions`` (N, 3, into the sphere): ``orders`` hits, each (points, directions reflected
    there, cosine), as ``tf_inside_step``. A direction that does not enter the sphere stays where
    it is with cosine 0 (:func:`inside_reflections` then lets it leave freely)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    hits = []
    for _ in range(orders):
        chord = np.maximum(-2.0 * np.sum((p - c) * d, axis=-1), 0.0)
        p = p + chord[:, None] * d
        radius = p - c
        length = np.linalg.norm(radius, axis=-1, keepdims=True)
        n = np.where(length > 0.0, radius / np.maximum(length, 1e-300), -d)  # outward
        cos = np.clip(np.sum(d * n, axis=-1), 0.0, 1.0)
        d = d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n
        hits.append((p, d, np.where(chord > 0.0, cos, 0.0)))
    return hits


def inside_reflections(film, points, normals, views, centre, fit, mode: int, eta: float, tint, radiance):
    """(T₂, extra), each (N, 3): the far wall's reflection is S₁r₁·L(d₁)·T₂ + R₁·extra (module
    docstring). ``points`` on the far wall with ``normals`` facing the viewer (inward) and
    ``views`` towards the viewer; ``fit``: :func:`world_fit` (None: a constant thickness, the
    table's first row); ``radiance``: directions (N, 3) → (N, 3), the World along them."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    d1 = -v + 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n  # reflect(-v, n)
    hits = inside_path(points, d1, centre)

    def wall_at(p, cos):
        position = None if fit is None else np.clip(p @ np.asarray(fit[:3]) + fit[3], 0.0, 1.0)
        rows = thickness_lerp(film, position, p.shape[0])
        r = np.clip(transmit.white_reflectance(film, rows, cos), 0.0, 1.0)
        t, s = transmit.wall(r, cos, mode, eta, tint)
        return s * r, t

    reflectance, exit_t = wall_at(hits[0][0], hits[0][2])
    extra = np.zeros_like(exit_t)
    carried = np.ones_like(exit_t)
    for (_p, d, _cos), (p_next, _d, cos_next) in zip(hits[:-1], hits[1:], strict=True):
        carried = carried * reflectance
        reflectance, t_next = wall_at(p_next, cos_next)
        extra = extra + carried * t_next * radiance(d)
    entered = (hits[0][2] > 0.0)[:, None]  # else d₁ leaves the sphere at once: freely
    return np.where(entered, exit_t, 1.0), np.where(entered, extra, 0.0)
