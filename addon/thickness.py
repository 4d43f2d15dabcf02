"""A film's thickness over a mesh: one parameter in [0, 1] per face corner.

The top layer's thickness at a corner is min + value·(max − min) of the material's range.
:func:`thickness_per_vertex` reads one of three sources (a mesh attribute, procedural noise,
an image at the UVs); :func:`corner_order` lists the corners of the mesh's loop triangles, so
``thickness_per_vertex(...)[corner_order(mesh)]`` gives one value per triangle corner.
"""

from __future__ import annotations

import numpy as np

from ..precompute.noise import value_noise

__all__ = ["corner_order", "thickness_per_vertex"]


def corner_order(mesh) -> np.ndarray:
    """Corner (loop) indices of the mesh's loop triangles, flattened: shape (3·triangles,).

    ``thickness_per_vertex(...)[corner_order(mesh)]`` gives one value per triangle corner in
    the order of ``mesh.loop_triangles``.
    """
    mesh.calc_loop_triangles()
    loops = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    return loops


def _corner_vertices(mesh) -> np.ndarray:
    out = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", out)
    return out


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
        return values[_corner_vertices(mesh)]
    if attribute.domain == "CORNER":
        return values
    if attribute.domain == "FACE":
        return values[_corner_faces(mesh)]
    raise ValueError(
        f"{where}: attribute {name!r} is on the {attribute.domain} domain; "
        "use a point, corner or face attribute"
    )


def _image_values(obj, mesh, image, uv_map: str) -> np.ndarray:
    where = f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"
    if image is None:
        raise ValueError(f"{where}: thickness source IMAGE needs an image")
    width, height = int(image.size[0]), int(image.size[1])
    channels = int(image.channels)
    if width * height == 0 or channels == 0:
        raise ValueError(f"{where}: image {image.name!r} has no pixels (is its file missing?)")
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
    uv = uv.reshape(-1, 2).astype(np.float64)
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    first = pixels.reshape(height, width, channels)[:, :, 0].astype(np.float64)  # row 0 = bottom
    # Bilinear between pixel centres ((i + ½)/W, (j + ½)/H), repeating like Image Texture's default.
    x = uv[:, 0] * width - 0.5
    y = uv[:, 1] * height - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0 = x0.astype(np.int64) % width
    y0 = y0.astype(np.int64) % height
    x1, y1 = (x0 + 1) % width, (y0 + 1) % height
    return (
        first[y0, x0] * (1 - fx) * (1 - fy)
        + first[y0, x1] * fx * (1 - fy)
        + first[y1, x0] * (1 - fx) * fy
        + first[y1, x1] * fx * fy
    )


def thickness_per_vertex(obj, mesh, props, notes: list | None = None) -> np.ndarray | None:
    """Per-corner (loop) thickness parameter in [0, 1], or None when the thickness is constant.

    The top layer's thickness at a corner is min + value·(max − min). Sources:

    - ATTRIBUTE: the float attribute ``props.thickness_attribute`` on points, corners or faces
      (values clipped to [0, 1]); a missing attribute raises ValueError naming it.
    - NOISE: :func:`precompute.noise.value_noise` of the object-space vertex positions,
      ``noise_scale`` and ``noise_seed``; deterministic.
    - IMAGE: the first channel of ``props.thickness_image`` at the corners' UVs (UV map
      ``props.thickness_uv_map``, empty = the active render map), bilinear, repeating, raw pixel
      values (use Non-Color images).

    Index the result with :func:`corner_order` for loop-triangle corners.

    NaN/Inf values (from a script, a broken image) are drawn at the middle of the range, 0.5,
    with a line appended to ``notes``; a source with no finite value at all raises ValueError
    (the caller then draws the whole object at the middle of the range, with its message).
    """
    if not props.vary_thickness:
        return None
    where = f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"
    source = props.thickness_source
    if source == "ATTRIBUTE":
        values = _attribute_values(obj, mesh, props.thickness_attribute)
    elif source == "NOISE":
        if not 0.0 <= props.noise_scale <= MAX_NOISE_SCALE:
            raise ValueError(
                f"{where}: the thickness noise scale is {props.noise_scale!r}; it must lie in "
                f"[0, {MAX_NOISE_SCALE:g}]"
            )
        co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        per_vertex = value_noise(co.reshape(-1, 3), props.noise_scale, props.noise_seed)
        values = per_vertex[_corner_vertices(mesh)]
    elif source == "IMAGE":
        values = _image_values(obj, mesh, props.thickness_image, props.thickness_uv_map)
    else:
        raise ValueError(f"unknown thickness source {source!r}")
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    if not finite.all():
        what = {"ATTRIBUTE": f"attribute {props.thickness_attribute!r}", "IMAGE": "image"}.get(source, source)
        bad = int(values.size - np.count_nonzero(finite))
        if not finite.any():
            raise ValueError(f"{where}: thickness {what} has no finite value ({bad} NaN/Inf)")
        if notes is not None:
            notes.append(
                f"{where}: {bad} of {values.size} thickness values from the {what} are NaN/Inf; "
                "drawn at the middle of the thickness range"
            )
        values = np.where(finite, values, 0.5)
    return np.clip(values, 0.0, 1.0)
