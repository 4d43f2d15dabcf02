"""A film's thickness per pixel: a map over the mesh's UVs, where a texture drives it.

A thickness given per face corner (:mod:`.linked`) is interpolated linearly across each triangle,
so a texture's detail between the corners is lost: a Noise Texture of scale 3 on Blender's
default UV sphere (32 × 16) is 4.3 mean ΔE2000 from Cycles per corner and 0.9 on a 256 × 128
one (docs/texture-thickness.md). Where the thickness comes from images at one UV map, or from a
graph Cycles can bake at the mesh's UVs, the film also carries a **map**: the thickness in nm at
the texel centres of a (H, W) grid over one UV map, row 0 at v = 0, which the shader reads per
pixel at the interpolated UVs (``TF_THICKNESS_MAP``, bilinear, as :func:`sample_bilinear`).

- images (:func:`.linked_nodes.link_map`): the graph evaluated in numpy at the texel centres;
  with the image's own size the texels are its pixels, so the GPU's bilinear filter of the map
  is Cycles' of the image wherever the graph is linear (Map Range, Mix, Separate Color);
- a Cycles bake (a Noise Texture, a Color Ramp, …; :func:`.linked.bake_map`) into a float image
  of :data:`BAKE_SIZE`² at the active UV map. A bake writes each texel once, so overlapping UV
  islands or UVs outside [0, 1] would give one part of the mesh another part's thickness: the
  map is kept only where it agrees with the per-corner bake at every corner's UV
  (:func:`agrees`), else the film stays per corner and the panel says why.

:attr:`ThicknessMap.lo` / ``hi`` are the map's range over the mesh (:func:`make`), which widens
the table's thickness range (a texture's peaks between corners would otherwise be clamped).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import bpy
import numpy as np

from .. import caches, workers
from .linked_nodes import Unsupported, sample

__all__ = [
    "AGREEMENT",
    "BAKE_SIZE",
    "MAPS",
    "PENDING",
    "SETTLE_S",
    "STATS",
    "ThicknessMap",
    "agrees",
    "field_map",
    "inline_allowed",
    "make",
    "parameters",
    "run_settled",
    "sample_bilinear",
    "triangle_points",
]

#: Side of a baked map (texels): 1024² bakes in ≈ 0.7 s at one sample on the 2-core machine
#: (docs/texture-thickness.md), 4 MB as float32.
BAKE_SIZE = 1024
#: A baked map agrees with the per-corner bake when at least this share of corners lies within
#: 2 % of the thickness range (plus 0.01 nm) of it (:func:`agrees`).
AGREEMENT = 0.99
#: Barycentric weights of the points each triangle is sampled at for an image map's range: a
#: grid of 6 steps per edge (28 points, its corners among them).
_BARYCENTRIC = np.array([(i, j, 6 - i - j) for i in range(7) for j in range(7 - i)], dtype=np.float64) / 6.0


@dataclass(frozen=True)
class ThicknessMap:
    """The thickness in nm at a map's texel centres over UV map ``layer`` (see the module).

    ``values``: (H, W) float32, row 0 at v = 0, finite; ``uv``: (corners, 2) float32, the mesh's
    UVs in that map (the batch's ``uv`` attribute); ``repeat``: the map tiles (an image with
    extension Repeat), else its edges extend; ``lo``/``hi``: its range over the mesh's
    triangles; ``how``: one line for the panel.
    """

    values: np.ndarray
    uv: np.ndarray
    layer: str
    repeat: bool
    lo: float
    hi: float
    how: str


def sample_bilinear(values, uv, repeat: bool = False) -> np.ndarray:
    """The map (H, W) at UVs (N, 2): bilinear between texel centres, edges repeated or extended
    (what ``TF_THICKNESS_MAP`` reads: a GPU texture's linear filter)."""
    values = np.asarray(values, dtype=np.float64)
    return sample(values[..., None], np.asarray(uv, dtype=np.float64).reshape(-1, 2), False, repeat)[:, 0]


def triangle_points(uv, triangles) -> np.ndarray:
    """UVs (N, 2) of points on every triangle ((T, 3) corner indices into ``uv``): a barycentric
    grid of 6 steps per edge (:data:`_BARYCENTRIC`)."""
    corners = np.asarray(uv, dtype=np.float64)[np.asarray(triangles).reshape(-1, 3)]  # (T, 3, 2)
    return np.einsum("pk,tkc->tpc", _BARYCENTRIC, corners).reshape(-1, 2)


def make(values, uv, triangles, layer: str, repeat: bool, how: str) -> ThicknessMap:
    """A :class:`ThicknessMap` of ``values`` (H, W nm) for a mesh whose corners have ``uv`` and
    whose ``triangles`` index them. A bake's map has NaN where nothing was written: its range is
    its written texels' (the triangles' and the margin's, which repeats their edges), and the
    rest take the mean (the margin covers every texel a triangle's bilinear read reaches). An
    image's map has no NaN and may hold more than the mesh uses (an atlas): its range is the map
    read on a grid of points on every triangle (:func:`triangle_points`). Raises ValueError when
    the map has no finite value."""
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    if not finite.any():
        raise ValueError("the thickness map has no finite value")
    if finite.all():
        on_mesh = sample_bilinear(values, triangle_points(uv, triangles), repeat)
        lo, hi = float(on_mesh.min()), float(on_mesh.max())
    else:
        lo, hi = float(values[finite].min()), float(values[finite].max())
    filled = np.where(finite, values, float(values[finite].mean()))
    return ThicknessMap(
        filled.astype(np.float32),
        np.asarray(uv, dtype=np.float32).reshape(-1, 2),
        layer,
        bool(repeat),
        lo,
        hi,
        how,
    )


def agrees(found: ThicknessMap, corner_values) -> bool:
    """Whether the map holds every corner's value (nm) where the corner's UV reads it: the
    bilinear read there, or one of the 4 × 4 texels around it, within 2 % of the values' range,
    for :data:`AGREEMENT` of the corners. False where UV islands overlap or leave [0, 1] (a bake
    writes each texel once, so another part of the surface's values sit there). The texels
    around count because a steep texture changes across one texel, and the corners at a UV
    sphere's pole sit on the map's edge row, which only the pole's slivers reach."""
    corner_values = np.asarray(corner_values, dtype=np.float64).reshape(-1)
    at_corners = sample_bilinear(found.values, found.uv, found.repeat)
    finite = np.isfinite(corner_values)
    if at_corners.shape != corner_values.shape or not finite.any():
        return False
    span = float(np.ptp(corner_values[finite]))
    tolerance = 0.02 * span + 0.01
    near = np.abs(_texels_around(found.values, found.uv, found.repeat) - corner_values[:, None])
    close = (np.abs(at_corners - corner_values) <= tolerance) | (np.nanmin(near, axis=1) <= tolerance)
    return bool(np.mean(close[finite]) >= AGREEMENT)


def _texels_around(values, uv, repeat: bool) -> np.ndarray:
    """The 4 × 4 texels around each UV ((N, 16); the edges repeated or extended)."""
    values = np.asarray(values, dtype=np.float64)
    h, w = values.shape
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    x0 = np.floor(uv[:, 0] * w - 0.5).astype(np.int64)
    y0 = np.floor(uv[:, 1] * h - 0.5).astype(np.int64)
    steps = np.arange(-1, 3)
    xs, ys = x0[:, None] + steps, y0[:, None] + steps
    xs, ys = (np.mod(xs, w), np.mod(ys, h)) if repeat else (np.clip(xs, 0, w - 1), np.clip(ys, 0, h - 1))
    return values[ys[:, :, None], xs[:, None, :]].reshape(-1, 16)


def parameters(found: ThicknessMap, thickness_range) -> np.ndarray:
    """The map as the table's parameter in [0, 1] along ``thickness_range`` (nm), float32."""
    lo, hi = (float(v) for v in thickness_range)
    return np.clip((found.values - lo) / max(hi - lo, 1e-9), 0.0, 1.0).astype(np.float32)


# ----------------------------------------------------------------------------------------------
# Making maps: apart from the corners, never inside a draw
# ----------------------------------------------------------------------------------------------
#: Maps made, by the key of the field they belong to: (ThicknessMap or None, why not or None).
MAPS = caches.register("thickness_maps", caches.LRU(16), scope=caches.FILE)
#: Maps the draw asked for, made by the viewport's timer (:func:`.linked.run_pending`) once their key has
#: waited :data:`SETTLE_S`: a 1024² map takes 0.3–0.6 s of the main thread (a Cycles bake, a
#: 1024² image's graph; docs/texture-thickness.md), so dragging a slider draws the corners and
#: makes one map when it stops, not one per step.
PENDING = workers.Deferred("thickness maps")
SETTLE_S = 0.5
_map_asked: dict = {}  # key → time.monotonic() of the first ask
#: Maps made so far: a reader of the thickness range (the EEVEE film) reads it again when it grows.
STATS = {"made": 0}


def inline_allowed() -> bool:
    """Whether a map is made where it is asked for: in background mode (a headless render,
    ``blender -b``), where nothing waits for the main thread; else the viewport's timer makes it."""
    return bool(bpy.app.background)


def field_map(cache_key, job: tuple, make, defer: bool):
    """(the map of the field under ``cache_key`` or None, why not or None, whether it is being
    waited for): made by ``make()`` → (map or None, why) now in background mode (a headless
    render, ``blender -b``: nothing waits for the main thread), else queued for the viewport's
    timer (:func:`.linked.run_pending`); a draw, a panel or an EEVEE sync draws the corners
    meanwhile. ``job`` names what the map is of, (object name, material, source), not its
    content: a newer field's map replaces a queued one, so a dragged slider makes one map."""
    made = MAPS.get(cache_key)
    if made is not None:
        return made[0], made[1], False
    if defer or not inline_allowed():
        _map_asked.setdefault(cache_key, time.monotonic())
        PENDING.defer(("map", *job), lambda: _make_map(cache_key, make))
        return None, None, True
    return (*_make_map(cache_key, make), False)


def _make_map(cache_key, make):
    """Make one map (main thread) and keep it, with why there is none."""
    _map_asked.pop(cache_key, None)
    try:
        made = make()
    except (ValueError, RuntimeError, Unsupported) as exc:
        made = (None, f"no map per pixel ({exc}): per corner")
    MAPS[cache_key] = made
    STATS["made"] += 1
    return made


def run_settled(errors) -> list:
    """Run the queued maps once every key has waited :data:`SETTLE_S` (main thread, outside
    drawing); ``(key, exception)`` of each that raised one of ``errors``."""
    now = time.monotonic()
    if not PENDING or any(now - asked < SETTLE_S for asked in _map_asked.values()):
        return []
    failed = PENDING.run(errors)
    _map_asked.clear()  # every queued map ran (or its data is gone)
    return failed
