"""Corners the draw must not compute: the *Image* source's and Blender's noise on a large mesh.

Both sources are drawn per pixel without their corners. The *Image* source is read through
Blender's own GPU texture of the image (:class:`..gpu.mesh.ImageTexture`, ``TF_THICKNESS_MAP``),
looked up at each draw: nothing reads the pixels in the draw, painting the image shows on the
next frame, and an image of any size is read at its own resolution (Blender keeps a float image
as half floats on the GPU: 3 decimal digits, under 0.5 nm of a 700 nm range). The *Blender
Noise* source is computed in the shader (``tf_perlin.glsl``, ``MeshBatch.noise``).

Their corners (the batch's ``thickness``: the film of solid glass's inner faces, a bubble's
inside fit, the panel's NaN count) cost more than a frame can spare: the image's pixels read on
the CPU (:func:`.thickness.image_source`: ≈ 0.1–0.3 s for a 2048² float image), Blender's noise
at more than :data:`.linked_nodes.INLINE_VERTICES` vertices (numpy, ≈ 7 µs a vertex), the
threshold a linked Noise Texture's corners share. They are computed once
per input (:func:`.thickness.thickness_inputs`: the image's identity, not every painted stroke;
the noise's scale and seed) and mesh, queued for the viewport's timer while the draw draws the
film per pixel and the corners at the middle of the range; in background mode at once. An image
holding NaN or infinite values is drawn from a map of its pixels instead
(:func:`.thickness.image_map`, those pixels at the middle of the range, as the panel's note
says): Blender's GPU texture turns NaN into 0. So is a tiled (UDIM) image's first tile, what
the corners read: Blender's texture of it is an array of tiles.
"""

from __future__ import annotations

import numpy as np

from .. import caches
from ..gpu.mesh import ImageTexture
from . import linked
from .thickness import corner_uv, image_map, image_source, thickness_field, thickness_inputs

__all__ = ["CORNERS", "image_parameters", "noise_parameters"]

#: Corners by (object, mesh sizes, geometry epoch, the source's inputs): (parameters (N,) in
#: [0, 1], non-finite count, a map of the image's pixels where they hold NaN or ±∞, else None),
#: or the ValueError's message when the source could not give any.
CORNERS = caches.register("deferred_corners", caches.LRU(16), scope=caches.FILE)


def _key(name: str, mesh, props) -> tuple:
    return linked.field_key(name, mesh, repr(thickness_inputs(props)))


def _read(obj, mesh, props):
    """The corners (main thread, outside the draw), kept in :data:`CORNERS`."""
    key = _key(obj.name, mesh, props)
    try:
        image = image_source(obj, mesh, props)
        values, bad = thickness_field(obj, mesh, props, image)
        texture_reads = image is None or (bool(np.isfinite(image[0]).all()) and not _tiled(props))
        found = (values, bad, None if texture_reads else image_map(obj, mesh, props, image))
    except ValueError as exc:
        found = str(exc)
    CORNERS[key] = found
    return found


def _tiled(props) -> bool:
    """Whether the Image source's image is tiled (UDIM): Blender's texture of it is an array of
    tiles, which the shader's map does not read; its first tile is drawn from its pixels."""
    image = props.thickness_image
    return image is not None and image.source == "TILED"


def _corners(obj, mesh, props, inline: bool):
    """(the corners' :data:`CORNERS` entry, or None while they are queued for the timer)."""
    name = obj.original.name if hasattr(obj, "original") else obj.name
    found = CORNERS.get(_key(name, mesh, props))
    if found is None and not inline and linked.is_deferring():
        material = props.id_data.name
        linked.PENDING.defer(("corners", name, material), lambda: _queued(name, material))
        return None
    if found is None:
        found = _read(obj, mesh, props)
    if isinstance(found, str):
        raise ValueError(found)
    return found


def image_parameters(obj, mesh, props):
    """(per-corner parameter in [0, 1] or None while queued, non-finite count, the batch's map:
    (corner UVs, :class:`ImageTexture` or a map of the pixels, repeat), whether the corners are
    awaited) of the IMAGE source; ValueError naming what is missing."""
    image = props.thickness_image
    if image is None:
        name = obj.original.name if hasattr(obj, "original") else obj.name
        raise ValueError(f"object {name!r}: thickness source IMAGE needs an image")
    uv = corner_uv(obj, mesh, props.thickness_uv_map).astype(np.float32)
    texture = None if _tiled(props) else (uv, ImageTexture.of(image), True)
    found = _corners(obj, mesh, props, inline=False)
    if found is None:
        return None, 0, texture, True
    values, bad, pixel_map = found
    return values, bad, pixel_map or texture, False


def noise_parameters(obj, mesh, props):
    """(per-corner parameter in [0, 1] or None while queued, non-finite count, whether the
    corners are awaited) of the BLENDER_NOISE source (drawn per pixel meanwhile)."""
    found = _corners(obj, mesh, props, inline=len(mesh.vertices) <= linked.linked_nodes.INLINE_VERTICES)
    if found is None:
        return None, 0, True
    return found[0], found[1], False


def _queued(name: str, material: str) -> None:
    """The timer's read of an object's corners, by names (the draw's references are gone)."""
    import bpy

    obj = bpy.data.objects.get(name)
    bpy_material = bpy.data.materials.get(material)
    if obj is None or bpy_material is None:
        return
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    _read(evaluated, evaluated.data, bpy_material.thinfilm_sh)
