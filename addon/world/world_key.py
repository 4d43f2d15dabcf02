"""The content key of a scene's World: what :func:`.world.world_sh` depends on, read cheaply.

:func:`world_key` hashes a canonical description of the World (every node setting, socket
value and link of its node tree, node groups and referenced objects; images by path, file size
and mtime, or packed size, never by their pixels), the viewport colour, l_max and the working
space. The draw code polls it every frame to see whether the World changed; the World's SH and
panorama are recomputed only when it does.
"""

from __future__ import annotations

import math
import os

import bpy

from ...precompute.tables import table_io
from ..colour_space import working_space

__all__ = [
    "KEY_VERSION",
    "describe_image",
    "image_path",
    "world_key",
    "world_uses_nodes",
]

#: Version of the key description; bump when the computation changes so old entries miss.
KEY_VERSION = 1
_MAX_DESCRIBE_DEPTH = 4


def _node_ui_properties() -> frozenset:
    base = {p.identifier for p in bpy.types.Node.bl_rna.properties}
    return frozenset(base - {"name", "mute"})


_SKIP_NODE_PROPS = _node_ui_properties()
_SKIP_STRUCT_PROPS = frozenset({"rna_type", "select", "select_left_handle", "select_right_handle"})


def _plain(value):
    """A bpy/mathutils value as JSON-friendly data (NaN/Inf become strings)."""
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else repr(value)
    if isinstance(value, set | frozenset):
        return sorted(str(v) for v in value)
    if isinstance(value, bpy.types.ID):
        return {"id": type(value).__name__, "name": value.name_full}
    try:
        return [_plain(v) for v in value]
    except TypeError:
        return repr(value)


def _file_stat(path: str):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]


def image_path(image) -> str:
    """Absolute path of an image's file (resolved against its library), or ''."""
    return bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""


def describe_image(image) -> dict:
    """What identifies an image's pixels, without loading them (also the thickness image's key)."""
    desc = {
        "name": image.name_full,
        "source": image.source,
        "filepath": image.filepath,
        "colorspace": image.colorspace_settings.name,
        "alpha_mode": image.alpha_mode,
        "is_dirty": bool(image.is_dirty),
    }
    if image.packed_file is not None:
        desc["packed_size"] = image.packed_file.size
    elif image.source in {"FILE", "SEQUENCE", "MOVIE", "TILED"}:
        path = image_path(image)
        desc["abspath"] = path
        desc["stat"] = _file_stat(path)
    if image.source == "GENERATED":
        desc["generated"] = [
            image.generated_type,
            image.generated_width,
            image.generated_height,
            _plain(image.generated_color),
            bool(image.use_generated_float),
        ]
    return desc


def _describe_struct(struct, depth: int, seen: set, skip=_SKIP_STRUCT_PROPS) -> dict:
    """Every RNA property of ``struct`` (values, nested structs, collections, referenced IDs)."""
    out = {}
    for prop in struct.bl_rna.properties:
        ident = prop.identifier
        if ident in skip or ident.startswith("bl_"):
            continue
        try:
            value = getattr(struct, ident)
        except (AttributeError, RuntimeError, TypeError):
            continue
        if prop.type == "POINTER":
            out[ident] = _describe_pointer(value, depth, seen)
        elif prop.type == "COLLECTION":
            if depth <= 0:
                out[ident] = len(value)
            else:
                out[ident] = [_describe_pointer(item, depth, seen) for item in value]
        else:
            out[ident] = _plain(value)
    return out


def _describe_pointer(value, depth: int, seen: set):
    if value is None:
        return None
    if isinstance(value, bpy.types.Image):
        return describe_image(value)
    if isinstance(value, bpy.types.NodeTree):
        return _describe_tree(value, seen)
    if isinstance(value, bpy.types.Object):
        return {"object": value.name_full, "matrix_world": _plain(value.matrix_world)}
    if isinstance(value, bpy.types.ID):
        return _plain(value)
    if depth <= 0:
        return type(value).__name__
    return _describe_struct(value, depth - 1, seen)


def _socket_value(socket):
    return _plain(socket.default_value) if hasattr(socket, "default_value") else None


def _describe_tree(tree, seen: set) -> dict | str:
    """Nodes (type, settings, socket values) and links of a node tree, node groups included."""
    if tree.name_full in seen:
        return {"tree": tree.name_full}
    seen = seen | {tree.name_full}
    nodes = {}
    for node in tree.nodes:
        desc = _describe_struct(node, _MAX_DESCRIBE_DEPTH, seen, skip=_SKIP_NODE_PROPS | _SKIP_STRUCT_PROPS)
        desc["bl_idname"] = node.bl_idname
        desc["inputs"] = [[s.identifier, _socket_value(s)] for s in node.inputs]
        desc["outputs"] = [[s.identifier, _socket_value(s)] for s in node.outputs]
        nodes[node.name] = desc
    links = sorted(
        [
            link.from_node.name,
            link.from_socket.identifier,
            link.to_node.name,
            link.to_socket.identifier,
            bool(link.is_muted),
            bool(link.is_valid),
        ]
        for link in tree.links
    )
    return {"tree": tree.name_full, "nodes": nodes, "links": links}


def world_uses_nodes(world) -> bool:
    """True when the World is shaded by its node tree."""
    if world.node_tree is None:
        return False
    if bpy.app.version >= (5, 0, 0):  # use_nodes is deprecated and always on since 5.0
        return True
    return bool(world.use_nodes)


def _describe_world(world, without=frozenset()) -> dict | None:
    if world is None:
        return None
    desc = {"color": _plain(world.color), "use_nodes": world_uses_nodes(world)}
    if desc["use_nodes"]:
        desc["tree"] = _describe_tree(world.node_tree, set())
        nodes = desc["tree"].get("nodes", {}) if isinstance(desc["tree"], dict) else {}
        for node_name, ident in without:  # the cheap parameters: read apart (world_params.world_parts)
            for entry in nodes.get(node_name, {}).get("inputs", ()):
                if entry[0] == ident:
                    entry[1] = "parameter"
    return desc


def world_key(scene, l_max: int = 8, *, without=()) -> str:
    """Content hash of everything :func:`.world.world_sh` depends on; cheap (reads no pixels).

    Covers the World's node tree (every node setting, socket value and link, node groups and
    referenced objects), images (path, size and mtime of the file, or packed size; generated
    settings), the World's viewport colour, ``l_max`` and the working space. Edits to an
    image's pixels inside Blender are seen only through ``is_dirty`` (once).

    ``without``: (node name, input identifier) pairs of the World's top-level tree whose values
    are left out (and named instead): the World's *content* key, for values applied without
    recomputation (:func:`.world_params.world_parts`: a Background Strength, a Mapping rotation).
    """
    without = frozenset(without)
    description = {
        "version": KEY_VERSION,
        "l_max": int(l_max),
        "working_space": working_space(),
        "world": _describe_world(scene.world, without),
    }
    if without:
        description["parameters"] = sorted(without)
    return table_io.content_key(description)
