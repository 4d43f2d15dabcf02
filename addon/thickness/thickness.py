"""A film's thickness over a mesh: one parameter in [0, 1] per face corner.

The top layer's thickness at a corner is min + value·(max − min) of the material's range.
:func:`thickness_field` reads one of three sources (a mesh attribute, procedural noise, an
image at the UVs) and counts the NaN values it met; :func:`thickness_per_vertex` is its array;
:func:`corner_order` lists the corners of the mesh's loop triangles, so
``thickness_per_vertex(...)[corner_order(mesh)]`` gives one value per triangle corner.

:func:`thickness_inputs` is what the field depends on besides the mesh itself (the source and
its settings, the image's identity): the draw keys its batches by it, so an edit to any of them
reaches the preview. The *Image* source is drawn per pixel from Blender's own texture of the
image (:mod:`.corners`), so painting it reaches the preview without a rebuild. Edits to
the mesh (and so to a thickness attribute) arrive as depsgraph geometry updates.
"""

from __future__ import annotations

import time
import zlib

import numpy as np

from ...precompute.materials.noise import value_noise
from ...precompute.materials.perlin import blender_noise
from .. import caches
from ..gpu.mesh import corner_vertices, triangle_corners
from ..world.world_image import srgb_to_linear
from ..world.world_key import describe_image
from .linked_nodes import MAP_MAX_SIZE, sample, texel_centres

__all__ = [
    "IMAGE_RECHECK_S",
    "NAN_PARAMETER",
    "corner_order",
    "corner_uv",
    "image_identity",
    "image_map",
    "image_source",
    "image_stamp",
    "thickness_field",
    "thickness_inputs",
    "thickness_per_vertex",
]

#: Where a NaN thickness value is drawn: the middle of the material's range (finite, as far
#: from either end as possible). The NaN values are counted and reported, never hidden.
NAN_PARAMETER = 0.5
#: An image with unsaved edits (painted, or pixels set from Python) in a node graph linked into
#: a film's thickness has its pixels fingerprinted at most this often (a 2048² float image:
#: ≈ 35 ms), so a stroke reaches the preview within this time without hashing the image on every
#: frame. (The *Image* source needs no fingerprint: it is drawn from the image's GPU texture.)
IMAGE_RECHECK_S = 0.5
#: Pixel fingerprints of edited thickness images by image name: (identity, time, crc).
_PRINTS = caches.register("thickness_images", caches.LRU(16), scope=caches.FILE)


def corner_order(mesh) -> np.ndarray:
    """Corner (loop) indices of the mesh's loop triangles, flattened: shape (3·triangles,).

    ``thickness_per_vertex(...)[corner_order(mesh)]`` gives one value per triangle corner in
    the order of ``mesh.loop_triangles``.
    """
    mesh.calc_loop_triangles()
    return triangle_corners(mesh).ravel()


def _corner_faces(mesh) -> np.ndarray:
    totals = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", totals)
    # Blender stores each face's corners contiguously, faces in order (face offsets).
    return np.repeat(np.arange(len(totals), dtype=np.int32), totals)


#: Largest noise scale (cycles per object-space unit): a million features per unit is finer than
#: any mesh samples, and keeps position × scale far inside the integers value noise hashes.
MAX_NOISE_SCALE = 1e6

_NUMERIC_ATTRIBUTES = {"FLOAT": np.float32, "INT": np.int32, "INT8": np.int8, "BOOLEAN": bool}


def _attribute_values(obj, mesh, name: str) -> np.ndarray:
    where = f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"
    if not name:
        raise ValueError(f"{where}: thickness source ATTRIBUTE needs an attribute name")
    attribute = mesh.attributes.get(name)
    if attribute is None:
        found = sorted(a.name for a in mesh.attributes if a.data_type in _NUMERIC_ATTRIBUTES)
        found = [n for n in found if not n.startswith(".")]
        raise ValueError(
            f"{where}: mesh {mesh.name!r} has no attribute {name!r} for the film thickness "
            f"(float attributes on points or corners; this mesh has {found or 'none'})"
        )
    if attribute.data_type not in _NUMERIC_ATTRIBUTES:
        raise ValueError(
            f"{where}: attribute {name!r} holds {attribute.data_type}; the thickness needs a FLOAT attribute"
        )
    values = np.empty(len(attribute.data), dtype=_NUMERIC_ATTRIBUTES[attribute.data_type])
    attribute.data.foreach_get("value", values)
    values = values.astype(np.float64)
    if attribute.domain == "POINT":
        return values[corner_vertices(mesh)]
    if attribute.domain == "CORNER":
        return values
    if attribute.domain == "FACE":
        return values[_corner_faces(mesh)]
    raise ValueError(
        f"{where}: attribute {name!r} is on the {attribute.domain} domain; "
        "use a point, corner or face attribute"
    )


def corner_uv(obj, mesh, uv_map: str) -> np.ndarray:
    """The corners' UVs (N, 2) float64 in UV map ``uv_map`` (empty: the active render map);
    ValueError naming what is missing."""
    where = f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"
    layer = mesh.uv_layers.get(uv_map) if uv_map else None
    if uv_map and layer is None:
        raise ValueError(
            f"{where}: mesh {mesh.name!r} has no UV map {uv_map!r} "
            f"(it has {[uv.name for uv in mesh.uv_layers] or 'none'})"
        )
    if layer is None:
        layer = next((uv for uv in mesh.uv_layers if uv.active_render), None) or mesh.uv_layers.active
    if layer is None:
        raise ValueError(f"{where}: mesh {mesh.name!r} has no UV map for the thickness image")
    uv = np.empty(2 * len(mesh.loops), dtype=np.float32)
    layer.data.foreach_get("uv", uv)
    return uv.reshape(-1, 2).astype(np.float64)


def _decoded(image, first: np.ndarray) -> np.ndarray:
    """The first channel as Blender's GPU texture and Cycles' Image Texture read it: an 8-bit
    image in the sRGB space decoded to linear; float images (linear when loaded) and data
    (Non-Color) as stored."""
    settings = image.colorspace_settings
    if image.is_float or settings.is_data or settings.name != "sRGB":
        return first
    return srgb_to_linear(first)


def _image_source(obj, mesh, image, uv_map: str) -> tuple[np.ndarray, np.ndarray]:
    """(the image's first channel (H, W), row 0 at the bottom; the corners' UVs (N, 2)) of the
    IMAGE source; ValueError naming what is missing."""
    where = f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"
    if image is None:
        raise ValueError(f"{where}: thickness source IMAGE needs an image")
    width, height = int(image.size[0]), int(image.size[1])
    channels = int(image.channels)
    if width * height == 0 or channels == 0:
        raise ValueError(f"{where}: image {image.name!r} has no pixels (is its file missing?)")
    uv = corner_uv(obj, mesh, uv_map)
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    first = pixels.reshape(height, width, channels)[:, :, 0].astype(np.float64)  # row 0 = bottom
    return _decoded(image, first), uv


def image_source(obj, mesh, props) -> tuple[np.ndarray, np.ndarray] | None:
    """(the IMAGE source's first channel (H, W), the corners' UVs (N, 2)), its pixels read once
    for :func:`thickness_field` and :func:`image_map`, or None for another source."""
    if not props.vary_thickness or props.thickness_source != "IMAGE":
        return None
    return _image_source(obj, mesh, props.thickness_image, props.thickness_uv_map)


def _pixel_print(image) -> int:
    """CRC-32 of the image's first channel (the one the thickness reads)."""
    channels = max(1, int(image.channels))
    pixels = np.empty(int(image.size[0]) * int(image.size[1]) * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    return zlib.crc32(np.ascontiguousarray(pixels[::channels]))


def image_identity(image) -> str:
    """The image's identity without reading its pixels (:func:`.world_key.describe_image`: name,
    source, file path with the file's size and mtime, packed size, generated settings, whether it
    has unsaved edits), its size and channels."""
    return repr((sorted(describe_image(image).items()), tuple(image.size), int(image.channels)))


def image_stamp(image, now: float | None = None):
    """What identifies a thickness image's pixels, as a hashable value (None for no image).

    Its identity without reading pixels (:func:`.world_key.describe_image`: name, source, file
    path with the file's size and mtime, packed size, generated settings, whether it has unsaved
    edits) and its size; an image with unsaved edits also adds a fingerprint of its first
    channel, refreshed at most every :data:`IMAGE_RECHECK_S` seconds.
    """
    if image is None:
        return None
    identity = image_identity(image)
    if not image.is_dirty:
        return identity
    now = time.monotonic() if now is None else now
    seen = _PRINTS.get(image.name_full)
    if seen is None or seen[0] != identity or now - seen[1] >= IMAGE_RECHECK_S:
        seen = (identity, now, _pixel_print(image))
        _PRINTS[image.name_full] = seen
    return identity, seen[2]


def thickness_inputs(props):
    """What the thickness field of ``props`` depends on besides the mesh (hashable), or None
    when the thickness is constant: the source and its settings (attribute name; noise scale
    and seed; image :func:`image_identity` and UV map: painting is drawn from the image's GPU
    texture, :mod:`.corners`)."""
    if not props.vary_thickness:
        return None
    source = props.thickness_source
    if source == "ATTRIBUTE":
        return source, props.thickness_attribute
    if source in {"NOISE", "BLENDER_NOISE"}:
        return source, float(props.noise_scale), int(props.noise_seed)
    if source == "IMAGE":
        image = props.thickness_image
        return source, props.thickness_uv_map, None if image is None else image_identity(image)
    return (source,)


def image_map(obj, mesh, props, image=None):
    """The IMAGE source per pixel from its pixels, where Blender's texture of it cannot stand in
    (:mod:`.corners`: the image holds NaN or ±∞): (the corners' UVs (N, 2) float32, the
    image's first channel as the parameter map (H, W) in [0, 1] float32 (NaN at
    :data:`NAN_PARAMETER`), True: it repeats) for the batch (:mod:`.maps`,
    ``TF_THICKNESS_MAP``), or None for another source. ``image``: :func:`image_source`'s,
    already read. An image larger than :data:`.linked_nodes.MAP_MAX_SIZE` a side is read at
    that many texel centres. Raises ValueError as :func:`thickness_field` does."""
    image = image_source(obj, mesh, props) if image is None else image
    if image is None:
        return None
    first, uv = image
    height, width = first.shape
    if max(height, width) > MAP_MAX_SIZE:
        height, width = min(height, MAP_MAX_SIZE), min(width, MAP_MAX_SIZE)
        first = sample(first[..., None], texel_centres(height, width), False, True)[:, 0]
        first = first.reshape(height, width)
    values = np.clip(np.where(np.isfinite(first), first, NAN_PARAMETER), 0.0, 1.0)
    return uv.astype(np.float32), values.astype(np.float32), True


def thickness_per_vertex(obj, mesh, props, notes: list | None = None) -> np.ndarray | None:
    """Per-corner (loop) thickness parameter in [0, 1], or None when the thickness is constant:
    :func:`thickness_field`'s values; a line on the non-finite values, if any, is appended to
    ``notes`` (:func:`non_finite_note`)."""
    values, bad = thickness_field(obj, mesh, props)
    if bad and notes is not None:
        notes.append(non_finite_note(_where(obj, mesh), bad, values.size))
    return values


def non_finite_note(where: str, bad: int, total: int) -> str:
    """The message for ``bad`` non-finite thickness values out of ``total`` (NaN or ±∞)."""
    return (
        f"{where}: {bad} of {total} thickness values are NaN or infinite; drawn at the middle of "
        "the thickness range"
    )


def _where(obj, mesh) -> str:
    return f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"


def thickness_field(obj, mesh, props, image=None) -> tuple[np.ndarray | None, int]:
    """(per-corner (loop) thickness parameter in [0, 1], how many values were not finite), or
    (None, 0) when the thickness is constant. ``image``: the IMAGE source's
    :func:`image_source`, already read (the batch reads its pixels once for the map too).

    The top layer's thickness at a corner is min + value·(max − min). Sources:

    - ATTRIBUTE: the float attribute ``props.thickness_attribute`` on points, corners or faces
      (values clipped to [0, 1]); a missing attribute raises ValueError naming it.
    - NOISE: :func:`precompute.materials.noise.value_noise` of the object-space vertex positions,
      ``noise_scale`` (in [0, :data:`MAX_NOISE_SCALE`]) and ``noise_seed``; deterministic.
    - BLENDER_NOISE: Blender's Noise Texture as write-back writes it, the same positions, scale
      and seed (:func:`precompute.materials.perlin.blender_noise`, what Cycles computes).
    - IMAGE: the first channel of ``props.thickness_image`` at the corners' UVs (UV map
      ``props.thickness_uv_map``, empty = the active render map), bilinear, repeating, as
      Cycles' Image Texture reads it (an 8-bit sRGB image decoded; Non-Color as stored).

    A NaN or infinite value (an attribute or a float image can hold them) is counted and drawn
    at :data:`NAN_PARAMETER`, the middle of the range; a source with no finite value at all
    raises ValueError (the caller then draws the object at the middle, with that message).
    Index the values with :func:`corner_order` for loop-triangle corners.
    """
    if not props.vary_thickness:
        return None, 0
    where = _where(obj, mesh)
    source = props.thickness_source
    if source == "ATTRIBUTE":
        values = _attribute_values(obj, mesh, props.thickness_attribute)
    elif source in {"NOISE", "BLENDER_NOISE"}:
        if not 0.0 <= props.noise_scale <= MAX_NOISE_SCALE:
            raise ValueError(
                f"{where}: the thickness noise scale is {props.noise_scale!r}; it must lie in "
                f"[0, {MAX_NOISE_SCALE:g}]"
            )
        co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        noise = value_noise if source == "NOISE" else blender_noise
        per_vertex = noise(co.reshape(-1, 3), props.noise_scale, props.noise_seed)
        values = per_vertex[corner_vertices(mesh)]
    elif source == "IMAGE":  # bilinear between pixel centres, repeating as Image Texture does
        first, uv = image_source(obj, mesh, props) if image is None else image
        values = sample(first[..., None], uv, False, True)[:, 0]
    else:
        raise ValueError(f"unknown thickness source {source!r}")
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    bad = int(values.size - np.count_nonzero(finite))
    if bad:
        if bad == values.size:
            what = {"ATTRIBUTE": f"attribute {props.thickness_attribute!r}", "IMAGE": "image"}.get(
                source, source.lower()
            )
            raise ValueError(f"{where}: thickness {what} has no finite value ({bad} NaN/Inf)")
        values = np.where(finite, values, NAN_PARAMETER)
    return np.clip(values, 0.0, 1.0), bad
