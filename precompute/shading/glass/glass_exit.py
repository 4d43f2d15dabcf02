"""Solid glass's exit through its real mesh: the glass buffers marched in numpy (numpy twin of
glsl/tf_glass_exit.glsl).

The headless frame draws each solid glass object's faces into the glass buffers
(addon/gpu/glass_buffers.py): per pixel of the films' window its ``GLASS_LAYERS`` nearest front
and back faces (depth peeling), their outward normals, depths and geometric normals
(:func:`glass_texel`, :func:`geometric_texel`). The ray refracted in at the shaded point is
marched inside over the object's spans until it leaves (:func:`_march_inside`), meets each face
as Cycles' smooth glass meets it (:func:`valid_normal`, :func:`_face_step`), reflects totally,
and where it leaves a concave glass enters the object's further spans again
(:func:`_march_enter`); :func:`mesh_exit` gives where it leaves for good. Without the buffers the
sphere about the object's origin stands in (:func:`.refract.exit_ray`). What the exit ray then
sees is :mod:`.refract`'s march over the scene behind.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...brdf import reflect
from ..policy import (
    GLASS_BLEND_COS,
    GLASS_BLEND_DEPTH,
    GLASS_BOUNCES,
    GLASS_REACH,
    GLASS_REFINE,
    GLASS_SLACK,
    GLASS_STEPS,
    REFRACT_FAR,
    TIR_EPS,
    VALID_REFLECTION_RISE,
    VALID_REFLECTION_SCALE,
    WALL_GUARD,
)
from .refract import _project, _unit, _uv, exit_ray, inner_cosine, refract


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
    face's plane (cos = incoming · geometric; :data:`..policy.VALID_REFLECTION_SCALE`, ``_RISE``),
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


def _refract_in(g, w, n, e: float):
    """Rays arriving from outside (``w``: towards where they came from, (N, 3)) refracted into
    glass of index ``e`` at faces of geometric normals ``g`` and shading normals ``n`` (both
    facing w) as Cycles' smooth glass refracts them (glsl ``tf_glass_refract_in``): (the normals
    used, :func:`valid_normal`; the directions in; dropped (N,): where Cycles ends the path, a
    refraction that does not cross the face)."""
    n_valid = valid_normal(g, w, n)
    d_in = _unit(refract(-w, n_valid, 1.0 / e), -w)
    dropped = (np.sum(g * d_in, axis=-1) >= 0.0) | (np.sum(n_valid * w, axis=-1) <= 0.0)
    return n_valid, d_in, dropped


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

    def __init__(self, front, back, view_proj, camera, view_dir, screen=(1.0, 1.0, 0.0, 0.0), geometric=None):
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

    def face(self, through_back, layer, row, col, q=None, own=None):
        """(outward normal, geometric normal) (N, 3) of the faces :meth:`outside` names; with the
        points ``q`` on them and their object ``own``, the normal interpolated at q between the
        four texel centres around it (:meth:`_blend`)."""
        n = np.where(through_back[:, None], self.back[1][layer, row, col], self.front[1][layer, row, col])
        g = np.where(through_back[:, None], self.back_g[layer, row, col], self.front_g[layer, row, col])
        if q is not None:
            n = self._blend(q, through_back, layer, row, col, own, n)
        return n, g

    def _blend(self, q, through_back, layer, row, col, own, nearest):
        """The faces' normals at points ``q`` (N, 3), bilinear between the four texel centres
        around them (glsl ``tf_glass_face_near``): the texels of the same face only, those of
        ``own`` whose normal lies within GLASS_BLEND_COS of the nearest texel's (``nearest``, on
        row, col) and whose depth within GLASS_BLEND_DEPTH of its depth (a crease or another
        surface keeps its own normal). The nearest texel's normal alone is a staircase: at a
        glass's rim, seen edge-on, a texel spans a degree of normal, which the grazing exit
        turns by several."""
        depth0 = np.where(through_back, self.back[2][layer, row, col], self.front[2][layer, row, col])
        uv, _w = _uv(q, self.view_proj, self.screen)
        h, w = self.back[0].shape[1:]
        x, y = uv[:, 0] * w - 0.5, uv[:, 1] * h - 0.5  # texel units, row 0 at the bottom
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        total = np.zeros_like(nearest)
        for dy in (0, 1):
            for dx in (0, 1):
                c = np.clip(x0 + dx, 0, w - 1).astype(np.int64)
                r = (h - 1 - np.clip(y0 + dy, 0, h - 1)).astype(np.int64)
                id_k = np.where(through_back, self.back[0][layer, r, c], self.front[0][layer, r, c])
                n_k = np.where(through_back[:, None], self.back[1][layer, r, c], self.front[1][layer, r, c])
                d_k = np.where(through_back, self.back[2][layer, r, c], self.front[2][layer, r, c])
                same = (
                    (id_k == own)
                    & (np.sum(n_k * nearest, axis=-1) >= GLASS_BLEND_COS)
                    & (np.abs(d_k - depth0) <= GLASS_BLEND_DEPTH * depth0)
                )
                weight = (fx if dx else 1.0 - fx) * (fy if dy else 1.0 - fy)
                total += np.where(same, weight, 0.0)[:, None] * n_k
        return _unit(total, nearest)


def _march_inside(glass, o, d, reach, own):
    """Where the rays o + s d (N, 3), s in (0, reach], first leave the object ``own``: (found,
    s, the face's outward normal, its geometric normal). GLASS_STEPS even steps, the first exit
    bisected GLASS_REFINE times; the face read where the exit lies, or, off the object's
    silhouette there, on the last texel inside (its front or back face, the nearer in depth)."""
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
    q = o + hi[:, None] * d
    _o, back, layer, row, col, _in = glass.outside(q, own)
    # a ray that leaves across the silhouette (a rim's face seen edge-on) ends on an empty texel:
    # the face is the one on the last texel inside, its front or back whichever lies nearer in depth
    empty = np.where(back, glass.back[0][layer, row, col], glass.front[0][layer, row, col]) != own
    row_lo, col_lo, _in = _project(
        o + lo[:, None] * d, glass.view_proj, glass.screen, glass.back[0].shape[1:]
    )
    z = (glass.camera - q) @ glass.view_dir
    f, b = glass.front[2][layer, row_lo, col_lo], glass.back[2][layer, row_lo, col_lo]
    back = np.where(empty, np.abs(z - b) <= np.abs(z - f), back)
    row, col = np.where(empty, row_lo, row), np.where(empty, col_lo, col)
    return (found, hi, *glass.face(back, layer, row, col, q, own))


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
    return (found, hi, *glass.face(~away, layer, row, col, o + hi[:, None] * d, own))


@dataclasses.dataclass
class Branches:
    """The two rays the film branches off a path through a concave glass (NaN where none), what
    :func:`mesh_exit` gives with ``side``: ``mirror``, its mirror in the air where the path first
    enters the object again (a wine glass's far wall seen from its bowl), and ``inner``, its
    reflection back inside where the path then leaves (that wall's outer face seen from inside
    the glass: the cosine inside there is the path's last). Points and directions (N, 3) each;
    :func:`branch_exit` follows them."""

    mirror_point: np.ndarray
    mirror_dir: np.ndarray
    inner_point: np.ndarray
    inner_dir: np.ndarray


def _follow(glass, o, d, reach, own: int, e: float, reflections: int, active):
    """The rays o + s d (N, 3) inside the object ``own`` (index ``e``) followed until they leave
    it for good, the lanes ``active`` only (glsl ``tf_glass_follow``; see :func:`mesh_exit`):
    (exit points, directions, found (the first march met a face), left (they leave: the path
    carries light), cos first, cos last, the forced reflections' cosines (N, reflections), the
    entries' cosines (N, 2 (layers − 1)), :class:`Branches`)."""
    count = o.shape[0]
    done = ~active
    first_found = np.zeros(count, dtype=bool)
    left = np.zeros(count, dtype=bool)
    first = np.ones(count, dtype=bool)
    cos_first = np.ones(count)
    cos_last = np.ones(count)
    forced = np.zeros(count, dtype=np.int64)
    cos_forced = np.full((count, int(reflections)), np.nan)
    entries = np.zeros(count, dtype=np.int64)
    branches = Branches(*(np.full((count, 3), np.nan) for _ in range(4)))
    cos_entries = np.full((count, 2 * (glass.layers - 1)), np.nan)
    for bounce in range(GLASS_BOUNCES):
        found, s, face_n, face_g = _march_inside(glass, o, d, reach, own)
        found &= active
        if bounce == 0:
            first_found = found.copy()
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
            n_in, d_in, drop_in = _refract_in(in_g, w, in_n, e)
            drop_in &= met
            cos_in = np.clip(np.sum(w * n_in, axis=-1), 0.0, 1.0)
            mirror_here = (met & ~drop_in & (entries == 0))[:, None]
            branches.mirror_point = np.where(mirror_here, q + s_in[:, None] * out, branches.mirror_point)
            branches.mirror_dir = np.where(mirror_here, -reflect(out, n_in), branches.mirror_dir)
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
        # where it leaves after entering again, the film's reflection back inside
        inner_here = (leave & (entries == 1) & mirror_ok)[:, None]
        branches.inner_point = np.where(inner_here, q, branches.inner_point)
        branches.inner_dir = np.where(inner_here, mirrored, branches.inner_dir)
        cos_last = np.where(leave, cos_face, cos_last)
        o = np.where(live[:, None], q, o)
        d = np.where(leave[:, None], out, np.where(go[:, None], mirrored, d))
        done |= leave | ~found | drop_here
        left |= leave
        first &= ~live
    return o, d, first_found, left, cos_first, cos_last, cos_forced, cos_entries, branches


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
    (:func:`..transmit.back_reflectance`), then per entry into a further span (NaN where none):
    the cosine inside at the face it left through before and the cosine outside at the face it
    enters (the film's reflectance from outside there, :func:`..transmit.white_reflectance`).
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
    # Cycles drops a refraction that does not go into the face (a smooth normal tilted past it)
    _n_entry, d, dropped_in = _refract_in(g_entry, v, n, e)
    reach = GLASS_REACH * np.maximum(np.linalg.norm(p - c, axis=-1), WALL_GUARD)
    _o, _b, _l, row, col, on_picture = glass.outside(p, own)
    present = (glass.back[0][0, row, col] == own) & on_picture  # the object is in the buffers at its entry
    o, d, first_found, left, cos_first, cos_last, cos_forced, cos_entries, branches = _follow(
        glass, p, d, reach, own, e, reflections, present & ~dropped_in
    )
    any_found = (dropped_in & present) | first_found  # dropped on the way in: it goes no further
    o = np.where((dropped_in & present)[:, None], p, o)
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
    return (*result, branches) if side else result


def branch_exit(points, dirs, in_air: bool, centre, eta: float, own: int, *buffers, geometric=None):
    """Where the rays a path branches off (:class:`Branches`; NaN lanes carry nothing) leave the
    object ``own`` (glsl ``tf_glass_branch``): ``in_air`` (a mirror) the ray enters the object
    where it meets it again (:func:`_march_enter`: a bowl's near wall, from behind) as Cycles
    refracts it in, else (an inner reflection) it is inside already; then followed
    (:func:`_follow`). (exit points, directions, followed (N,): the ray was followed (else it is
    seen along itself, or, inner, not at all), cos outside at the entry (NaN where none), cosines
    (N, 2 + 2 (layers − 1)) as :func:`mesh_exit`'s (NaN last: carries nothing)). ``buffers``: front,
    back, view_proj, camera, view_dir[, screen] as :func:`mesh_exit` takes them."""
    o = np.nan_to_num(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    d = _unit(
        np.nan_to_num(np.asarray(dirs, dtype=np.float64).reshape(-1, 3), nan=1.0), np.array([0.0, 0.0, 1.0])
    )
    live = ~np.isnan(np.asarray(points, dtype=np.float64).reshape(-1, 3)[:, 0])
    e = max(float(eta), WALL_GUARD)
    glass = _Glass(*buffers, geometric=geometric)
    reach = GLASS_REACH * np.maximum(
        np.linalg.norm(o - np.asarray(centre, dtype=np.float64), axis=-1), WALL_GUARD
    )
    cos_entry = np.full(o.shape[0], np.nan)
    dropped = np.zeros(o.shape[0], dtype=bool)
    if in_air:
        met, s_in, in_n, in_g = _march_enter(glass, o, d, reach, own)
        w = -d
        met &= live & (np.sum(in_g * w, axis=-1) > 0.0)
        n_in, d_in, dropped = _refract_in(
            in_g, w, np.where(np.sum(in_n * w, -1, keepdims=True) < 0.0, -in_n, in_n), e
        )
        dropped &= met
        cos_entry = np.where(met, np.clip(np.sum(w * n_in, axis=-1), 0.0, 1.0), np.nan)
        o = np.where(met[:, None], o + s_in[:, None] * d, o)
        d = np.where(met[:, None], d_in, d)
        live = met & ~dropped
    q, out, found, left, _cf, cos_last, _cr, cos_entries, _b = _follow(glass, o, d, reach, own, e, 0, live)
    cosines = np.concatenate([np.stack([_cf, np.where(left, cos_last, np.nan)], -1), cos_entries], axis=-1)
    cosines[dropped, 1] = np.nan
    return q, out, found | dropped, cos_entry, cosines
