"""glTF ``KHR_materials_iridescence``, both ways, through the glTF add-on's user-extension hooks.

Blender's bundled importer (io_scene_gltf2, checked against 5.2) builds Image → Separate Color
(G) → Mix(min, max) → *Thin Film Thickness* for ``iridescenceThicknessTexture``, but loses:

- ``iridescenceThicknessMaximum``: it reads the key ``iridescenceThickness`` (the draft name), so
  every file written to the ratified spec gets the default 400 nm;
- ``iridescenceIor`` and ``iridescenceFactor`` when a thickness texture is present (only the
  texture-free branch sets them).

:class:`ImportUserExtension` (exposed to the glTF add-on as ``glTF2ImportUserExtension`` by the
package's ``__init__``) runs after each material is built and writes the file's own values into
the nodes the importer left (:func:`repair_import`); the original values are also kept in the
material's custom property ``KHR_materials_iridescence``. A file imported while the extension
was not enabled keeps the importer's losses (the material's nodes no longer hold the file's
maximum; re-import it).

:class:`ExportUserExtension` (``glTF2ExportUserExtension``) adds the extension to every material
the preview shows a film for (:func:`export_iridescence`): the glTF add-on itself writes it only
for materials with its "glTF Material Output" group, and then keeps its own values and texture.
A film whose thickness varies through anything but the importer's texture graph (a Noise
Texture, the extension's own source) is baked by Cycles into a Non-Color texture at the first
user's UVs and written as ``iridescenceThicknessTexture`` with its range. What glTF cannot
carry — several layers, a metal's n + ik, a dispersive film, an ambient index ≠ 1 — is warned
about (:data:`LAST_EXPORT_WARNINGS`, and the exporter's log).
"""

from __future__ import annotations

import json

import bpy

from ...precompute.materials.conductors import real_index
from ..thickness.linked import bake_thickness_image
from .description import description
from .principled import SOCKET_FILM_IOR, SOCKET_THICKNESS, principled_node

__all__ = [
    "EXTENSION",
    "LAST_EXPORT_WARNINGS",
    "ExportUserExtension",
    "ImportUserExtension",
    "export_iridescence",
    "export_warnings",
    "repair_import",
]

EXTENSION = "KHR_materials_iridescence"
#: The spec's defaults (KHR_materials_iridescence README): factor 0, IOR 1.3, 100–400 nm.
DEFAULTS = {
    "iridescenceFactor": 0.0,
    "iridescenceIor": 1.3,
    "iridescenceThicknessMinimum": 100.0,
    "iridescenceThicknessMaximum": 400.0,
}
#: Labels the importer gives its two thickness Value nodes.
_MIN_LABEL, _MAX_LABEL = "Iridescence Thickness Minimum", "Iridescence Thickness Maximum"
#: What the last export warned about, one line per material and problem (the tests read it).
LAST_EXPORT_WARNINGS: list[str] = []


def _file_values(ext: dict) -> dict:
    values = {key: float(ext.get(key, default)) for key, default in DEFAULTS.items()}
    values["hasThicknessTexture"] = ext.get("iridescenceThicknessTexture") is not None
    return values


def _gltf_output_socket(tree, name: str):
    """An input of the importer's "glTF Material Output" group node, or None."""
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeGroup" and name in node.inputs:
            return node.inputs[name]
    return None


def repair_import(bpy_material, ext: dict) -> dict:
    """Write the file's iridescence values into the nodes Blender's importer built; returns them.

    Thin Film IOR = ``iridescenceIor``; the importer's Value nodes (texture) or the socket's own
    value (no texture) = ``iridescenceThicknessMaximum`` / ``Minimum``; the group's Iridescence
    Factor = ``iridescenceFactor``. The values are kept in the custom property
    ``KHR_materials_iridescence`` (JSON).
    """
    values = _file_values(ext)
    bpy_material[EXTENSION] = json.dumps(values)
    node = principled_node(bpy_material)
    if node is None:
        return values
    node.inputs[SOCKET_FILM_IOR].default_value = values["iridescenceIor"]
    socket = node.inputs[SOCKET_THICKNESS]
    for item in bpy_material.node_tree.nodes:
        if item.bl_idname == "ShaderNodeValue" and item.label == _MAX_LABEL:
            item.outputs[0].default_value = values["iridescenceThicknessMaximum"]
        elif item.bl_idname == "ShaderNodeValue" and item.label == _MIN_LABEL:
            item.outputs[0].default_value = values["iridescenceThicknessMinimum"]
    if not socket.is_linked:
        socket.default_value = values["iridescenceThicknessMaximum"]
    factor = _gltf_output_socket(bpy_material.node_tree, "Iridescence Factor")
    if factor is not None and not factor.is_linked:
        factor.default_value = values["iridescenceFactor"]
    return values


def export_warnings(desc) -> list[str]:
    """What glTF's single dielectric film cannot carry of a description."""
    out = []
    if len(desc.layers) > 1:
        out.append(f"{len(desc.layers)} film layers: glTF has one film; exported the top layer")
    if isinstance(desc.substrate, dict) or real_index(desc.substrate).imag > 0.0:
        out.append("a metal substrate's n + ik is not in glTF: the base is exported by the core material")
    if desc.layers and (isinstance(desc.layers[0].index, dict) or real_index(desc.layers[0].index).imag):
        out.append("the film's dispersion / absorption is not in glTF: exported n at 550 nm")
    if desc.ambient != 1.0:
        out.append(f"ambient index {desc.ambient:g} is not in glTF (it assumes air)")
    return out


def _texture_graph(bpy_material) -> bool:
    """Whether the thickness comes from the importer's texture graph (the glTF add-on writes it)."""
    node = principled_node(bpy_material)
    if node is None or not node.inputs[SOCKET_THICKNESS].is_linked:
        return False
    labels = {n.label for n in bpy_material.node_tree.nodes if n.bl_idname == "ShaderNodeValue"}
    return _MAX_LABEL in labels and _MIN_LABEL in labels


def _users(bpy_material) -> list:
    return [
        obj
        for obj in bpy.context.scene.objects
        if obj.type == "MESH"
        and obj.data.uv_layers
        and any(s.material == bpy_material for s in obj.material_slots)
    ]


def _baked_texture(bpy_material, thickness_range, export_settings):
    """(glTF TextureInfo of the thickness baked at the first user's UVs, or None, a note)."""
    users = _users(bpy_material)
    if not users or export_settings is None:
        return None, "no object with a UV map uses it to bake the thickness on"
    image = bake_thickness_image(users[0], bpy_material, thickness_range)
    if image is None:
        return None, "its thickness could not be baked"
    from io_scene_gltf2.blender.exp.material.search_node_tree import NodeSocket  # optional add-on
    from io_scene_gltf2.blender.exp.material.texture_info import gather_texture_info  # same

    tree = bpy_material.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")  # removed below: the exporter reads nodes
    texture.image = image
    separate = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(texture.outputs["Color"], separate.inputs["Color"])
    try:
        socket = NodeSocket(separate.inputs["Color"], [tree])
        info = gather_texture_info(socket, (socket,), export_settings)[0]
    finally:
        tree.nodes.remove(separate)
        tree.nodes.remove(texture)
    where = users[0].name
    return info, f"thickness baked by Cycles into a {image.size[0]}² texture at {where!r}'s UVs"


def export_iridescence(extensions: dict, bpy_material, export_settings=None) -> list[str]:
    """Add KHR_materials_iridescence to a glTF material's ``extensions`` (name → Extension);
    returns warnings. A material without a film is left alone. A thickness that varies by
    anything but the importer's texture graph is baked into a texture (Cycles, at the first
    user's UVs; ``export_settings`` is the exporter's, needed to add it)."""
    try:
        desc = description(bpy_material)
    except ValueError as exc:
        return [f"not exported as iridescence: {exc}"]
    if desc is None or not desc.layers:
        return []
    notes = export_warnings(desc)
    existing = extensions.get(EXTENSION)
    data = dict(existing.extension) if existing is not None else {}
    data.setdefault("iridescenceFactor", 1.0)
    data.setdefault("iridescenceIor", max(1.0, real_index(desc.layers[0].index).real))
    if existing is None or "iridescenceThicknessTexture" not in data:
        if desc.thickness_range_nm is None:
            data["iridescenceThicknessMaximum"] = float(desc.layers[0].thickness_nm)
        else:
            lo, hi = (float(v) for v in desc.thickness_range_nm)
            data["iridescenceThicknessMinimum"], data["iridescenceThicknessMaximum"] = lo, hi
            if not _texture_graph(bpy_material):
                info, why = _baked_texture(bpy_material, (lo, hi), export_settings)
                if info is not None:
                    data["iridescenceThicknessTexture"] = info
                    props = getattr(bpy_material, "thinfilm_sh", None)
                    if props is not None and props.enabled and props.thickness_source == "NOISE":
                        notes.append(
                            "the value noise is exported as Blender's Noise Texture (another pattern)"
                        )
                else:
                    notes.append(f"thickness varies {lo:g}–{hi:g} nm but {why}: exported its range only")
    from io_scene_gltf2.io.com.gltf2_io_extensions import Extension  # optional add-on, at export

    extensions[EXTENSION] = Extension(EXTENSION, data, False)
    return notes


class ImportUserExtension:
    """The glTF importer's hook object (``glTF2ImportUserExtension``)."""

    def gather_import_material_after_hook(self, pymaterial, vertex_color, bpy_material, gltf):
        """After a material is built: repair what the importer lost of KHR_materials_iridescence."""
        ext = (pymaterial.extensions or {}).get(EXTENSION)
        if ext:
            repair_import(bpy_material, ext)


class ExportUserExtension:
    """The glTF exporter's hook object (``glTF2ExportUserExtension``)."""

    def __init__(self):
        LAST_EXPORT_WARNINGS.clear()

    def gather_material_hook(self, gltf2_material, bpy_material, export_settings):
        """After a material is gathered: add KHR_materials_iridescence for a film material."""
        if gltf2_material.extensions is None:
            gltf2_material.extensions = {}
        for note in export_iridescence(gltf2_material.extensions, bpy_material, export_settings):
            line = f"material {bpy_material.name!r}: {note}"
            LAST_EXPORT_WARNINGS.append(line)
            log = export_settings.get("log")
            if log is not None:
                log.warning(f"Thin Film SH: {line}")
