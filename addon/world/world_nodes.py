"""Reading a World's node tree: which node feeds which, and a Mapping's transform as a matrix.

The shapes :mod:`.world` reads directly (a Background, an Environment Texture through reroutes
and Mapping nodes fed by Texture Coordinate "Generated") are recognised here; anything else
raises :class:`Fallback`, and the World is rendered as a panorama instead.
"""

from __future__ import annotations

import math

import numpy as np
from mathutils import Euler

#: Relative tolerance for "this Mapping is a rotation times a uniform scale".
SIMILARITY_TOL = 1e-6


class Fallback(Exception):
    """The tree is not one of the shapes read directly: render a panorama instead."""


def active_world_output(tree):
    """The World Output node Cycles uses (active, for all engines or Cycles), or None."""
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    for preferred in (
        lambda n: n.is_active_output and n.target in {"ALL", "CYCLES"},
        lambda n: n.is_active_output,
        lambda n: True,
    ):
        found = [n for n in outputs if preferred(n)]
        if found:
            return found[0]
    return None


def linked_from(socket):
    """(node, output socket) feeding ``socket`` through reroutes, or None when unlinked."""
    seen = 0
    while socket.is_linked:
        links = [link for link in socket.links]
        if len(links) != 1:
            raise Fallback("multiple links")
        link = links[0]
        if link.is_muted or not link.is_valid:
            raise Fallback("a muted or invalid link")
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            if node.mute:
                raise Fallback("a muted reroute")
            socket = node.inputs[0]
            seen += 1
            if seen > 1000:
                raise Fallback("a reroute loop")
            continue
        return node, link.from_socket
    return None


def mapping_matrix(node) -> np.ndarray:
    """3×3 matrix A with (Mapping output) ∝ A · input for direction lookups; raises Fallback."""
    for ident in ("Location", "Rotation", "Scale"):
        sock = node.inputs.get(ident)
        if sock is not None and sock.enabled and sock.is_linked:
            raise Fallback(f"Mapping with a linked {ident}")
    kind = node.vector_type
    rot = Euler(tuple(node.inputs["Rotation"].default_value), "XYZ").to_matrix()
    r = np.array([list(row) for row in rot], dtype=np.float64)
    scale = np.array(tuple(node.inputs["Scale"].default_value), dtype=np.float64)
    location = node.inputs.get("Location")
    if kind in {"POINT", "TEXTURE"} and location is not None:
        if np.any(np.array(tuple(location.default_value)) != 0.0):
            raise Fallback("Mapping with a location offset")
    if kind in {"POINT", "VECTOR"}:
        return r @ np.diag(scale)
    if np.any(scale == 0.0):
        raise Fallback("Mapping with a zero scale")
    if kind == "TEXTURE":
        return np.diag(1.0 / scale) @ r.T
    if kind == "NORMAL":
        return r @ np.diag(1.0 / scale)
    raise Fallback(f"Mapping of type {kind}")


def texture_matrix(node) -> np.ndarray:
    """The Environment Texture's own (legacy) texture_mapping must be the identity."""
    tm = node.texture_mapping
    identity = (
        tuple(tm.translation) == (0.0, 0.0, 0.0)
        and tuple(tm.rotation) == (0.0, 0.0, 0.0)
        and tuple(tm.scale) == (1.0, 1.0, 1.0)
        and not tm.use_min
        and not tm.use_max
        and (tm.mapping_x, tm.mapping_y, tm.mapping_z) == ("X", "Y", "Z")
    )
    if not identity:
        raise Fallback("Environment Texture with a texture mapping")
    return np.eye(3)


def lookup_matrix(env_node, mappings: list | None = None) -> np.ndarray:
    """A with lookup direction d' ∝ A d for the Environment Texture's Vector input; the names of
    the Mapping nodes on the way are appended to ``mappings``."""
    a = texture_matrix(env_node)
    source = linked_from(env_node.inputs["Vector"])
    while source is not None:
        node, out = source
        if node.mute:
            raise Fallback(f"muted node '{node.name}'")
        if node.bl_idname == "ShaderNodeMapping":
            a = a @ mapping_matrix(node)
            if mappings is not None:
                mappings.append(node.name)
            source = linked_from(node.inputs["Vector"])
            if source is None:
                raise Fallback("Mapping with an unlinked Vector")
            continue
        if node.bl_idname == "ShaderNodeTexCoord" and out.identifier == "Generated":
            return a
        raise Fallback(f"texture coordinates from '{node.name}'")
    return a


def rotation_from_lookup(a: np.ndarray) -> tuple[np.ndarray, int]:
    """Split A = s·Q (s > 0) into a proper rotation P and a parity ±1 with Q = parity·P."""
    gram = a @ a.T
    k = np.trace(gram) / 3.0
    if not k > 0.0 or np.max(np.abs(gram - k * np.eye(3))) > SIMILARITY_TOL * k:
        raise Fallback("Mapping with a non-uniform scale")
    q = a / math.sqrt(k)
    parity = 1 if np.linalg.det(q) > 0.0 else -1
    return parity * q, parity


def uses_light_path(tree, seen=None) -> bool:
    """Whether ``tree`` (or a node group in it) has a Light Path node."""
    seen = seen or set()
    if tree.name_full in seen:
        return False
    seen.add(tree.name_full)
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeLightPath":
            return True
        group = getattr(node, "node_tree", None)
        if group is not None and uses_light_path(group, seen):
            return True
    return False
