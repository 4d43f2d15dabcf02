"""Solid glass refracts the scene behind it: the exit ray and its screen-space march (numpy twin of
glsl/tf_refract.glsl).

A film on solid glass (:data:`..transmit.WALL_SOLID`, a Principled BSDF with *Transmission* and no
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
   :data:`..policy.REFRACT_STEPS` …); each sample q is projected to the image (the view-projection
   matrix, then ``screen``: the pass's [0, 1] window → the image's uv) and read at its nearest
   texel. The first step where q's depth passes the image's depth (after one in front of it) is
   bisected :data:`..policy.REFRACT_REFINE` times against the depth between texel centres
   (bilinear in 1 / depth, exact for a plane); the hit is accepted where q lies at most
   :data:`..policy.REFRACT_THICKNESS` × its depth behind the surface (else the ray passed behind
   an occluder and marches on), and sees the image's colour at the hit point, bilinear between
   texel centres. A ray that leaves the image or the march sees nothing: the caller falls back to
   the headless frame's scene probe (:mod:`.probe`), else the World along w (the prefiltered
   World's sharpest level).

Smooth solid glass also reflects the scene behind where its mirror ray reflect(−v, n) meets it
(the same march from the shaded point): its film reflection gains
w · r (scene − World along the mirror ray), the World's part replaced by the scene's, with
w = :func:`mirror_weight` of its roughness and r the film's reflectance per channel.

A glass of index 1 thus sees the image unshifted (the ray goes straight on and hits the texel
behind the pixel), and a ball of glass inverts what lies behind it far enough, as a ball lens.
"""

from __future__ import annotations

import numpy as np

from ..policy import (
    REFRACT_EDGE,
    REFRACT_FAR,
    REFRACT_FIRST,
    REFRACT_GROWTH,
    REFRACT_LINE_EPS,
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


def _uv(q, view_proj, screen) -> tuple[np.ndarray, np.ndarray]:
    """(uv (N, 2), clip w (N,)) of world points ``q`` (N, 3): the view-projection, then the
    window's [0, 1] → uv (``screen``: sx, sy, ox, oy); v = 0 at the image's bottom."""
    clip = np.concatenate([q, np.ones(q.shape[:-1] + (1,))], axis=-1) @ np.asarray(view_proj).T
    w = clip[..., 3]
    safe = np.where(np.abs(w) > 1e-30, w, 1e-30)
    return (clip[..., :2] / safe[..., None] * 0.5 + 0.5) * screen[:2] + screen[2:], w


def _project(q, view_proj, screen, shape):
    """(row, column, inside) of world points ``q`` (N, 3) in an image of ``shape`` (H, W), top
    row first: the view-projection, then the window's [0, 1] → uv (``screen``: sx, sy, ox, oy)."""
    uv, w = _uv(q, view_proj, screen)
    h, width = shape
    col = np.floor(uv[..., 0] * width)
    row_up = np.floor(uv[..., 1] * h)
    inside = (w > 0.0) & (col >= 0) & (col < width) & (row_up >= 0) & (row_up < h)
    col = np.clip(col, 0, width - 1).astype(np.int64)
    row = (h - 1 - np.clip(row_up, 0, h - 1)).astype(np.int64)
    return row, col, inside


def on_picture(q, view_proj, screen, shape) -> np.ndarray:
    """(N,) whether world points ``q`` (N, 3) lie in the picture of ``shape`` (H, W) in front of
    the camera (``tf_refract_sample``'s test)."""
    return _project(np.asarray(q, dtype=np.float64), view_proj, screen, shape)[2]


def bilinear(image, rows, cols, spread: bool = False) -> np.ndarray:
    """``image`` (H, W, …) at the points (``rows``, ``cols``) (N,) in texel units, top row first
    (texel (i, j) spans [i, i + 1) × [j, j + 1)): interpolated between the four nearest texel
    centres, the edge texels held beyond them (GLSL: ``tf_behind_corners``). ``spread``: instead
    the (min, max) of the four, along a last axis of 2."""
    img = np.asarray(image, dtype=np.float64)
    h, w = img.shape[:2]
    y = np.asarray(rows, dtype=np.float64) - 0.5
    x = np.asarray(cols, dtype=np.float64) - 0.5
    y0, x0 = np.floor(y), np.floor(x)
    fy, fx = y - y0, x - x0
    r0, r1 = np.clip(y0, 0, h - 1).astype(np.int64), np.clip(y0 + 1, 0, h - 1).astype(np.int64)
    c0, c1 = np.clip(x0, 0, w - 1).astype(np.int64), np.clip(x0 + 1, 0, w - 1).astype(np.int64)
    if spread:
        four = np.stack([img[r0, c0], img[r0, c1], img[r1, c0], img[r1, c1]])
        return np.stack([four.min(axis=0), four.max(axis=0)], axis=-1)
    shape = (-1,) + (1,) * (img.ndim - 2)
    fy, fx = fy.reshape(shape), fx.reshape(shape)
    top = img[r0, c0] * (1.0 - fx) + img[r0, c1] * fx
    bottom = img[r1, c0] * (1.0 - fx) + img[r1, c1] * fx
    return top * (1.0 - fy) + bottom * fy


def _catmull_rom(t) -> np.ndarray:
    """Catmull–Rom's four weights (…, 4) at fraction ``t`` between the middle two samples."""
    t = np.asarray(t, dtype=np.float64)[..., None]
    t2, t3 = t * t, t * t * t
    return np.concatenate(
        [
            -0.5 * t3 + t2 - 0.5 * t,
            1.5 * t3 - 2.5 * t2 + 1.0,
            -1.5 * t3 + 2.0 * t2 + 0.5 * t,
            0.5 * t3 - 0.5 * t2,
        ],
        axis=-1,
    )


def sharp(image, depth, rows, cols) -> np.ndarray:
    """``image`` (H, W, C) at the points (``rows``, ``cols``) (N,) in texel units, top row first
    (GLSL: ``tf_behind_colour_at``): Catmull–Rom between the 4 × 4 texel centres around each,
    held within the range of the four nearest (no ringing), where those sixteen lie on one
    surface (``depth`` (H, W) within 1 + REFRACT_THICKNESS of each other, the empty World's at
    REFRACT_FAR) and inside the picture; else :func:`bilinear`. Bilinear weights are a tent a
    texel wide on top of the pixel filter the image was rendered with: through a ball's lens,
    which spreads the picture behind, the checker's edges came out 1.5× as wide as Cycles'."""
    img = np.asarray(image, dtype=np.float64)
    h, w = img.shape[:2]
    d = np.asarray(depth, dtype=np.float64)
    d = np.where(np.isfinite(d), np.minimum(d, REFRACT_FAR), REFRACT_FAR)
    y = np.asarray(rows, dtype=np.float64) - 0.5
    x = np.asarray(cols, dtype=np.float64) - 0.5
    y0, x0 = np.floor(y), np.floor(x)
    out = bilinear(img, rows, cols)
    inner = (y0 >= 1) & (y0 <= h - 3) & (x0 >= 1) & (x0 <= w - 3)
    if not inner.any():
        return out
    r = y0[inner].astype(np.int64)[:, None] + np.arange(-1, 3)[None]  # (M, 4)
    c = x0[inner].astype(np.int64)[:, None] + np.arange(-1, 3)[None]
    block = img[r[:, :, None], c[:, None, :]]  # (M, 4, 4, C)
    depths = d[r[:, :, None], c[:, None, :]].reshape(len(r), -1)
    wy, wx = _catmull_rom((y - y0)[inner]), _catmull_rom((x - x0)[inner])
    value = np.einsum("mi,mj,mij...->m...", wy, wx, block)
    middle = block[:, 1:3, 1:3].reshape(len(r), 4, *img.shape[2:])
    value = np.clip(value, middle.min(axis=1), middle.max(axis=1))
    smooth = depths.max(axis=1) <= (1.0 + REFRACT_THICKNESS) * depths.min(axis=1)
    out[inner] = np.where(smooth.reshape((-1,) + (1,) * (img.ndim - 2)), value, out[inner])
    return out


class _Scene:
    """The scene behind as the march reads it: depth (H, W, top row first, ``REFRACT_FAR`` where
    empty), the view, and the window → uv map."""

    def __init__(self, depth, view_proj, camera, view_dir, screen):
        d = np.asarray(depth, dtype=np.float64)
        self.depth = np.where(np.isfinite(d), np.minimum(d, REFRACT_FAR), REFRACT_FAR)
        self.inverse = np.where(self.depth < REFRACT_FAR, 1.0 / np.maximum(self.depth, 1e-300), 0.0)
        self.view_proj = np.asarray(view_proj, dtype=np.float64)
        self.camera = np.asarray(camera, dtype=np.float64).reshape(3)
        self.view_dir = np.asarray(view_dir, dtype=np.float64).reshape(3)
        self.screen = np.asarray(screen, dtype=np.float64).reshape(4)

    def sample(self, q):
        """(q's depth, the image's depth at q, row, column, inside) for points ``q`` (N, 3)."""
        row, col, inside = _project(q, self.view_proj, self.screen, self.depth.shape)
        z = (self.camera - q) @ self.view_dir
        return z, self.depth[row, col], row, col, inside & (z > 0.0)

    def surface(self, q):
        """(q's depth, the image's depth under q, q's row and column in texel units (top row
        first)) for points ``q`` (N, 3). Where the four nearest texels hold one surface (their
        depths within ``1 + REFRACT_THICKNESS`` of each other) the depth is interpolated between
        their centres, bilinear in 1 / depth (exact for a plane, whose 1 / depth is linear on
        the screen); elsewhere (an edge, the World) it is the nearest texel's, and the point is
        moved to that texel's centre, so that the colour read there is the texel's, not a mix
        across the edge. The nearest texel's depth alone is a staircase: a hit on a receding
        floor landed 0.23 texel nearer on average (docs/transparent-films.md#solid-glass-refraction)."""
        uv, _w = _uv(q, self.view_proj, self.screen)
        h, w = self.depth.shape
        rows, cols = h * (1.0 - uv[..., 1]), w * uv[..., 0]
        near = bilinear(self.depth, rows, cols, spread=True)
        lo, hi = near[..., 0], near[..., 1]
        smooth = hi <= (1.0 + REFRACT_THICKNESS) * lo
        between = bilinear(self.inverse, rows, cols)
        r_n = np.clip(np.floor(rows), 0, h - 1)
        c_n = np.clip(np.floor(cols), 0, w - 1)
        nearest = self.depth[r_n.astype(np.int64), c_n.astype(np.int64)]
        between = np.where(between > 0.0, 1.0 / np.maximum(between, 1e-300), REFRACT_FAR)
        depth = np.where(smooth, between, nearest)
        rows = np.where(smooth, rows, r_n + 0.5)
        cols = np.where(smooth, cols, c_n + 0.5)
        z = (self.camera - q) @ self.view_dir
        return z, depth, rows, cols


def _refine(scene, origins, dirs, lo, hi):
    """Bisect [lo, hi] (N,) to where the ray's depth passes the image's (:meth:`_Scene.surface`):
    the last ``hi``."""
    for _ in range(REFRACT_REFINE):
        mid = 0.5 * (lo + hi)
        z, d, _r, _c = scene.surface(origins + mid[:, None] * dirs)
        behind = z >= d
        hi = np.where(behind, mid, hi)
        lo = np.where(behind, lo, mid)
    return hi


def march(origins, dirs, depth, view_proj, camera, view_dir, screen, edge: bool = REFRACT_EDGE):
    """Where the rays ``origins`` + s ``dirs`` (N, 3) first hit the scene behind, an image of
    ``depth`` (H, W, top row first; distance along the camera axis, inf where empty): (hit (N,)
    bool, row (N,), column (N,)) of the point hit, in texel units (float; texel (i, j) spans
    [i, i + 1) × [j, j + 1)). ``view_proj`` (4 × 4), ``camera`` (its position), ``view_dir``
    (unit, towards the viewer) and ``screen`` (sx, sy, ox, oy: the drawn window's [0, 1]
    coordinates → the image's uv) place the image. See the module.
    ``edge``: a ray that leaves the picture after a sample inside it takes the centre of the texel
    of its last sample inside where that texel is a surface (the scene beyond the edge taken as
    the scene at the edge: a floor goes on), counted as a hit; else (the World there) it sees
    nothing. A ray in front of that surface must also be heading into it (:func:`_meets_ahead`):
    one that climbs away from a floor sees the World, not the floor's edge. The headless frame
    passes False where it has a scene probe (:mod:`.probe`, GLSL ``tf_behind_view.probe.w``): the
    probe shows where the scene beyond the edge ends (a floor 20 m long does not go on)."""
    scene = _Scene(depth, view_proj, camera, view_dir, screen)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    count = o.shape[0]
    scale = np.maximum((scene.camera - o) @ scene.view_dir, WALL_GUARD)
    hit = np.zeros(count, dtype=bool)
    active = np.ones(count, dtype=bool)
    prev_behind = np.zeros(count, dtype=bool)
    prev_s = np.zeros(count)
    rows = np.zeros(count, dtype=np.int64)  # the texel of each ray's last sample inside
    cols = np.zeros(count, dtype=np.int64)
    at_row, at_col = np.zeros(count), np.zeros(count)
    # the surface points under the last two samples inside, and the last one's s
    last_s, last_pt, prev_pt = np.zeros(count), np.full((count, 3), np.nan), np.full((count, 3), np.nan)
    for k in range(REFRACT_STEPS):
        s = scale * (REFRACT_FIRST * REFRACT_GROWTH**k)
        q = o + s[:, None] * w
        z, d, r_k, c_k, inside = scene.sample(q)
        leaving = active & ~inside & (scene.depth[rows, cols] < REFRACT_FAR)
        if edge and k > 0 and np.any(leaving):
            leaving &= prev_behind | _meets_ahead(o, w, last_s, prev_pt, last_pt)
            hit |= leaving  # rows, cols still hold the last sample inside: a surface
            at_row = np.where(leaving, rows + 0.5, at_row)
            at_col = np.where(leaving, cols + 0.5, at_col)
        active &= inside
        rows = np.where(active, r_k, rows)
        cols = np.where(active, c_k, cols)
        under = scene.camera + (q - scene.camera) * (d / np.maximum(z, WALL_GUARD))[:, None]
        prev_pt = np.where(active[:, None], last_pt, prev_pt)
        last_pt = np.where(active[:, None], np.where((d < REFRACT_FAR)[:, None], under, np.nan), last_pt)
        last_s = np.where(active, s, last_s)
        behind = z >= d
        cross = active & behind & ~prev_behind
        if np.any(cross):
            idx = np.flatnonzero(cross)
            s_hit = _refine(scene, o[idx], w[idx], prev_s[idx], s[idx])
            zh, dh, rh, ch = scene.surface(o[idx] + s_hit[:, None] * w[idx])
            ok = zh - dh <= REFRACT_THICKNESS * zh
            found = idx[ok]
            hit[found], at_row[found], at_col[found] = True, rh[ok], ch[ok]
            active[found] = False
        prev_behind, prev_s = behind, s
    return hit, at_row, at_col


def _meets_ahead(o, w, s, a, b) -> np.ndarray:
    """Whether the rays o + t w (N, 3) meet the line through the surface points ``a`` and ``b``
    (N, 3; NaN where unknown) beyond t = ``s`` (N,). a and b lie under two samples of the ray, on
    the plane through the camera and the ray, so the line is the surface's trace in that plane
    (exact for a plane): where the ray crosses it. Unknown points, or points too close together
    to give a direction, count as met (the picture's edge taken as before)."""
    e = b - a
    m = np.cross(w, e)
    mm = np.sum(m * m, axis=-1)
    ee = np.sum(e * e, axis=-1)
    known = np.isfinite(mm) & (ee > REFRACT_LINE_EPS * np.maximum(np.sum(a * a, axis=-1), 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = -np.sum(np.cross(o - a, e) * m, axis=-1) / mm
    return ~known | ((mm > REFRACT_LINE_EPS * ee) & (t > s))


def mirror_weight(roughness) -> float:
    """How much of the scene behind smooth solid glass reflects in place of the World: 1 at
    roughness 0, falling linearly to 0 at :data:`..policy.REFRACT_MIRROR_ROUGHNESS`."""
    return float(np.clip(1.0 - float(roughness) / REFRACT_MIRROR_ROUGHNESS, 0.0, 1.0))


def seen(hit, rows, cols, colour, fallback, depth) -> np.ndarray:
    """The colour (N, 3) each ray sees: the image ``colour`` (H, W, 3) at its hit point (``rows``,
    ``cols`` in texel units, :func:`march`; :func:`sharp` between texel centres over the image's
    ``depth`` (H, W)), else ``fallback`` (N, 3): the World along the exit ray."""
    c = sharp(np.asarray(colour, dtype=np.float64)[..., :3], depth, rows, cols)
    return np.where(np.asarray(hit)[:, None], c, np.asarray(fallback, dtype=np.float64))


def inner_cosine(cos_outside, eta: float) -> np.ndarray:
    """cos θₜ inside glass of index ``eta`` of a ray entering at cos θᵢ = ``cos_outside`` (…,):
    the cosine at which it meets a sphere's far side."""
    c = np.clip(np.asarray(cos_outside, dtype=np.float64), 0.0, 1.0)
    return np.sqrt(np.maximum(1.0 - (1.0 - c * c) / (max(float(eta), WALL_GUARD) ** 2), 0.0))
