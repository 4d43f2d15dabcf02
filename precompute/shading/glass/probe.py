"""The scene around solid glass, for the paths that leave the picture (glsl/tf_probe.glsl).

Solid glass's paths see the scene behind where the screen-space march meets it
(:func:`.refract.march`); a path that leaves the picture (a reflection towards the camera, a ray
bent off its edges) saw the World. Below a glass standing on a floor that is the wrong light: a
wine glass's bowl reflects the floor in front of it (towards the camera) by its outer face, by
its far wall's mirror and by each glint, and those paths saw the studio's dark lower half where
Cycles sees the lit floor (the bowl 0.075 where an exact trace and Cycles give 0.11,
docs/transparent-films.md#the-scene-around-the-glass).

**The probe** is the scene as seen from one point c (the solid glass objects' centre), the
glass and films hidden: six square 90° views (:data:`FACES`, rendered by the headless frame's
engine, addon/headless/probe.py) resampled by :func:`from_faces` to an equirect panorama
(docs/conventions.md's mapping, world frame) of colour and **distance from c** (0 where the
view saw only the World).

**A path meets it** (:func:`lookup`) where it first passes behind the probe's surface: the
probe is read by direction from c, so a point q of the path lies behind it where |q − c|
exceeds the distance D the probe holds in q's direction from c (never where that direction holds
the World). The path o + s d is sampled at s growing by :data:`..policy.PROBE_GROWTH` from
:data:`..policy.PROBE_FIRST` × (|o − c| + D(d)), :data:`..policy.PROBE_STEPS` samples, and the
first that lies behind is bisected :data:`..policy.PROBE_REFINE` times; the colour is read in
the direction u of the point found, bilinear (as :func:`precompute.world.hdri.equirect_lookup`).
A fixed-point step (u ← the direction of the point at distance D(u) along the path) ran away on
shallow paths from above c: a wine glass's far-wall mirror leaving its rim 0.7 above c and
heading 9° down reached a direction over the floor's far edge and saw the World. A path that
passes behind none of the surface sees the World, as before (its sharp level and lamps are
finer than the probe's). **The picture comes first**: where the point met (c + D(u) u) lies in
the background pass's picture, the march, which reads that picture at the pixel's own
resolution, has said the path meets nothing there, and the World stands (a wine glass's paths
that leave just over the floor's far edge: the probe's texel there, 1.4° tall, still holds the
floor).

Exact for a path from c (no parallax), and for a plane seen from near c it converges to the
point the ray meets (tests/optics/test_scene_probe.py); what the probe cannot show is what its point
does not see (the floor under the glass's foot is seen from the centre past the foot).
"""

from __future__ import annotations

import numpy as np

from ...world import hdri
from ..policy import PROBE_FIRST, PROBE_GROWTH, PROBE_REFINE, PROBE_STEPS

__all__ = ["FACES", "face_rays", "from_faces", "lookup"]

#: The six 90° views (camera to world, columns: right, up, backward, as a Blender camera looks
#: along its −Z with +Y up): +X, −X, +Y, −Y, +Z, −Z.
FACES = tuple(
    np.column_stack([np.cross(forward, up), up, -np.asarray(forward, float)]).astype(np.float64)
    for forward, up in (
        ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        ((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
        ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
        ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
        ((0.0, 0.0, -1.0), (0.0, -1.0, 0.0)),
    )
)


def face_rays(size: int) -> np.ndarray:
    """(size, size, 2) the camera-plane coordinates (x right, y up, at distance 1) of a
    ``size``² 90° view's texel centres, top row first."""
    t = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(t, -t)
    return np.stack([x, y], axis=-1)


def from_faces(colours, depths, rows: int) -> np.ndarray:
    """The probe, (rows, 2 rows, 4): colour and distance from the views' point (0: the World)
    of six ``colours`` (6, N, N, 3+) and ``depths`` (6, N, N: distance along each view's axis,
    inf where nothing was drawn), top rows first, in the order of :data:`FACES`."""
    colours = np.asarray(colours, dtype=np.float64)[..., :3]
    depths = np.asarray(depths, dtype=np.float64)
    if colours.shape[:1] != (6,) or colours.shape[1] != colours.shape[2] or depths.shape != colours.shape[:3]:
        raise ValueError(f"a probe needs six square views and depths, got {colours.shape} and {depths.shape}")
    n = colours.shape[1]
    plane = face_rays(n)
    ray_length = np.sqrt(1.0 + np.sum(plane * plane, -1))
    distance = np.where(np.isfinite(depths) & (depths > 0.0), depths * ray_length, 0.0)
    dirs = hdri.equirect_directions(int(rows), 2 * int(rows)).reshape(-1, 3)
    face = np.argmax(np.stack([dirs @ -m[:, 2] for m in FACES]), axis=0)
    out = np.zeros((len(dirs), 4))
    for k, m in enumerate(FACES):
        sel = face == k
        local = dirs[sel] @ m  # (right, up, backward) components
        x, y = local[:, 0] / -local[:, 2], local[:, 1] / -local[:, 2]
        col, row = (x + 1.0) / 2.0 * n - 0.5, (1.0 - y) / 2.0 * n - 0.5
        c0, r0 = np.clip(np.floor(col).astype(int), 0, n - 1), np.clip(np.floor(row).astype(int), 0, n - 1)
        c1, r1 = np.minimum(c0 + 1, n - 1), np.minimum(r0 + 1, n - 1)
        fx, fy = np.clip(col - c0, 0.0, 1.0)[:, None], np.clip(row - r0, 0.0, 1.0)[:, None]
        img = colours[k]
        out[sel, :3] = (1 - fy) * ((1 - fx) * img[r0, c0] + fx * img[r0, c1]) + fy * (
            (1 - fx) * img[r1, c0] + fx * img[r1, c1]
        )
        near_r = np.clip(np.rint(row).astype(int), 0, n - 1)
        near_c = np.clip(np.rint(col).astype(int), 0, n - 1)
        out[sel, 3] = distance[k][near_r, near_c]
    return out.reshape(int(rows), 2 * int(rows), 4)


def _distance(probe, u) -> np.ndarray:
    """The probe's distance at unit directions ``u`` (N, 3), its nearest texel (u wraps, rows
    clamp)."""
    h, w = probe.shape[:2]
    x = (0.5 - np.arctan2(u[:, 1], u[:, 0]) / (2.0 * np.pi)) * w
    y = np.arccos(np.clip(u[:, 2], -1.0, 1.0)) / np.pi * h
    col = np.floor(x).astype(int) % w
    row = np.clip(np.floor(y).astype(int), 0, h - 1)
    return probe[row, col, 3]


def _behind(probe, centre, q) -> np.ndarray:
    """(N,) whether points ``q`` (N, 3) lie beyond the probe's surface in their direction from
    ``centre`` (never where that direction holds the World)."""
    v = q - centre
    r = np.linalg.norm(v, axis=-1)
    u = v / np.where(r > 0.0, r, 1.0)[:, None]
    dist = _distance(probe, u)
    return (r > 0.0) & (dist > 0.0) & (r > dist)


def lookup(probe, centre, origins, dirs, covered=None) -> tuple:
    """(colour (N, 3), seen (N,)): what paths leaving at ``origins`` (N, 3) along unit ``dirs``
    see in the ``probe`` (:func:`from_faces`) taken at ``centre``; ``seen`` False (colour 0)
    where they pass behind none of its surface (the World) or where the point they meet lies in
    the picture the march read (``covered``: world points (N, 3) → (N,) bool,
    :func:`.refract.on_picture`; None: no picture); see the module."""
    probe = np.asarray(probe, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    along = _distance(probe, d)
    scale = np.linalg.norm(o - c, axis=-1) + along
    lo, hi = np.zeros(len(o)), np.zeros(len(o))
    found = np.zeros(len(o), dtype=bool)
    previous = np.zeros(len(o))
    for k in range(PROBE_STEPS):
        step = scale * PROBE_FIRST * PROBE_GROWTH**k
        first = _behind(probe, c, o + step[:, None] * d) & ~found
        lo, hi = np.where(first, previous, lo), np.where(first, step, hi)
        found |= first
        previous = step
    for _ in range(PROBE_REFINE):
        mid = 0.5 * (lo + hi)
        past = _behind(probe, c, o + mid[:, None] * d)
        lo, hi = np.where(past, lo, mid), np.where(past, mid, hi)
    v = o + hi[:, None] * d - c
    r = np.linalg.norm(v, axis=-1, keepdims=True)
    u = np.where(r > 0.0, v / np.where(r > 0.0, r, 1.0), d)
    dist = _distance(probe, u)
    seen = found & (dist > 0.0)
    if covered is not None:
        seen &= ~np.asarray(covered(c + dist[:, None] * u), dtype=bool)
    colour = np.where(seen[:, None], hdri.equirect_lookup(probe[..., :3], u), 0.0)
    return colour, seen
