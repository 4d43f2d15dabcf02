"""Generated coordinates as Blender's renders read them, for a linked thickness.

A Noise Texture (or any texture) reads a mesh's *Generated* coordinates by default. Blender's
renders read them in the **original** mesh's texture space: as the evaluated positions after
modifiers that build geometry (:data:`GENERATED_IS_POSITION`), and as the original vertices'
positions (``orco``) after Deform modifiers and shape keys (:data:`DEFORMS`), not in the
evaluated mesh's own bounds (docs/texture-thickness.md, *Generated coordinates of a modified
mesh*). :func:`generated_space` gives the numpy evaluator and the corner bake those
coordinates; :func:`orco_corners` gives the batch the positions a Noise Texture drawn per pixel
reads (``TF_NOISE_ORCO``); :func:`read_orco_attribute` makes a bake's material read them.
"""

from __future__ import annotations

import numpy as np

from ..gpu.mesh import corner_vertices

#: The corner bake copy's attribute of Generated coordinates before a deformation (a plain
#: name: names that start with a dot are Blender's internal attributes).
ORCO_ATTRIBUTE = "thinfilm_sh_orco"


#: Modifiers after which a mesh's Generated coordinates are still its evaluated positions in the
#: original mesh's texture space. Measured in Blender 5.2 (Cycles renders of Generated against
#: Object coordinates mapped by that texture space, 2026-12-07): equal to 1e-4 for each of
#: these, Geometry Nodes' Set Position included; 0.08–0.15 apart (the median of a rotated cube)
#: for Displace, Simple Deform, Smooth and a shape key, whose Generated coordinates stay where
#: the vertices were before the deformation.
GENERATED_IS_POSITION = frozenset(
    {
        "ARRAY",
        "BEVEL",
        "DECIMATE",
        "EDGE_SPLIT",
        "MIRROR",
        "MULTIRES",
        "NODES",
        "REMESH",
        "SOLIDIFY",
        "SUBSURF",
        "TRIANGULATE",
        "WEIGHTED_NORMAL",
        "WELD",
        "WIREFRAME",
    }
)


def original_texspace(obj):
    """(location, size) of a mesh object's original mesh's texture space, else None: the space
    Blender's renders read Generated coordinates in, whatever the modifiers (not the evaluated
    mesh's own bounds, smaller than the cage under a Subdivision Surface)."""
    original = obj.original if hasattr(obj, "original") else obj
    if original.type != "MESH":
        return None
    return tuple(original.data.texspace_location), tuple(original.data.texspace_size)


#: Blender's Deform modifiers: they move vertices and keep them, one for one. After them (and
#: after shape keys) a mesh's Generated coordinates are its original vertices' positions
#: (measured for Displace, Simple Deform, Smooth, Wave, Lattice, Armature and a shape key: the
#: renders' Generated equal to them to 1e-6, 0.007–0.43 from the deformed positions).
DEFORMS = frozenset(
    {
        "ARMATURE",
        "CAST",
        "CORRECTIVE_SMOOTH",
        "CURVE",
        "DISPLACE",
        "HOOK",
        "LAPLACIANDEFORM",
        "LAPLACIANSMOOTH",
        "LATTICE",
        "MESH_DEFORM",
        "SHRINKWRAP",
        "SIMPLE_DEFORM",
        "SMOOTH",
        "SURFACE_DEFORM",
        "WARP",
        "WAVE",
    }
)

#: Texture nodes whose unlinked Vector input reads Generated coordinates.
_GENERATED_BY_DEFAULT = frozenset(
    {
        "ShaderNodeTexBrick",
        "ShaderNodeTexChecker",
        "ShaderNodeTexGabor",
        "ShaderNodeTexGradient",
        "ShaderNodeTexMagic",
        "ShaderNodeTexNoise",
        "ShaderNodeTexVoronoi",
        "ShaderNodeTexWave",
    }
)


def texspace(obj):
    """(location, size) of the texture space in which a mesh object's Generated coordinates are
    its evaluated mesh's positions (:func:`original_texspace`), or None where they are not: a
    deforming modifier (one outside :data:`GENERATED_IS_POSITION`) or shape keys, or an object
    that is not a mesh."""
    original = obj.original if hasattr(obj, "original") else obj
    if original.type != "MESH" or original.data.shape_keys is not None:
        return None
    used = [m for m in original.modifiers if m.show_viewport or m.show_render]
    if any(m.type not in GENERATED_IS_POSITION for m in used):
        return None
    return original_texspace(obj)


def deformed_only(obj) -> bool:
    """Whether only Deform modifiers (:data:`DEFORMS`) and shape keys move ``obj``'s mesh, which
    keeps its original's vertices one for one."""
    original = obj.original if hasattr(obj, "original") else obj
    if original.type != "MESH":
        return False
    return all(m.type in DEFORMS for m in original.modifiers if m.show_viewport or m.show_render)


def orco_corners(obj, mesh) -> np.ndarray | None:
    """(N, 3) float32 where ``mesh``'s (``obj``'s evaluated mesh's) corners were before Deform
    modifiers and shape keys moved them (:func:`generated_space`), or None."""
    orco = generated_space(obj, mesh)[1]
    return None if orco is None else orco[corner_vertices(mesh)].astype(np.float32)


def generated_space(obj, mesh) -> tuple:
    """(texture space, orco) in which ``mesh`` (``obj``'s evaluated mesh) has its Generated
    coordinates (:class:`.linked_nodes._Context`): (:func:`texspace`, None) where they are its
    positions; (the original's, its original vertices' positions (V, 3)) where only Deform
    modifiers (:data:`DEFORMS`) and shape keys moved them, vertex for vertex; (None, None)
    otherwise (a Deform before a modifier that builds geometry)."""
    found = texspace(obj)
    if found is not None:
        return found, None
    original = obj.original if hasattr(obj, "original") else obj
    if not deformed_only(obj) or len(original.data.vertices) != len(mesh.vertices):
        return None, None
    orco = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    original.data.vertices.foreach_get("co", orco)  # the basis shape: what Generated reads
    return original_texspace(obj), orco.reshape(-1, 3).astype(np.float64)


def read_orco_attribute(tree, orco_name: str) -> None:
    """Make the nodes of ``tree`` that read Generated coordinates (a Texture Coordinate's
    output, a texture's unlinked Vector) read the corner bake copy's attribute ``orco_name``
    instead (top level only: a node group is shared with other materials)."""
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type, attribute.attribute_name = "GEOMETRY", orco_name
    vector = attribute.outputs["Vector"]
    for node in list(tree.nodes):
        if node.bl_idname == "ShaderNodeTexCoord":
            for link in list(node.outputs["Generated"].links):
                tree.links.new(vector, link.to_socket)
        elif node.bl_idname in _GENERATED_BY_DEFAULT and not node.inputs["Vector"].is_linked:
            tree.links.new(vector, node.inputs["Vector"])
