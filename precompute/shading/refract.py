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
   bisected :data:`.policy.REFRACT_REFINE` times against the depth between texel centres
   (bilinear in 1 / depth, exact for a plane); the hit is accepted where q lies at most
   :data:`.policy.REFRACT_THICKNESS` × its depth behind the surface (else the ray passed behind
   an occluder and marches on), and sees the image's colour at the hit point, bilinear between
   texel centres. A ray that leaves the image or the march sees nothing: the caller falls back to
   the World along w (the prefiltered World's sharpest level).

Smooth solid glass also reflects the scene behind where its mirror ray reflect(−v, n) meets it
(the same march from the shaded point): its film reflection gains
w · r (scene − World along the mirror ray), the World's part replaced by the scene's, with
w = :func:`mirror_weight` of its roughness and r the film's reflectance per channel.

A glass of index 1 thus sees the image unshifted (the ray goes straight on and hits the texel
behind the pixel), and a ball of glass inverts what lies behind it far enough, as a ball lens.
"""

from __future__ import annotations

import numpy as np

from ..brdf import reflect
from .policy import (
    GLASS_BOUNCES,
    GLASS_REACH,
    GLASS_REFINE,
    GLASS_SLACK,
    GLASS_STEPS,
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
    VALID_REFLECTION_RISE,
    VALID_REFLECTION_SCALE,
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
    one that climbs away from a floor sees the World, not the floor's edge."""
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
    roughness 0, falling linearly to 0 at :data:`.policy.REFRACT_MIRROR_ROUGHNESS`."""
    return float(np.clip(1.0 - float(roughness) / REFRACT_MIRROR_ROUGHNESS, 0.0, 1.0))


def seen(hit, rows, cols, colour, fallback) -> np.ndarray:
    """The colour (N, 3) each ray sees: the image ``colour`` (H, W, 3) at its hit point (``rows``,
    ``cols`` in texel units, :func:`march`; bilinear between texel centres), else ``fallback``
    (N, 3): the World along the exit ray."""
    c = bilinear(np.asarray(colour, dtype=np.float64)[..., :3], rows, cols)
    return np.where(np.asarray(hit)[:, None], c, np.asarray(fallback, dtype=np.float64))


# ----------------------------------------------------------------------------------------------
# The exit through the real mesh (the glass buffers)
# ----------------------------------------------------------------------------------------------


def glass_texel(encoded) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(object id (…,) int, unit outward normal (…, 3), depth (…,)) of glass-buffer texels
    (…, 4): .xyz the normal times (id + 1), .w the depth along the camera axis; id −1 where empty
    (a zero texel)."""
    e = np.asarray(encoded, dtype=np.float64)
    length = np.linalg.norm(e[..., :3], axis=-1)
    ids = np.rint(length).astype(np.int64) - 1
    normal = e[..., :3] / np.maximum(length, 1e-30)[..., None]
    return ids, normal, e[..., 3]


def octahedral(normals) -> np.ndarray:
    """Unit vectors (…, 3) → their octahedral coordinates (…, 2) in [−1, 1]² (the lower half
    folded over the diagonals), as tf_oct_encode: how the glass buffers keep a face's geometric
    normal in two floats."""
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.maximum(np.sum(np.abs(n), axis=-1, keepdims=True), 1e-30)
    xy = n[..., :2]
    folded = (1.0 - np.abs(xy[..., ::-1])) * np.where(xy >= 0.0, 1.0, -1.0)
    return np.where(n[..., 2:3] >= 0.0, xy, folded)


def from_octahedral(coords) -> np.ndarray:
    """Octahedral coordinates (…, 2) → unit vectors (…, 3) (:func:`octahedral`'s inverse), as
    tf_oct_decode."""
    e = np.asarray(coords, dtype=np.float64)
    z = 1.0 - np.abs(e[..., 0]) - np.abs(e[..., 1])
    t = np.maximum(-z, 0.0)
    x = e[..., 0] + np.where(e[..., 0] >= 0.0, -t, t)
    y = e[..., 1] + np.where(e[..., 1] >= 0.0, -t, t)
    n = np.stack([x, y, z], axis=-1)
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)


def geometric_texel(encoded) -> tuple[np.ndarray, np.ndarray]:
    """(front, back) unit outward geometric normals (…, 3) of the geometric glass buffer's texels
    (…, 4): .xy the front face's, .zw the back face's, octahedral (:func:`octahedral`)."""
    e = np.asarray(encoded, dtype=np.float64)
    return from_octahedral(e[..., :2]), from_octahedral(e[..., 2:])


def valid_normal(geometric, incoming, normal) -> np.ndarray:
    """The shading normal Cycles uses for a smooth glass's reflection and refraction (…, 3)
    (``ensure_valid_specular_reflection``, Blender 5.2, a material's *Bump Map Correction*, on
    by default): ``normal`` where the mirror of the unit ``incoming`` direction (towards where the
    light goes back to, facing ``geometric``) about it rises at least min(0.9 cos, 0.01) above the
    face's plane (cos = incoming · geometric; :data:`.policy.VALID_REFLECTION_SCALE`, ``_RISE``),
    else that normal turned towards ``geometric`` in their plane just far enough that the mirror
    rises exactly that much. All three face the incoming side. As tf_valid_normal."""
    ng = np.asarray(geometric, dtype=np.float64)
    wi = np.asarray(incoming, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    mirror = reflect(wi, n)
    iz = np.sum(wi * ng, axis=-1)
    threshold = np.minimum(VALID_REFLECTION_SCALE * iz, VALID_REFLECTION_RISE)
    keep = np.sum(ng * mirror, axis=-1) >= threshold
    x = _unit(n - np.sum(n * ng, axis=-1, keepdims=True) * ng, n)
    ix = np.sum(wi * x, axis=-1)
    a = np.maximum(ix * ix + iz * iz, 1e-30)
    b = 2.0 * (a + iz * threshold)
    c = (threshold + iz) ** 2
    root = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
    nz2 = np.where(ix < 0.0, 0.25 * (b + root) / a, 0.25 * (b - root) / a)
    along, up = np.sqrt(np.maximum(1.0 - nz2, 0.0)), np.sqrt(np.maximum(nz2, 0.0))
    turned = along[..., None] * x + up[..., None] * ng
    return np.where(keep[..., None], n, turned)


def _face_step(d, face_n, face_g, eta: float):
    """One face met from inside by the unit ray ``d`` (N, 3), outward shading and geometric
    normals ``face_n`` and ``face_g``, as Cycles' smooth glass meets it: (cosine inside, refracted
    direction out (0 under total internal reflection), mirrored direction, whether the refracted
    and the mirrored directions are valid). The normal is :func:`valid_normal` facing back inside;
    a direction is valid where it leaves on its side of both the face and that normal (Cycles
    drops the rest: its path ends)."""
    g_in = -face_g
    n_in = valid_normal(g_in, -d, -face_n)
    cos_face = np.clip(-np.sum(d * n_in, axis=-1), 0.0, 1.0)
    out = refract(d, n_in, eta)
    mirrored = _unit(-reflect(d, n_in), d)
    out_ok = (np.sum(g_in * out, axis=-1) < 0.0) & (np.sum(n_in * out, axis=-1) < 0.0)
    mirror_ok = (np.sum(g_in * mirrored, axis=-1) > 0.0) & (np.sum(n_in * mirrored, axis=-1) > 0.0)
    facing = np.sum(n_in * -d, axis=-1) > 0.0
    return cos_face, out, mirrored, out_ok & facing, mirror_ok & facing


def _layers(buffer) -> np.ndarray:
    """A glass buffer as its layers (L, H, W, 4): one (H, W, 4) is one layer."""
    b = np.asarray(buffer, dtype=np.float64)
    return b[None] if b.ndim == 3 else b


class _Glass:
    """The glass buffers as the mesh march reads them: front and back (L, H, W, 4) top row first,
    their L faces per pixel nearest first (depth peeling; one (H, W, 4) is one layer;
    :func:`glass_texel`), their faces' geometric normals ``geometric`` (:func:`geometric_texel`;
    None: the shading normals stand in), placed in the drawn window by ``screen``, as
    :class:`_Scene`.

    The object ``own``'s spans along a pixel's camera ray are its layers: layer 0 from its front
    face (or from the camera where the front buffer's face there is another's) to its back face,
    each further layer from its front face to its back face, where both are ``own``'s."""

    def __init__(self, front, back, view_proj, camera, view_dir, screen, geometric=None):
        self.front = glass_texel(_layers(front))
        self.back = glass_texel(_layers(back))
        if geometric is None:
            self.front_g, self.back_g = self.front[1], self.back[1]
        else:
            self.front_g, self.back_g = geometric_texel(_layers(geometric))
        self.layers = self.back[0].shape[0]
        self.view_proj = np.asarray(view_proj, dtype=np.float64)
        self.camera = np.asarray(camera, dtype=np.float64).reshape(3)
        self.view_dir = np.asarray(view_dir, dtype=np.float64).reshape(3)
        self.screen = np.asarray(screen, dtype=np.float64).reshape(4)

    def spans(self, q, own):
        """(row, column, inside the picture, depth z (N,), valid (L, N), front depth (L, N),
        back depth (L, N)) of points ``q``: ``own``'s spans on their pixels (see the class; an
        open layer 0 starts at −REFRACT_FAR)."""
        row, col, inside = _project(q, self.view_proj, self.screen, self.back[0].shape[1:])
        z = (self.camera - q) @ self.view_dir
        id_f, d_f = self.front[0][:, row, col], self.front[2][:, row, col]
        id_b, d_b = self.back[0][:, row, col], self.back[2][:, row, col]
        valid = id_b == own
        valid[1:] &= id_f[1:] == own
        f = np.where(id_f == own, d_f, -REFRACT_FAR)
        return row, col, inside, z, valid, f, d_b

    def outside(self, q, own):
        """(outside (N,), through a back face (N,), that face's layer (N,), row, column, inside the
        picture) of points ``q``: whether q lies outside every span of the object ``own`` along
        its pixel's camera ray, and the face it lies beyond: the nearest back face it lies behind
        or front face it lies in front of (layer 0's back where it lies beyond none: off the
        object's silhouette)."""
        row, col, inside, z, valid, f, b = self.spans(q, own)
        slack = GLASS_SLACK * z
        within = valid & (z <= b + slack) & (z >= f - slack)
        beyond = np.concatenate(
            [
                np.where(valid & (z > b + slack), z - b, np.inf),
                np.where(valid & (z < f - slack), f - z, np.inf),
            ]
        )
        nearest = np.argmin(beyond, axis=0)
        none = ~np.isfinite(np.min(beyond, axis=0))
        through_back = (nearest < self.layers) | none
        layer = np.where(none, 0, nearest % self.layers)
        return ~within.any(axis=0), through_back, layer, row, col, inside

    def face(self, through_back, layer, row, col):
        """(outward normal, geometric normal) (N, 3) of the faces :meth:`outside` names."""
        n = np.where(through_back[:, None], self.back[1][layer, row, col], self.front[1][layer, row, col])
        g = np.where(through_back[:, None], self.back_g[layer, row, col], self.front_g[layer, row, col])
        return n, g


def _march_inside(glass, o, d, reach, own):
    """Where the rays o + s d (N, 3), s in (0, reach], first leave the object ``own``: (found,
    s, the face's outward normal, its geometric normal). GLASS_STEPS even steps, the first exit
    bisected GLASS_REFINE times."""
    count = o.shape[0]
    found = np.zeros(count, dtype=bool)
    s_hit = np.zeros(count)
    lo = np.zeros(count)
    for k in range(GLASS_STEPS):
        s = reach * (k + 1) / GLASS_STEPS
        out, _b, _l, _r, _c, inside = glass.outside(o + s[:, None] * d, own)
        new = ~found & out & inside
        s_hit = np.where(new, s, s_hit)
        found |= new
        lo = np.where(found, lo, s)
    hi = s_hit
    for _ in range(GLASS_REFINE):
        mid = 0.5 * (lo + hi)
        out, _b, _l, _r, _c, _in = glass.outside(o + mid[:, None] * d, own)
        hi = np.where(out, mid, hi)
        lo = np.where(out, lo, mid)
    _o, back, layer, row, col, _in = glass.outside(o + hi[:, None] * d, own)
    return (found, hi, *glass.face(back, layer, row, col))


def _march_enter(glass, o, d, reach, own):
    """Where the rays o + s d (N, 3) that have left the object ``own`` at o first enter one of its
    spans again, s in (0, reach]: (found, s, the face's outward normal, its geometric normal).
    GLASS_STEPS even steps until the ray leaves the picture; a step enters span k where it
    crosses the span's near face on its pixel (its front face for a ray going away from the
    camera, else its back face; a thin wall between two steps is not stepped over) or lies
    within the span; the entry is bisected GLASS_REFINE times against that face of layer k."""
    count = o.shape[0]
    away = (d @ glass.view_dir) <= 0.0  # depth grows along the ray: it enters through front faces
    prev_z = (glass.camera - o) @ glass.view_dir
    found = np.zeros(count, dtype=bool)
    gone = np.zeros(count, dtype=bool)
    layer = np.zeros(count, dtype=np.int64)
    s_hit = np.zeros(count)
    lo = np.zeros(count)
    lanes = np.arange(count)
    for k in range(GLASS_STEPS):
        s = reach * (k + 1) / GLASS_STEPS
        _r, _c, inside, z, valid, f, b = glass.spans(o + s[:, None] * d, own)
        slack = GLASS_SLACK * z
        crosses = np.where(
            away, (prev_z < f - slack) & (z >= f - slack), (prev_z > b + slack) & (z <= b + slack)
        )
        enters = valid & (crosses | ((z <= b + slack) & (z >= f - slack)))
        gone |= ~found & ~inside
        new = ~found & ~gone & enters.any(axis=0)
        layer = np.where(new, np.argmax(enters, axis=0), layer)
        s_hit = np.where(new, s, s_hit)
        found |= new
        lo = np.where(found | gone, lo, s)
        prev_z = z

    def past(s):  # at s, on the pixel's layer k: past the face the ray enters through
        row, col, _in, z, valid, f, b = glass.spans(o + s[:, None] * d, own)
        slack = GLASS_SLACK * z
        f, b, valid = f[layer, lanes], b[layer, lanes], valid[layer, lanes]
        return valid & np.where(away, z >= f - slack, z <= b + slack), row, col

    hi = s_hit
    for _ in range(GLASS_REFINE):
        mid = 0.5 * (lo + hi)
        yes, _r, _c = past(mid)
        hi = np.where(yes, mid, hi)
        lo = np.where(yes, lo, mid)
    _yes, row, col = past(hi)
    return (found, hi, *glass.face(~away, layer, row, col))


def mesh_exit(
    points,
    normals,
    views,
    centre,
    eta: float,
    own: int,
    front,
    back,
    view_proj,
    camera,
    view_dir,
    screen=(1.0, 1.0, 0.0, 0.0),
    reflections: int = 0,
    geometric=None,
    entry_geometric=None,
    side: bool = False,
):
    """(exit points (N, 3), exit directions (N, 3), found (N,), cosines (N, 2 + reflections)):
    rays from the viewer entering glass of index ``eta`` at ``points`` (unit ``normals`` facing
    the viewer) and leaving the object ``own`` through its real surface, read from the glass
    buffers ``front`` and ``back`` (see :func:`glass_texel`; the object's nearest front and back
    faces per pixel) and ``geometric`` (their faces' geometric normals, :func:`geometric_texel`;
    None: the shading normals stand in; ``entry_geometric``: the entry faces', facing the viewer).

    The inner ray is marched until it leaves the object (:func:`_march_inside`, over
    GLASS_REACH × ‖p − centre‖), refracted out at the face it crosses; under total internal
    reflection it is reflected and marched again, up to GLASS_BOUNCES faces; a path that has not
    left by then carries nothing, as Cycles' bounce limit ends it. Each face turns and refracts
    as Cycles' smooth glass does (:func:`_face_step`, :func:`valid_normal`: a smooth-shaded
    mesh's normal is lifted where its mirror would dip below the face); a path whose next
    direction Cycles drops (a refraction that would not leave through the face, a mirror that
    would) carries nothing. With more than one layer in the buffers a ray that leaves is marched
    on (:func:`_march_enter`) into the object's further spans, at most layers − 1 times: it
    refracts in there as at its entry (a concave glass: a wine glass's far wall, its foot behind
    its stem) and goes on inside. ``reflections``: the first that many faces the ray could leave
    through reflect it instead (the glints: the light the film reflects back inside, once or
    more; faces that reflect totally do so anyway and are not counted). ``cosines``: the cosine
    inside the glass at the first face met, at the face the ray leaves through (NaN where the
    path carries nothing: it never leaves, or Cycles drops it), then at each face that reflected
    it by choice (NaN where it met no more), for the film's reflectance from inside
    (:func:`.transmit.back_reflectance`), then per entry into a further span (NaN where none):
    the cosine inside at the face it left through before and the cosine outside at the face it
    enters (the film's reflectance from outside there, :func:`.transmit.white_reflectance`).
    ``side``: also (points (N, 3), directions (N, 3)) of the ray the film mirrors where the path
    first enters a further span (a wine glass's far wall seen from its bowl; NaN where it does
    not), a fifth item.
    Where the first march finds no face (the object is not in the back buffer at the entry's
    pixel, or no exit within reach) ``found`` is False and the sphere about ``centre`` stands in
    (:func:`exit_ray`; every cosine its cos θₜ)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    e = max(float(eta), WALL_GUARD)
    glass = _Glass(front, back, view_proj, camera, view_dir, screen, geometric)
    g_entry = n if entry_geometric is None else np.asarray(entry_geometric, dtype=np.float64).reshape(-1, 3)
    n_entry = valid_normal(g_entry, v, n)
    d = _unit(refract(-v, n_entry, 1.0 / e), -v)
    # Cycles drops a refraction that does not go into the face (a smooth normal tilted past it)
    dropped_in = (np.sum(g_entry * d, axis=-1) >= 0.0) | (np.sum(n_entry * v, axis=-1) <= 0.0)
    reach = GLASS_REACH * np.maximum(np.linalg.norm(p - c, axis=-1), WALL_GUARD)
    o = p.copy()
    count = p.shape[0]
    left = np.zeros(count, dtype=bool)
    first = np.ones(count, dtype=bool)
    cos_first = np.ones(count)
    cos_last = np.ones(count)
    forced = np.zeros(count, dtype=np.int64)
    cos_forced = np.full((count, int(reflections)), np.nan)
    entries = np.zeros(count, dtype=np.int64)
    side_p, side_d = np.full((count, 3), np.nan), np.full((count, 3), np.nan)
    cos_entries = np.full((count, 2 * (glass.layers - 1)), np.nan)
    _o, _b, _l, row, col, on_picture = glass.outside(p, own)
    present = (glass.back[0][0, row, col] == own) & on_picture  # the object is in the buffers at its entry
    done = dropped_in & present  # dropped on the way in: it goes no further
    any_found = done.copy()
    for bounce in range(GLASS_BOUNCES):
        found, s, face_n, face_g = _march_inside(glass, o, d, reach, own)
        found &= present
        if bounce == 0:
            any_found |= found
        live = found & ~done
        q = o + s[:, None] * d
        cos_face, out, mirrored, out_ok, mirror_ok = _face_step(d, face_n, face_g, e)
        cos_first = np.where(live & first, cos_face, cos_first)
        tir = np.sum(out * out, axis=-1) < TIR_EPS
        chosen = live & ~tir & (forced < reflections)  # reflected by choice: a glint's path
        for k in range(int(reflections)):
            cos_forced[:, k] = np.where(chosen & (forced == k), cos_face, cos_forced[:, k])
        forced += chosen
        bounce_here = tir | chosen
        drop_here = live & np.where(bounce_here, ~mirror_ok, ~out_ok)
        go = live & ~drop_here
        leave = go & ~bounce_here
        out = _unit(out, d)
        # out into the air: on into a further span of the object, refracted in as at the entry
        again = leave & (entries < glass.layers - 1)
        if again.any():
            met, s_in, in_n, in_g = _march_enter(glass, q, out, reach, own)
            w = -out
            met &= again & (np.sum(in_g * w, axis=-1) > 0.0)  # the face met from outside
            n_in = valid_normal(in_g, w, in_n)
            d_in = _unit(refract(out, n_in, 1.0 / e), out)
            drop_in = met & ((np.sum(in_g * d_in, axis=-1) >= 0.0) | (np.sum(n_in * w, axis=-1) <= 0.0))
            cos_in = np.clip(np.sum(w * n_in, axis=-1), 0.0, 1.0)
            mirror_here = (met & ~drop_in & (entries == 0))[:, None]
            side_p = np.where(mirror_here, q + s_in[:, None] * out, side_p)
            side_d = np.where(mirror_here, -reflect(out, n_in), side_d)
            for k in range(glass.layers - 1):
                at = met & (entries == k)
                cos_entries[:, 2 * k] = np.where(at, cos_face, cos_entries[:, 2 * k])
                cos_entries[:, 2 * k + 1] = np.where(at, cos_in, cos_entries[:, 2 * k + 1])
            entries += met
            drop_here |= drop_in
            leave &= ~met
            go &= ~drop_in
            q = np.where(met[:, None], q + s_in[:, None] * out, q)
            mirrored = np.where(met[:, None], d_in, mirrored)
        cos_last = np.where(leave, cos_face, cos_last)
        o = np.where(live[:, None], q, o)
        d = np.where(leave[:, None], out, np.where(go[:, None], mirrored, d))
        done |= leave | ~found | drop_here
        left |= leave
        first &= ~live
    sphere_point, sphere_dir = exit_ray(p, n, v, c, e)
    cos_t = inner_cosine(np.sum(n * v, axis=-1), e)
    # a path that does not leave (within GLASS_BOUNCES faces, or one Cycles drops) carries nothing
    cos_last = np.where(left, cos_last, np.nan)
    traced = np.concatenate([np.stack([cos_first, cos_last], -1), cos_forced, cos_entries], axis=-1)
    sphere = np.concatenate([np.repeat(cos_t[:, None], 2 + int(reflections), 1), np.nan * cos_entries], -1)
    cosines = np.where(any_found[:, None], traced, sphere)
    result = (
        np.where(any_found[:, None], o, sphere_point),
        np.where(any_found[:, None], d, sphere_dir),
        any_found,
        cosines,
    )
    return (*result, (side_p, side_d)) if side else result


def inner_cosine(cos_outside, eta: float) -> np.ndarray:
    """cos θₜ inside glass of index ``eta`` of a ray entering at cos θᵢ = ``cos_outside`` (…,):
    the cosine at which it meets a sphere's far side."""
    c = np.clip(np.asarray(cos_outside, dtype=np.float64), 0.0, 1.0)
    return np.sqrt(np.maximum(1.0 - (1.0 - c * c) / (max(float(eta), WALL_GUARD) ** 2), 0.0))
