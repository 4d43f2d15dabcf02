"""Generated coordinates as Blender's renders read them, for a linked thickness.

A Noise Texture (or any texture) reads a mesh's *Generated* coordinates by default. Blender's
renders read them in the **original** mesh's texture space: as the evaluated positions after
modifiers that build geometry (:data:`GENERATED_IS_POSITION`), and as the original vertices'
positions (``orco``) after Deform modifiers and shape keys (:data:`DEFORMS`), not in the
evaluated mesh's own bounds (docs/texture-thickness.md, *Generated coordinates of a modified
mesh*). Where building modifiers follow the deformation (an Armature, then a Subdivision
Surface), ``orco`` is the original object evaluated again without its Deform modifiers and
shape keys (:func:`evaluate_orco`: a copy in a temporary scene, never inside a draw; cached by
what it depends on, not by the deformation: :func:`orco_key`). :func:`generated_space` gives
the numpy evaluator and the corner bake those coordinates; :func:`orco_corners` gives the batch
the positions a Noise Texture drawn per pixel reads (``TF_NOISE_ORCO``);
:func:`read_orco_attribute` makes a bake's material read them.
"""

from __future__ import annotations

import contextlib
import hashlib

import bpy
import numpy as np

from .. import caches
from ..gpu.mesh import corner_vertices

#: The corner bake copy's attribute of Generated coordinates before a deformation (a plain
#: name: names that start with a dot are Blender's internal attributes).
ORCO_ATTRIBUTE = "thinfilm_sh_orco"
#: The name of the temporary scene, object and mesh :func:`evaluate_orco` makes and removes.
_ORCO_PREFIX = ".thinfilm_sh_orco"
#: Evaluated positions without the Deform modifiers and shape keys ((V, 3) float64) by
#: :func:`orco_key`.
ORCOS = caches.register("generated_orco", caches.LRU(16), scope=caches.FILE)


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
    original = _original(obj)
    if original.type != "MESH":
        return None
    return tuple(original.data.texspace_location), tuple(original.data.texspace_size)


#: Modifiers after which Generated coordinates are the evaluated positions too (Cycles renders
#: of a turned cube, 2026-12-08: within 7.3e-6 of the texture space), but whose faces follow
#: where the vertices are (a Boolean's cut, a Skin's hulls, a Screw's merged vertices): after a
#: deformation or shape keys, evaluated again without them, they would not match the deformed
#: mesh vertex for vertex, so there the link stays baked.
GENERATED_IS_POSITION_UNDEFORMED = frozenset({"BOOLEAN", "SCREW", "SKIN"})


#: Blender's Deform modifiers, and the physics modifiers that move vertices one for one (Cloth,
#: Soft Body): after them (and after shape keys) a mesh's Generated coordinates are its original
#: vertices' positions (measured for Displace, Simple Deform, Smooth, Wave, Lattice, Armature
#: and a shape key: the renders' Generated equal to them to 1e-6, 0.007–0.43 from the deformed
#: positions; a grid's Cloth and Soft Body ten frames in, 2026-12-08: equal to them, 0.22 and
#: 0.24 in the median from the simulated positions).
DEFORMS = frozenset(
    {
        "ARMATURE",
        "CAST",
        "CLOTH",
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
        "SOFT_BODY",
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


#: :func:`kind`'s answers: Generated coordinates are the evaluated positions, the original
#: vertices' positions, or the positions of the object evaluated again without its deformation.
POSITIONS, ORIGINAL, EVALUATED = "positions", "original", "evaluated"


def _original(obj):
    return obj.original if hasattr(obj, "original") else obj


def _used(original) -> list:
    """The object's modifiers that the viewport or the render runs."""
    return [m for m in original.modifiers if m.show_viewport or m.show_render]


def kind(obj) -> str | None:
    """How a mesh object's Generated coordinates are read: :data:`POSITIONS` (only modifiers of
    :data:`GENERATED_IS_POSITION` and :data:`GENERATED_IS_POSITION_UNDEFORMED`, no shape
    keys), :data:`ORIGINAL` (only Deform modifiers,
    :data:`DEFORMS`, and shape keys: the vertices kept one for one), :data:`EVALUATED` (both
    kinds: :func:`evaluate_orco`), or None (another modifier, one of
    :data:`GENERATED_IS_POSITION_UNDEFORMED` with a deformation, or not a mesh)."""
    original = _original(obj)
    if original.type != "MESH":
        return None
    types = {m.type for m in _used(original)}
    if not types <= DEFORMS | GENERATED_IS_POSITION | GENERATED_IS_POSITION_UNDEFORMED:
        return None
    if original.data.shape_keys is None and not types & DEFORMS:
        return POSITIONS
    if types & GENERATED_IS_POSITION_UNDEFORMED:
        return None
    return ORIGINAL if types <= DEFORMS else EVALUATED


def texspace_affine(space) -> tuple[np.ndarray, np.ndarray]:
    """(scale (3,), offset (3,)) taking object-space points into the texture space ``space``
    ((location, size)): 0–1 across it, Blender's Generated coordinates."""
    location, size = (np.asarray(v, dtype=np.float64) for v in space)
    scale = 1.0 / np.where(size != 0.0, 2.0 * size, 1.0)
    return scale, -(location - size) * scale


#: A modifier's RNA properties that are not its settings (its name, the interface's state).
_NOT_SETTINGS = frozenset(
    {
        "rna_type",
        "name",
        "is_override_data",
        "persistent_uid",
        "is_active",
        "show_expanded",
        "use_pin_to_last",
    }
)


def _settings(modifier) -> tuple:
    """A modifier's type and RNA settings (pointers by name), for :func:`orco_key`."""
    values = []
    for prop in modifier.bl_rna.properties:
        if prop.identifier in _NOT_SETTINGS or prop.type == "COLLECTION":
            continue
        value = getattr(modifier, prop.identifier, None)
        values.append(
            (prop.identifier, getattr(value, "name", None) if prop.type == "POINTER" else repr(value))
        )
    return modifier.type, tuple(values)


#: :func:`one_pass`'s memo of :func:`orco_key` by original object (None outside one).
_keys: dict | None = None


@contextlib.contextmanager
def one_pass():
    """Within it (a context manager or a decorator: one collect of the draw items), each
    object's :func:`orco_key` reads and hashes its original positions once, not at each of the
    up to three checks of a batch's rebuild (8.8 ms each at 203 401 vertices). Nothing inside
    may edit an original mesh."""
    global _keys
    outer = _keys
    _keys = {} if outer is None else outer
    try:
        yield
    finally:
        _keys = outer


def orco_key(obj) -> tuple:
    """What :func:`evaluate_orco`'s result depends on: the original mesh's name, sizes and
    positions (a hash), and its building modifiers' settings; not the deformation. Read once
    per object inside :func:`one_pass`."""
    original = _original(obj)
    memo = _keys
    if memo is not None:
        found = memo.get(original.as_pointer())
        if found is not None:
            return found
    key = _orco_key(original)
    if memo is not None:
        memo[original.as_pointer()] = key
    return key


def _orco_key(original) -> tuple:
    mesh = original.data
    positions = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", positions)
    digest = hashlib.blake2b(positions.tobytes(), digest_size=16).hexdigest()
    building = tuple(_settings(m) for m in _used(original) if m.type not in DEFORMS)
    return original.name, mesh.name, len(mesh.vertices), len(mesh.loops), digest, building


def needs_evaluation(obj) -> bool:
    """Whether ``obj``'s Generated coordinates need :func:`evaluate_orco` and it has not run for
    what they depend on (never inside a draw: it makes and removes data-blocks)."""
    return kind(obj) == EVALUATED and ORCOS.get(orco_key(obj)) is None


def evaluate_orco(obj) -> np.ndarray:
    """(V, 3) the evaluated mesh's vertices without its Deform modifiers and shape keys: a copy
    of the original object and mesh in a temporary scene, the Deform modifiers and shape keys
    removed, evaluated there (the building modifiers keep the vertices' order). Cached
    (:data:`ORCOS`); main thread, outside drawing. Measured against Cycles' renders of Generated
    (2026-12-07: Subdivision Surface then Displace, shape keys then Subdivision Surface, Wave
    then Subdivision Surface): 6e-6 of the texture space; 2–23 ms for 98–2402 vertices. A
    failure is remembered as no positions (:func:`generated_space` then gives none) and
    raised."""
    key = orco_key(obj)
    found = ORCOS.get(key)
    if found is not None:
        return found
    original = _original(obj)
    scene = temp = mesh = None
    try:
        scene = bpy.data.scenes.new(_ORCO_PREFIX)
        temp = original.copy()
        mesh = original.data.copy()
        temp.name = mesh.name = _ORCO_PREFIX
        temp.data = mesh
        scene.collection.objects.link(temp)
        if mesh.shape_keys is not None:
            temp.shape_key_clear()
        for modifier in list(temp.modifiers):
            if modifier.type in DEFORMS:
                temp.modifiers.remove(modifier)
        layer = scene.view_layers[0]
        with bpy.context.temp_override(scene=scene, view_layer=layer):
            evaluated = temp.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
            positions = np.empty(3 * len(evaluated.vertices), dtype=np.float32)
            evaluated.vertices.foreach_get("co", positions)
    except Exception:
        ORCOS[key] = np.empty((0, 3))  # failed: no orco (the link is baked), not retried per frame
        raise
    finally:  # what was made, the object before its mesh
        for block, where in ((temp, bpy.data.objects), (mesh, bpy.data.meshes), (scene, bpy.data.scenes)):
            if block is not None:
                where.remove(block)
    found = positions.reshape(-1, 3).astype(np.float64)
    ORCOS[key] = found
    return found


def orco_vertices(obj, mesh) -> np.ndarray | None:
    """(V, 3) float32 where ``mesh``'s (``obj``'s evaluated mesh's) vertices were before Deform
    modifiers and shape keys moved them (:func:`generated_space`), or None (also where
    :func:`evaluate_orco` has not run: this never runs it, the draw calls it)."""
    if kind(obj) == EVALUATED:  # (one hash of the positions, not two)
        orco = ORCOS.get(orco_key(obj))
        orco = None if orco is None or len(orco) != len(mesh.vertices) else orco
    else:
        orco = generated_space(obj, mesh)[1]
    return None if orco is None else orco.astype(np.float32)


def orco_corners(obj, mesh) -> np.ndarray | None:
    """(N, 3) float32 :func:`orco_vertices` at ``mesh``'s corners, or None."""
    orco = orco_vertices(obj, mesh)
    return None if orco is None else np.take(orco, corner_vertices(mesh), axis=0)  # 3× faster than indexing


def generated_space(obj, mesh) -> tuple:
    """(texture space, orco) in which ``mesh`` (``obj``'s evaluated mesh) has its Generated
    coordinates (:class:`.linked_nodes._Context`): (:func:`texspace`, None) where they are its
    positions; (the original's, the vertices' positions before the deformation (V, 3)) where
    Deform modifiers (:data:`DEFORMS`) and shape keys moved them: the original vertices where
    nothing else ran, else :func:`evaluate_orco` (which this runs: not inside a draw); (None,
    None) otherwise (a modifier of neither kind) or where the counts disagree."""
    how = kind(obj)
    if how == POSITIONS:
        return original_texspace(obj), None
    if how == ORIGINAL:
        original = _original(obj)
        orco = np.empty(3 * len(original.data.vertices), dtype=np.float32)
        original.data.vertices.foreach_get("co", orco)  # the basis shape: what Generated reads
        orco = orco.reshape(-1, 3).astype(np.float64)
    elif how == EVALUATED:
        orco = evaluate_orco(obj)
    else:
        return None, None
    if len(orco) != len(mesh.vertices):
        return None, None
    return original_texspace(obj), orco


def carry_generated(obj, copy, material) -> list:
    """Give ``copy`` (a mesh made from ``obj``'s evaluated one, for a Cycles bake of
    ``material``) the Generated coordinates Blender's renders read: the original's texture space,
    not the copy's own bounds, and where a deformation moved the vertices their positions before
    it, as the attribute :data:`ORCO_ATTRIBUTE` that ``material`` is made to read. Returns the
    node groups copied for it (:func:`read_orco_attribute`), for the caller to remove with the
    material."""
    space, orco = generated_space(obj, copy)
    space = space or original_texspace(obj)
    if space is not None:
        copy.use_auto_texspace = False
        copy.texspace_location, copy.texspace_size = space
    if orco is None:
        return []
    scale, offset = texspace_affine(space)
    mapped = orco * scale + offset
    attribute = copy.attributes.new(ORCO_ATTRIBUTE, "FLOAT_VECTOR", "POINT")
    attribute.data.foreach_set("vector", mapped.astype(np.float32).ravel())
    return read_orco_attribute(material.node_tree, ORCO_ATTRIBUTE)


#: The name prefix of the node groups :func:`read_orco_attribute` copies.
ORCO_GROUP_PREFIX = ".thinfilm_sh_orco "


def read_orco_attribute(tree, orco_name: str) -> list:
    """Make the nodes of ``tree`` that read Generated coordinates (a Texture Coordinate's
    output, a texture's unlinked Vector) read the corner bake copy's attribute ``orco_name``
    instead. A node group that reads them, at any depth, is replaced in ``tree`` by a copy
    rewired the same way (the group itself may be shared with other materials); returns the
    copies (named :data:`ORCO_GROUP_PREFIX` + the group's name), for the caller to remove."""
    made: list = []
    _rewire(tree, orco_name, made, {})
    return made


def _reads_generated(tree) -> bool:
    """Whether a node tree reads Generated coordinates itself or in a group it uses."""
    for node in tree.nodes:
        group = node.node_tree if node.bl_idname == "ShaderNodeGroup" else None
        if _generated_input(node) is not None or (group is not None and _reads_generated(group)):
            return True
    return False


def _generated_input(node):
    """The sockets a node reads Generated coordinates through: a Texture Coordinate's linked
    Generated output's links, a texture's unlinked Vector input; else None."""
    if node.bl_idname == "ShaderNodeTexCoord" and node.outputs["Generated"].is_linked:
        return [link.to_socket for link in node.outputs["Generated"].links]
    if node.bl_idname in _GENERATED_BY_DEFAULT and not node.inputs["Vector"].is_linked:
        return [node.inputs["Vector"]]
    return None


def _rewire(tree, orco_name: str, made: list, copies: dict) -> None:
    """:func:`read_orco_attribute` in ``tree``; ``copies``: the groups copied so far by name."""
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type, attribute.attribute_name = "GEOMETRY", orco_name
    vector = attribute.outputs["Vector"]
    for node in list(tree.nodes):
        sockets = _generated_input(node)
        if sockets is not None:
            for socket in sockets:
                tree.links.new(vector, socket)
        elif node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None:
            group = node.node_tree
            if group.name not in copies and _reads_generated(group):
                copies[group.name] = group.copy()
                copies[group.name].name = ORCO_GROUP_PREFIX + group.name
                made.append(copies[group.name])
                _rewire(copies[group.name], orco_name, made, copies)
            node.node_tree = copies.get(group.name, group)
