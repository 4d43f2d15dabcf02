"""The scene around solid glass, rendered for the headless frame (precompute/shading/glass/probe.py).

A solid glass path that leaves the picture (a reflection towards the camera, a ray bent off its
edges) cannot be marched over the background pass; it read the World. The probe is the scene
seen from the solid glass objects' centre: six square 90° views rendered by the frame's engine
(:func:`.background.render_views` through a camera of our own at that point, the films and
the glass hidden from it and casting no shadow, the World's lamps lit as suns once for the
six), resampled to a panorama of colour and distance
(:func:`precompute.shading.glass.probe.from_faces`). The draw reads it where a path's march
meets nothing (glsl/tf_probe.glsl). Cost: six renders of
:data:`~precompute.shading.policy.PROBE_FACE`² pixels, EEVEE's at
:data:`~precompute.shading.policy.PROBE_SAMPLES` samples, Cycles' at most at
:data:`~precompute.shading.policy.PROBE_CYCLES_SAMPLES`
(docs/transparent-films.md#the-scene-around-the-glass).
"""

from __future__ import annotations

import math
import time

import bpy
import numpy as np
from mathutils import Matrix

from ...precompute.shading.glass import probe as probe_math
from ...precompute.shading.policy import PROBE_CYCLES_SAMPLES, PROBE_FACE, PROBE_ROWS, PROBE_SAMPLES
from ...precompute.shading.transmit import WALL_SOLID
from ..gpu.draw import is_wall
from .background import _changed, render_views

__all__ = ["Probe", "glass_centre", "render_probe"]

#: The probe camera's clipping range (m): near enough for a glass's own foot, far enough for a room.
CLIP = (1e-3, 1e4)


class Probe:
    """A rendered probe: ``image`` (rows, 2 rows, 4; :func:`~precompute.shading.glass.probe.from_faces`),
    ``centre`` (world), ``seconds`` its six renders took."""

    def __init__(self, image, centre, seconds: float):
        self.image = image
        self.centre = np.asarray(centre, dtype=np.float64)
        self.seconds = float(seconds)


def glass_centre(items) -> np.ndarray | None:
    """The centre of the world-space bounding box of the items that are solid glass, or None.

    Each item's mesh bounds (:attr:`.gpu.mesh.MeshBatch.bounds`) are placed by the item's own
    matrix: an instance of a glass (a collection instance, a particle or Geometry Nodes instance)
    where it is drawn, not where its prototype stands."""
    corners = []
    for item in items:
        if not (is_wall(item) and int(item.wall[0]) == WALL_SOLID):
            continue
        lo, hi = np.asarray(item.batch.bounds, dtype=np.float64)
        box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        matrix = np.asarray(item.model_matrix, dtype=np.float64)
        corners.append(box @ matrix[:3, :3].T + matrix[:3, 3])
    if not corners:
        return None
    points = np.concatenate(corners)
    return (points.min(axis=0) + points.max(axis=0)) / 2.0


def render_probe(scene, centre, *, engine: str, hidden=(), shadowless=(), world=None, size: int = PROBE_FACE):
    """The :class:`Probe` of ``scene`` at ``centre``: six ``size``² views by ``engine``, the
    objects named in ``hidden`` invisible to them and those in ``shadowless`` casting no shadow
    (:func:`.background.render_views`, with the World's lamps as suns from ``world``)."""
    t0 = time.perf_counter()
    data = bpy.data.cameras.new("thinfilm_sh probe")
    cam = bpy.data.objects.new("thinfilm_sh probe", data)
    data.angle = math.pi / 2.0
    data.sensor_fit = "HORIZONTAL"
    data.clip_start, data.clip_end = CLIP
    scene.collection.objects.link(cam)
    at = Matrix.Translation([float(v) for v in centre])
    matrices = [at @ Matrix(rotation.tolist()).to_4x4() for rotation in probe_math.FACES]
    try:
        samples = [(scene, "camera", cam), (scene.eevee, "taa_render_samples", PROBE_SAMPLES)]
        if engine == "CYCLES":
            samples.append((scene.cycles, "samples", min(int(scene.cycles.samples), PROBE_CYCLES_SAMPLES)))
        with _changed(samples):
            views = render_views(
                scene, size, matrices, engine=engine, hidden=hidden, shadowless=shadowless, world=world
            )
    finally:
        scene.collection.objects.unlink(cam)
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(data)
        bpy.context.view_layer.update()  # no stale entry of it left in the view layer's objects
    colours = np.array([rgba[..., :3] for rgba, _depth in views])
    image = probe_math.from_faces(colours, np.array([depth for _rgba, depth in views]), PROBE_ROWS)
    return Probe(image, centre, time.perf_counter() - t0)
