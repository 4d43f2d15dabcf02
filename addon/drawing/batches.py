"""Batches: a mesh's triangles of one material slot on the GPU, with its thickness per corner.

:func:`slot_batch` builds the :class:`BatchEntry` of an (object, material slot): positions,
normals and, for a film whose thickness varies, the thickness parameter per corner
(:func:`batch_thickness`: from the extension's source, :mod:`..thickness.thickness`, its
*Image* source read per pixel from Blender's texture and Blender's noise on a large mesh, their
corners computed off the draw, :mod:`..thickness.corners`, Blender's
Noise Texture or a linked Principled thickness, :mod:`..thickness.linked`).
:func:`thickness_source` is what the batches' thickness is made of, part of their signature: a
change rebuilds them. :mod:`.scene_draw` keeps the batches (``CACHES.batches``) and decides when
to build one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...precompute.materials.perlin import NoiseSpec
from ..gpu.mesh import MeshBatch, mesh_arrays, vertex_arrays
from ..materials.principled import linked_thickness_socket
from ..thickness import generated, linked
from ..thickness.corners import image_parameters, noise_parameters
from ..thickness.thickness import NAN_PARAMETER, non_finite_note, thickness_field, thickness_inputs

__all__ = ["BatchEntry", "batch_thickness", "slot_batch", "thickness_source"]


@dataclass
class BatchEntry:
    """One (object, material slot, instance)'s batch and what it was built from.

    ``signature``: the mesh's name and sizes, whether the material's thickness varies, its
    :func:`.thickness.thickness_inputs` and whether it is a thin transparent wall's (a different
    signature rebuilds the batch; nothing else of the material is in the batch, so a roughness
    drag rebuilds none);
    ``thickness``: the per-vertex thickness parameters uploaded (float32, one per corner; None
    for a constant thickness), kept to be read back; ``notes``: what the build found wrong
    (NaN thickness values, a missing attribute), repeated in every frame's messages.
    """

    signature: tuple
    batch: MeshBatch | None
    thickness: np.ndarray | None = None
    notes: tuple = ()


def thickness_source(bpy_material, props, desc):
    """(the batches' thickness key, (material, socket) of a linked Principled thickness or None):
    the extension's source settings, or the linked graph's content (an edit rebuilds batches)."""
    if not desc.varies:
        return None, None
    if props is not None:
        return thickness_inputs(props), None
    socket = linked_thickness_socket(bpy_material)
    if socket is None:
        return None, None
    return ("LINKED", linked.tree_key(socket), desc.thickness_range_nm), (bpy_material, socket)


def batch_thickness(name: str, obj_eval, mesh, props, desc, linked_source):
    """(per-corner thickness parameter or None, notes, whether a bake or a map is awaited, the
    thickness map or None, the noise computed per pixel or None) of a batch: from the
    extension's source (``props``: the *Image* and *Blender Noise* sources, :mod:`.corners`; the
    rest, :func:`.thickness.thickness_field`), or from the link into a Principled BSDF's Thin
    Film Thickness (``linked_source`` = (material, socket), :func:`.linked.corner_parameters`).
    The map, (corner UVs, parameters (H, W) or an image's texture, repeat), is read per pixel
    (:mod:`..thickness.maps`) where a texture or a bake gives one; the noise sources and a
    linked Noise Texture are computed per pixel (``MeshBatch.noise``)."""
    notes = []
    if not desc.varies:
        return None, notes, False, None, None
    thickness_map, waiting, noise = None, False, _source_noise(props)
    try:
        if props is not None and props.enabled and props.thickness_source == "IMAGE":
            thickness, nan_count, thickness_map, waiting = image_parameters(obj_eval, mesh, props)
        elif props is not None and props.enabled and props.thickness_source == "BLENDER_NOISE":
            thickness, nan_count, waiting = noise_parameters(obj_eval, mesh, props)
        elif props is not None and props.enabled:
            thickness, nan_count = thickness_field(obj_eval, mesh, props)
        elif linked_source is not None:
            thickness, nan_count, thickness_map, waiting, noise = linked.corner_parameters(
                obj_eval, mesh, *linked_source, desc.thickness_range_nm
            )
        else:
            return None, notes, False, None, None
    except linked.Pending as exc:  # built again on the next frame, after the timer's bake
        notes.append(f"{name}: {exc}; using the middle of the thickness range meanwhile")
        return None, notes, True, None, None
    except ValueError as exc:
        notes.append(f"{name}: {exc}; using the middle of the thickness range")
        return None, notes, False, None, None
    if nan_count:
        notes.append(non_finite_note(f"object {name!r}", nan_count, thickness.size))
    return thickness, notes, waiting, thickness_map, noise  # waiting: for a map or the corners


def _source_noise(props):
    """The extension's noise source computed per pixel from the object-space position
    (``MeshBatch.noise``), its corners by the same function: the *Noise* source's (scale, seed)
    (tf_noise.glsl), the *Blender Noise* source's Noise Texture (tf_perlin.glsl), else None."""
    if props is None or not props.enabled or not props.vary_thickness:
        return None
    if props.thickness_source == "NOISE":
        return float(props.noise_scale), int(props.noise_seed)
    if props.thickness_source == "BLENDER_NOISE":
        return NoiseSpec(4, float(props.noise_scale), float(props.noise_seed))
    return None


def _slot_triangles(mesh, triangles, slot: int) -> np.ndarray:
    """The rows of ``triangles`` (one per loop triangle) whose faces use material slot ``slot``
    (the faces' material indices and the triangles' faces read as arrays, not item by item)."""
    tri_poly = np.empty(len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangle_polygons.foreach_get("value", tri_poly)
    poly_mat = np.zeros(len(mesh.polygons), dtype=np.int32)
    attr = mesh.attributes.get("material_index")  # absent: every face uses slot 0
    if attr is not None and attr.domain == "FACE" and attr.data_type == "INT":
        attr.data.foreach_get("value", poly_mat)
    return triangles[poly_mat[tri_poly] == slot]


def slot_batch(
    name: str, obj_eval, mesh, slot: int, props, desc, signature, linked_source=None, wall: bool = False
) -> BatchEntry:
    """The batch of the triangles of material slot ``slot`` (None if it has none); ``wall``: a
    thin transparent wall's, which reads whether the slot's triangles close (MeshBatch.inside).

    ``props``: the ORIGINAL material's ``thinfilm_sh`` settings (Blender's evaluated copy of a
    material is not refreshed when an add-on property changes), or None; ``name``: the object's;
    ``linked_source``: (material, Thin Film Thickness socket) of a Principled BSDF whose
    thickness is linked, or None.
    """
    single = len(obj_eval.material_slots) <= 1
    if single and len(mesh.loop_triangles) == 0:
        mesh.calc_loop_triangles()
    if single and len(mesh.loop_triangles) == 0:
        return BatchEntry(signature, None)
    arrays = None
    if not single:  # the slot's triangles first: a slot without faces reads no thickness
        arrays = mesh_arrays(mesh)
        if arrays is None or not len(triangles := _slot_triangles(mesh, arrays[2], slot)):
            return BatchEntry(signature, None)
        arrays = (*arrays[:2], triangles, None)
    thickness, notes, waiting, thickness_map, noise = batch_thickness(
        name, obj_eval, mesh, props, desc, linked_source
    )
    if desc.varies and thickness is None:
        thickness = np.full(len(mesh.loops), NAN_PARAMETER, dtype=np.float32)
    if thickness is not None:  # thickness_field's values are finite and in [0, 1]: a last guard
        thickness = np.nan_to_num(
            np.clip(np.asarray(thickness, dtype=np.float32), 0.0, 1.0), nan=NAN_PARAMETER
        )
    # one row per vertex where nothing differs between a vertex's corners (thickness included)
    shared = vertex_arrays(mesh, thickness) if single and thickness_map is None else None
    with_orco = getattr(noise, "orco", False)
    if shared is not None:
        arrays, upload = shared, shared[3]
        orco = generated.orco_vertices(obj_eval, mesh) if with_orco else None
    else:
        arrays = mesh_arrays(mesh) if single else arrays
        upload = thickness
        orco = generated.orco_corners(obj_eval, mesh) if with_orco else None
    if arrays is None:
        return BatchEntry(signature, None)
    positions, normals, triangles, _ = arrays
    batch = MeshBatch.from_arrays(
        positions, normals, triangles, upload, wall=wall, thickness_map=thickness_map, orco=orco
    )
    if batch is not None and noise is not None:  # per pixel (TF_THICKNESS_NOISE)
        batch.noise = noise
    if waiting:
        signature = ("waiting for a bake", signature)  # never equal: rebuilt on the next frame
    return BatchEntry(signature, batch, thickness, tuple(notes))
