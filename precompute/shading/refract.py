"""Solid glass refracts the scene behind it: the exit ray and its screen-space march (numpy twin of
glsl/tf_refract.glsl).

A film on solid glass (:data:`.transmit.WALL_SOLID`, a Principled BSDF with *Transmission* and no
*Thin Wall*) replaces what is behind it by what the ray sees after passing through the glass.
Two steps, both per pixel:

1. **Through the glass** (:func:`exit_ray`). The ray −v refracts in at the shaded point p with
   normal n (relative index η), crosses the glass to the exit point and refracts out. The glass
   is taken as the sphere about the object's origin c through p (radius ‖p − c‖): exact for a
   sphere about its origin, and the only shape the draw knows without a back-face pass; a long
   or flat glass object is refracted as if it were that sphere (docs/transparent-films.md).
   The far hit of the inner ray t (unit) on that sphere is p + L t with L = −2 (p − c)·t;
   the exit normal n₂ = (p₂ − c) / ‖p₂ − c‖ and the exit direction refract(t, −n₂, η). Under
   total internal reflection at the exit (only where n differs from the sphere's normal) the
   ray goes on along t.
2. **Over the scene behind** (:func:`march`). The scene without the glass is an image with its
   depth d (the distance along the camera axis, the headless frame's background pass). The exit
   ray p₂ + s w is sampled at s_k = z₂ · FIRST · GROWTH^k (z₂: the exit point's depth; k < STEPS,
   :data:`.policy.REFRACT_STEPS` …); each sample q is projected to the image (the view-projection
   matrix, then ``screen``: the pass's [0, 1] window → the image's uv) and read at its nearest
   texel. The first step where q's depth passes the image's depth (after one in front of it) is
   bisected :data:`.policy.REFRACT_REFINE` times; the hit is accepted where q lies at most
   :data:`.policy.REFRACT_THICKNESS` × its depth behind the surface (else the ray passed behind
   an occluder and marches on). A ray that leaves the image or the march sees nothing: the caller
   falls back to the World along w (the prefiltered World's sharpest level).

Smooth solid glass also reflects the scene behind where its mirror ray reflect(−v, n) meets it
(the same march from the shaded point): its film reflection gains
w · r (scene − World along the mirror ray), the World's part replaced by the scene's, with
w = :func:`mirror_weight` of its roughness and r the film's reflectance per channel.

A glass of index 1 thus sees the image unshifted (the ray goes straight on and hits the texel
behind the pixel), and a ball of glass inverts what lies behind it far enough, as a ball lens.
"""

from __future__ import annotations

import numpy as np

from .policy import (
    REFRACT_FAR,
    REFRACT_FIRST,
    REFRACT_GROWTH,
    REFRACT_MIRROR_ROUGHNESS,
    REFRACT_REFINE,
    REFRACT_STEPS,
    REFRACT_THICKNESS,
    TIR_EPS,
    WALL_GUARD,
)


def refract(incident, normal, eta) -> np.ndarray:
    """GLSL's ``refract(I, N, eta)`` row by row (…, 3): the unit ``incident`` direction refracted
    at the unit ``normal`` (facing against it) with the index ratio ``eta`` = n₁ / n₂; zero under
    total internal reflection."""
    i = np.asarray(incident, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    d = np.sum(n * i, axis=-1, keepdims=True)
    k = 1.0 - eta * eta * (1.0 - d * d)
    out = eta * i - (eta * d + np.sqrt(np.maximum(k, 0.0))) * n
    return np.where(k < 0.0, 0.0, out)


def _unit(x, fallback) -> np.ndarray:
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    return np.where(norm > 1e-12, x / np.maximum(norm, 1e-300), fallback)


def exit_ray(points, normals, views, centre, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """(exit points, exit directions), each (N, 3), of rays from the viewer (unit ``views``
    towards it) entering glass of index ``eta`` at ``points`` with unit ``normals`` (facing the
    viewer); the glass is the sphere about ``centre`` through each point (see the module)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    eta = max(float(eta), WALL_GUARD)
    inner = _unit(refract(-v, n, 1.0 / eta), -v)
    chord = np.maximum(-2.0 * np.sum((p - c) * inner, axis=-1, keepdims=True), 0.0)
    exit_point = p + chord * inner
    n2 = _unit(exit_point - c, inner)
    out = refract(inner, -n2, eta)
    tir = np.sum(out * out, axis=-1, keepdims=True) < TIR_EPS
    return exit_point, np.where(tir, inner, _unit(out, inner))


def _project(q, view_proj, screen, shape):
    """(row, column, inside) of world points ``q`` (N, 3) in an image of ``shape`` (H, W), top
    row first: the view-projection, then the window's [0, 1] → uv (``screen``: sx, sy, ox, oy)."""
    clip = np.concatenate([q, np.ones(q.shape[:-1] + (1,))], axis=-1) @ np.asarray(view_proj).T
    w = clip[..., 3]
    safe = np.where(np.abs(w) > 1e-30, w, 1e-30)
    uv = (clip[..., :2] / safe[..., None] * 0.5 + 0.5) * screen[:2] + screen[2:]
    h, width = shape
    col = np.floor(uv[..., 0] * width)
    row_up = np.floor(uv[..., 1] * h)
    inside = (w > 0.0) & (col >= 0) & (col < width) & (row_up >= 0) & (row_up < h)
    col = np.clip(col, 0, width - 1).astype(np.int64)
    row = (h - 1 - np.clip(row_up, 0, h - 1)).astype(np.int64)
    return row, col, inside


class _Scene:
    """The scene behind as the march reads it: depth (H, W, top row first, ``REFRACT_FAR`` where
    empty), the view, and the window → uv map."""

    def __init__(self, depth, view_proj, camera, view_dir, screen):
        d = np.asarray(depth, dtype=np.float64)
        self.depth = np.where(np.isfinite(d), np.minimum(d, REFRACT_FAR), REFRACT_FAR)
        self.view_proj = np.asarray(view_proj, dtype=np.float64)
        self.camera = np.asarray(camera, dtype=np.float64).reshape(3)
        self.view_dir = np.asarray(view_dir, dtype=np.float64).reshape(3)
        self.screen = np.asarray(screen, dtype=np.float64).reshape(4)

    def sample(self, q):
        """(q's depth, the image's depth at q, row, column, inside) for points ``q`` (N, 3)."""
        row, col, inside = _project(q, self.view_proj, self.screen, self.depth.shape)
        z = (self.camera - q) @ self.view_dir
        return z, self.depth[row, col], row, col, inside & (z > 0.0)


def _refine(scene, origins, dirs, lo, hi):
    """Bisect [lo, hi] (N,) to where the ray's depth passes the image's: the last ``hi``."""
    for _ in range(REFRACT_REFINE):
        mid = 0.5 * (lo + hi)
        z, d, _r, _c, _in = scene.sample(origins + mid[:, None] * dirs)
        behind = z >= d
        hi = np.where(behind, mid, hi)
        lo = np.where(behind, lo, mid)
    return hi


def march(origins, dirs, depth, view_proj, camera, view_dir, screen):
    """Where the rays ``origins`` + s ``dirs`` (N, 3) first hit the scene behind, an image of
    ``depth`` (H, W, top row first; distance along the camera axis, inf where empty): (hit (N,)
    bool, row (N,), column (N,)) of the texel hit. ``view_proj`` (4 × 4), ``camera`` (its
    position), ``view_dir`` (unit, towards the viewer) and ``screen`` (sx, sy, ox, oy: the
    drawn window's [0, 1] coordinates → the image's uv) place the image. See the module."""
    scene = _Scene(depth, view_proj, camera, view_dir, screen)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    count = o.shape[0]
    scale = np.maximum((scene.camera - o) @ scene.view_dir, WALL_GUARD)
    hit = np.zeros(count, dtype=bool)
    active = np.ones(count, dtype=bool)
    prev_behind = np.zeros(count, dtype=bool)
    prev_s = np.zeros(count)
    rows = np.zeros(count, dtype=np.int64)
    cols = np.zeros(count, dtype=np.int64)
    for k in range(REFRACT_STEPS):
        s = scale * (REFRACT_FIRST * REFRACT_GROWTH**k)
        z, d, _r, _c, inside = scene.sample(o + s[:, None] * w)
        active &= inside
        behind = z >= d
        cross = active & behind & ~prev_behind
        if np.any(cross):
            idx = np.flatnonzero(cross)
            s_hit = _refine(scene, o[idx], w[idx], prev_s[idx], s[idx])
            zh, dh, rh, ch, _ = scene.sample(o[idx] + s_hit[:, None] * w[idx])
            ok = zh - dh <= REFRACT_THICKNESS * zh
            found = idx[ok]
            hit[found], rows[found], cols[found] = True, rh[ok], ch[ok]
            active[found] = False
        prev_behind, prev_s = behind, s
    return hit, rows, cols


def mirror_weight(roughness) -> float:
    """How much of the scene behind smooth solid glass reflects in place of the World: 1 at
    roughness 0, falling linearly to 0 at :data:`.policy.REFRACT_MIRROR_ROUGHNESS`."""
    return float(np.clip(1.0 - float(roughness) / REFRACT_MIRROR_ROUGHNESS, 0.0, 1.0))


def seen(hit, rows, cols, colour, fallback) -> np.ndarray:
    """The colour (N, 3) each ray sees: the image ``colour`` (H, W, 3) at its hit texel, else
    ``fallback`` (N, 3): the World along the exit ray."""
    c = np.asarray(colour, dtype=np.float64)[rows, cols, :3]
    return np.where(np.asarray(hit)[:, None], c, np.asarray(fallback, dtype=np.float64))
