"""A Principled BSDF's *linked* Thin Film Thickness, evaluated over the surface.

In Blender and glTF files the film's thickness varies through a texture: *Thin Film Thickness*
linked to a Noise Texture or an image, through Map Range, Math, Mix or Separate Color (Blender's
glTF importer builds Image → Separate Color (G) → Mix(min, max)). This module turns such a link
into one thickness in nm per face corner of an evaluated mesh:

- **directly** (numpy, exact) for the graphs made of the nodes in :data:`.linked_nodes.DIRECT_NODES`: Value,
  Image Texture at a UV map (Non-Color or linear float pixels, Linear or Closest, Repeat or
  Extend), Map Range (linear), Math (the common operations), Mix (float, or colour Mix), Separate
  Color (RGB), Reroute;
- **by a Cycles bake** of everything else (a Noise Texture, a Color Ramp, …): a copy of the
  evaluated mesh and of the material whose output is an Emission of the linked value is baked
  (``bpy.ops.object.bake(type="EMIT")``) into a per-corner float colour attribute of the copy;
  both copies are removed afterwards, the user's data is never changed. Blender's bakes run on
  the main thread only, so in the viewport the draw callback never bakes: it queues the request
  (:func:`deferring`) and the viewport's timer runs :func:`run_pending`, then redraws.

Fields are cached (:data:`FIELDS`) by the object, its evaluated mesh's sizes and a geometry
epoch (bumped by :func:`mark_geometry` on depsgraph geometry updates) and
:func:`tree_key`, a hash of the linked graph's content (nodes, their settings, unlinked input
values, images' identity): editing a node re-evaluates (re-bakes), anything else is cached.
:func:`material_range` is the range the material's table covers: the evaluated values' min and
max over the scene's objects that use it, widened by their thickness maps where a texture gives
one (:func:`linked_map`, :mod:`.maps`: the thickness per pixel at the mesh's UVs, made apart from
the corners and never inside the draw).
"""

from __future__ import annotations

import contextlib
import hashlib
import math
from dataclasses import dataclass

import bpy
import numpy as np

from .. import caches, workers
from . import generated, linked_nodes, maps, noise_graph, thickness_nodes
from .thickness import corner_order, image_stamp

__all__ = [
    "FIELDS",
    "STATS",
    "Field",
    "Pending",
    "bake_map",
    "baking",
    "corner_parameters",
    "deferring",
    "evaluate",
    "field_key",
    "has_pending",
    "is_deferring",
    "linked_map",
    "mark_geometry",
    "material_range",
    "noise_graph_of",
    "pending_count",
    "run_pending",
    "tree_key",
]

#: Per-corner fields kept: (object, mesh sizes, geometry epoch, tree key) → Field.
FIELDS = caches.register("linked_thickness", caches.LRU(64), scope=caches.FILE)
#: Counters the tests read: direct evaluations, Cycles bakes per corner and into images run.
STATS = {"direct": 0, "bakes": 0, "image_bakes": 0}
#: Material name used for the temporary bake copies (removed after each bake).
_BAKE_PREFIX = ".thinfilm_sh_bake"

_geometry_epoch: dict[str, int] = {}
#: Cycles bakes queued inside the draw: (kind, object name) → a call that evaluates the wanted
#: field, run by the viewport's timer (:func:`run_pending`).
PENDING = workers.Deferred("linked thickness bakes")
_defer = False  # True inside the draw callback: bakes are queued, never run
_maps_later = False  # True while the timer runs queued bakes: their maps are queued in turn


class Pending(Exception):
    """The field needs a Cycles bake, queued for :func:`run_pending` (never run while drawing)."""


@dataclass(frozen=True)
class Field:
    """Thickness in nm per face corner of an evaluated mesh, and how it was obtained.

    ``how``: one line for the panel and ``plan`` (what drives the thickness and at what
    resolution it was sampled); ``baked``: whether Cycles computed it; ``lo``/``hi``: its finite
    values' min and max, worked out once (the draw reads them every frame).
    """

    values: np.ndarray
    how: str
    baked: bool = False
    lo: float = 0.0
    hi: float = 0.0


def _field(values, how: str, baked: bool = False) -> Field:
    values = np.asarray(values, dtype=np.float64)
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        raise ValueError("the linked thickness has no finite value")
    return Field(values, how, baked, float(finite.min()), float(finite.max()))


# ----------------------------------------------------------------------------------------------
# Keys
# ----------------------------------------------------------------------------------------------
def _value_repr(value) -> str:
    if hasattr(value, "__len__") and not isinstance(value, str):
        return repr(tuple(round(float(v), 7) for v in value))
    if isinstance(value, float):
        return repr(round(value, 7))
    return repr(value)


def _node_settings(node) -> list:
    """The node's own settings (enums, flags, numbers, image identity), not its location."""
    out = [node.bl_idname]
    for prop in node.bl_rna.properties:
        ident = prop.identifier
        if ident in {
            "location",
            "location_absolute",
            "width",
            "height",
            "dimensions",
            "select",
            "name",
            "label",
            "show_options",
            "show_preview",
            "hide",
            "mute",
            "color",
            "use_custom_color",
            "show_texture",
            "rna_type",
            "parent",
            "warning_propagation",
        }:
            continue
        if prop.type in {"BOOLEAN", "INT", "FLOAT", "STRING", "ENUM"} and not prop.is_hidden:
            with contextlib.suppress(AttributeError, TypeError):
                out.append((ident, _value_repr(getattr(node, ident))))
    image = getattr(node, "image", None)
    if image is not None:
        out.append(("image", image_stamp(image)))
    for sub in ("texture_mapping", "color_mapping"):  # Image and Noise textures' hidden mapping
        mapping = getattr(node, sub, None)
        if mapping is not None:
            out.append(
                (
                    sub,
                    [
                        _value_repr(getattr(mapping, p.identifier))
                        for p in mapping.bl_rna.properties
                        if p.type in {"FLOAT", "ENUM", "BOOLEAN"}
                    ],
                )
            )
    colour_ramp = getattr(node, "color_ramp", None)  # a Color Ramp's stops are not its settings
    if colour_ramp is not None:
        stops = [(_value_repr(e.position), _value_repr(e.color)) for e in colour_ramp.elements]
        modes = (colour_ramp.interpolation, colour_ramp.color_mode, colour_ramp.hue_interpolation)
        out.append(("color_ramp", modes, stops))
    return out


def tree_key(socket) -> str:
    """A hash of everything that decides the value reaching ``socket``: the upstream nodes'
    types and settings, their unlinked input values, the links between them, images' identity."""
    parts = []
    for node in linked_nodes.upstream(socket):
        parts.append((node.name, _node_settings(node)))
        for inp in node.inputs:
            if inp.is_linked:
                parts.append([(link.from_node.name, link.from_socket.identifier) for link in inp.links])
            elif hasattr(inp, "default_value") and inp.enabled:
                parts.append((inp.identifier, _value_repr(inp.default_value)))
        for out in node.outputs:  # a Value node keeps its value on its output
            if node.bl_idname == "ShaderNodeValue":
                parts.append(_value_repr(out.default_value))
    parts.append([(link.from_node.name, link.from_socket.identifier) for link in socket.links])
    return hashlib.sha1(repr(parts).encode()).hexdigest()[:16]


def mark_geometry(object_name: str) -> None:
    """An object's geometry changed: its fields are evaluated again (depsgraph handler)."""
    _geometry_epoch[object_name] = _geometry_epoch.get(object_name, 0) + 1


def field_key(obj_name: str, mesh, key: str) -> tuple:
    """What a field of an object's mesh is cached by: the object, its mesh's sizes, its geometry
    epoch (:func:`mark_geometry`) and ``key``, what the field is of."""
    return obj_name, len(mesh.vertices), len(mesh.loops), _geometry_epoch.get(obj_name, 0), key


def _direct(mesh, socket, texspace=None, orco=None) -> Field:
    """Evaluate the link into ``socket`` with numpy (raises Unsupported for other nodes)."""
    values, notes, corners = linked_nodes.link_values(mesh, socket, texspace, orco)
    STATS["direct"] += 1
    sources = ", ".join(dict.fromkeys(notes)) or "constant nodes"
    how = f"evaluated directly from {sources} at {corners} face corners"
    return _field(np.array(values, dtype=np.float64), how)


def _direct_map(mesh, socket) -> tuple[maps.ThicknessMap | None, str | None]:
    """(the link's map at its images' pixels, None) or (None, None) where it reads no image or
    images at two UV maps or modes (:func:`.linked_nodes.link_map`)."""
    grid = linked_nodes.link_map(mesh, socket)
    if grid is None:
        return None, None
    values, _, layer, repeat = grid
    uv = linked_nodes.corner_uv(mesh, mesh.uv_layers[layer])
    h, w = values.shape
    how = f"per pixel from a {w}×{h} map at UV map {layer!r}"
    return maps.make(values, uv, corner_order(mesh), layer, repeat, how), None


# ----------------------------------------------------------------------------------------------
# Cycles bake (any node graph)
# ----------------------------------------------------------------------------------------------
def _bake_material(bpy_material, node_name: str, socket_id: str):
    """A copy of the material whose output is an Emission of the value linked into the socket."""
    copy = bpy_material.copy()
    copy.name = _BAKE_PREFIX
    tree = copy.node_tree
    target = next(s for s in tree.nodes[node_name].inputs if s.identifier == socket_id)
    source = target.links[0].from_socket
    if source.type != "VALUE":  # converted as the thickness input converts it (its luminance)
        value = tree.nodes.new("ShaderNodeMath")
        value.operation = "ADD"
        value.inputs[1].default_value = 0.0
        tree.links.new(source, value.inputs[0])
        source = value.outputs[0]
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    tree.links.new(source, emission.inputs["Color"])
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    output.target = "ALL"
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeOutputMaterial":
            node.is_active_output = node == output
    return copy


def _bake(obj, bpy_material, socket) -> Field:
    """Bake the value linked into ``socket`` per face corner of ``obj``'s evaluated mesh."""
    values = _bake_emission(obj, _bake_material(bpy_material, socket.node.name, socket.identifier))
    how = f"baked with Cycles at {values.size} face corners (the mesh's resolution)"
    return _field(values, how, baked=True)


#: What a baked map's texels hold before the bake: texels no triangle (or margin) reaches keep it.
_UNBAKED = -1.0e30


def bake_map(obj, make_material, corner_values, size: int = maps.BAKE_SIZE):
    """(:class:`.maps.ThicknessMap` of the Emission of ``make_material()`` baked by Cycles into a
    float image of ``size``² at ``obj``'s active UV map, or None; why not, or None). None where
    the mesh has no UV map, or where the map disagrees with ``corner_values`` (the per-corner bake
    of the same graph) at the corners' UVs: overlapping UV islands, UVs outside [0, 1]."""
    mesh = _mesh_of(obj.name)
    layer = mesh.uv_layers.active
    if layer is None:
        return None, "no UV map: per corner"
    image = bpy.data.images.new(_BAKE_PREFIX, size, size, float_buffer=True)
    try:
        image.colorspace_settings.name = "Non-Color"
        image.pixels.foreach_set(np.full(size * size * 4, _UNBAKED, dtype=np.float32))
        _bake_emission(obj, make_material(), image, clear=False)
        pixels = np.empty(size * size * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    values = pixels.reshape(size, size, 4)[..., 0].astype(np.float64)
    values[values <= 0.5 * _UNBAKED] = np.nan
    uv = linked_nodes.corner_uv(mesh, layer)
    how = f"per pixel from a {size}² Cycles bake at UV map {layer.name!r}"
    try:
        found = maps.make(values, uv, corner_order(mesh), layer.name, False, how)
    except ValueError:
        return None, f"the bake at UV map {layer.name!r} wrote nothing: per corner"
    if not maps.agrees(found, corner_values):
        return None, f"UV map {layer.name!r} overlaps itself or leaves [0, 1]: per corner"
    return found, None


def _bake_emission(obj, material, image=None, clear: bool = True) -> np.ndarray | None:
    """Bake ``material``'s Emission colour (red) per face corner of a copy of ``obj``'s evaluated
    mesh, or into ``image`` at its active UV map (returns None; ``clear``: cleared first, else
    the texels no triangle reaches keep their values); the copy, a temporary scene and
    ``material`` (with the node groups copied for it) are removed afterwards."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    obj_eval = obj.evaluated_get(depsgraph)
    mesh = bpy.data.meshes.new_from_object(obj_eval, preserve_all_data_layers=True, depsgraph=depsgraph)
    scene = bpy.data.scenes.new(_BAKE_PREFIX)
    temp = bpy.data.objects.new(_BAKE_PREFIX, mesh)
    groups = []  # the node groups copied to read the positions before a deformation
    try:
        groups = generated.carry_generated(obj, mesh, material)
        mesh.materials.clear()
        mesh.materials.append(material)
        indices = np.zeros(len(mesh.polygons), dtype=np.int32)
        mesh.polygons.foreach_set("material_index", indices)
        temp.matrix_world = obj.matrix_world
        scene.collection.objects.link(temp)
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = 1  # an Emission of a value: one sample is exact
        attribute = mesh.color_attributes.new(_BAKE_PREFIX, "FLOAT_COLOR", "CORNER")
        mesh.color_attributes.active_color = attribute
        layer = scene.view_layers[0]
        with bpy.context.temp_override(
            scene=scene,
            view_layer=layer,
            active_object=temp,
            object=temp,
            selected_objects=[temp],
            selected_editable_objects=[temp],
        ):
            temp.select_set(True, view_layer=layer)
            layer.objects.active = temp
            if image is not None:  # the bake writes into the active Image Texture node's image
                target = material.node_tree.nodes.new("ShaderNodeTexImage")
                target.image = image
                material.node_tree.nodes.active = target
            result = bpy.ops.object.bake(
                type="EMIT",
                target="IMAGE_TEXTURES" if image is not None else "VERTEX_COLORS",
                use_clear=clear,
            )
        if "FINISHED" not in result:
            raise RuntimeError(f"Cycles bake of the thickness returned {result}")
        values = None
        if image is None:
            colours = np.empty(4 * len(attribute.data), dtype=np.float32)
            attribute.data.foreach_get("color", colours)
            values = colours.reshape(-1, 4)[:, 0].astype(np.float64)
    finally:
        bpy.data.objects.remove(temp)
        bpy.data.meshes.remove(mesh)
        bpy.data.materials.remove(material)
        for group in groups:
            bpy.data.node_groups.remove(group)
        bpy.data.scenes.remove(scene)
    STATS["bakes" if image is None else "image_bakes"] += 1
    return values


def _batch_map(found_map: maps.ThicknessMap | None, thickness_range):
    """(corner UVs, parameter map, repeat) of a map for the batch, or None."""
    if found_map is None:
        return None
    return found_map.uv, maps.parameters(found_map, thickness_range), found_map.repeat


def bake_thickness_image(obj, bpy_material, thickness_range, size: int = 512):
    """A Non-Color image (``size``²) of the material's varying thickness at ``obj``'s UVs, mapped
    from ``thickness_range`` (nm) to [0, 1] in every channel (glTF reads G): the extension's
    source (:func:`.thickness_nodes.build`) or the link into Thin Film Thickness, baked by Cycles.
    Returns None when the thickness does not vary by either."""
    props = getattr(bpy_material, "thinfilm_sh", None)
    lo, hi = (float(v) for v in thickness_range)
    if props is not None and props.enabled and props.vary_thickness:
        material = bpy.data.materials.new(_BAKE_PREFIX)
        tree = material.node_tree
        tree.nodes.clear()
        value = thickness_nodes.build(tree, props, lo, hi)
        tree.nodes.new("ShaderNodeOutputMaterial")
    else:
        principled = next(
            (n for n in bpy_material.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"), None
        )
        if principled is None or not principled.inputs["Thin Film Thickness"].is_linked:
            return None
        material = bpy_material.copy()
        tree = material.node_tree
        value = tree.nodes[principled.name].inputs["Thin Film Thickness"].links[0].from_socket
    ranged = tree.nodes.new("ShaderNodeMapRange")
    ranged.inputs["From Min"].default_value, ranged.inputs["From Max"].default_value = lo, hi
    tree.links.new(value, ranged.inputs["Value"])
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(ranged.outputs["Result"], emission.inputs["Color"])
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeOutputMaterial":
            node.is_active_output = node == output
    image = bpy.data.images.new(f"{bpy_material.name} thickness", size, size)
    image.colorspace_settings.name = "Non-Color"
    _bake_emission(obj, material, image)
    return image


def _mesh_of(name: str):
    return bpy.data.objects[name].evaluated_get(bpy.context.evaluated_depsgraph_get()).data


# ----------------------------------------------------------------------------------------------
# Public
# ----------------------------------------------------------------------------------------------
@generated.one_pass()  # its two orco checks and generated_space: one hash
def evaluate(obj, mesh, bpy_material, socket, key: str | None = None) -> Field:
    """The thickness (nm) per face corner of ``mesh`` (``obj``'s evaluated mesh) that the link
    into the material's Thin Film Thickness gives: cached; direct where exact, else baked.

    Raises :class:`Pending` inside :func:`deferring` when a bake is needed (it is queued), and
    ValueError when the link cannot be evaluated at all (the message says why).
    """
    key = key if key is not None else tree_key(socket)
    name = obj.original.name if hasattr(obj, "original") else obj.name
    if linked_nodes.positional(socket) and generated.needs_evaluation(obj):
        if _defer:  # it makes data-blocks: never inside the draw (the batch reads it too)
            PENDING.defer(("orco", name), lambda: generated.evaluate_orco(bpy.data.objects[name]))
            raise Pending("the positions before the deformation are being computed")
        generated.evaluate_orco(obj)
    cache_key = field_key(name, mesh, key)
    found = FIELDS.get(cache_key)
    if found is not None:
        return found
    if _defer and len(mesh.vertices) > linked_nodes.INLINE_VERTICES and linked_nodes.positional(socket):
        node_name, socket_id = socket.node.name, socket.identifier  # a large mesh's noise: ≥ 30 ms
        PENDING.defer(("linked", name), lambda: _run_linked(name, bpy_material, node_name, socket_id))
        raise Pending(f"the thickness at {len(mesh.vertices)} vertices is being computed")
    try:
        found = _direct(mesh, socket, *generated.generated_space(obj, mesh))
    except linked_nodes.Unsupported as why:
        found = _bake_or_queue(name, mesh, bpy_material, socket, why)
    FIELDS[cache_key] = found
    return found


def _bake_or_queue(name: str, mesh, bpy_material, socket, why) -> Field:
    """Bake the field with Cycles, or queue the bake (:class:`Pending`) inside :func:`deferring`."""
    if _defer:
        node_name, socket_id = socket.node.name, socket.identifier
        PENDING.defer(("linked", name), lambda: _run_linked(name, bpy_material, node_name, socket_id))
        raise Pending(f"thickness from {why} is being baked with Cycles")
    try:
        found = _bake(bpy.data.objects[name], bpy_material, socket)
    except RuntimeError as exc:
        raise ValueError(f"the linked thickness could not be baked: {exc}") from None
    if found.values.size != len(mesh.loops):
        raise ValueError("the baked thickness does not match the mesh's corners")
    return found


def _users(bpy_material) -> list:
    scene = bpy.context.scene
    return [
        obj
        for obj in scene.objects
        if obj.type == "MESH" and any(slot.material == bpy_material for slot in obj.material_slots)
    ]


def material_range(bpy_material, socket) -> tuple[float, float, str] | None:
    """(min nm, max nm, how) of the value linked into ``socket`` (the material's Thin Film
    Thickness) over the scene's objects using the material, or None when no object uses it.

    Raises :class:`Pending` (a bake is queued, inside :func:`deferring`) or ValueError.
    """
    key = tree_key(socket)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    lo, hi, hows = math.inf, -math.inf, []
    for obj in _users(bpy_material):
        graph = noise_graph_of(obj, socket)
        if graph is not None:  # per pixel: the thickness over the noise's whole range, which
            lo, hi = min(lo, graph.nm_range()[0]), max(hi, graph.nm_range()[1])  # holds the corners
            through = " through a Color Ramp" if graph.noise.ramp else ""
            hows.append(f"{obj.name}: per pixel (the Noise Texture{through} computed in the shader)")
            continue
        mesh = obj.evaluated_get(depsgraph).data
        field = evaluate(obj, mesh, bpy_material, socket, key)
        lo, hi = min(lo, field.lo), max(hi, field.hi)
        found_map, why, _ = linked_map(obj, mesh, bpy_material, socket, key)
        if found_map is not None:  # a texture's peaks between the corners
            lo, hi = min(lo, found_map.lo), max(hi, found_map.hi)
        extra = found_map.how if found_map is not None else why
        hows.append(f"{obj.name}: {field.how}" + (f"; {extra}" if extra else ""))
    if not hows:
        return None
    return lo, hi, "; ".join(hows)


def linked_map(obj, mesh, bpy_material, socket, key: str | None = None):
    """(map or None, why not or None, being waited for) of the link into ``socket`` over
    ``obj``'s evaluated ``mesh`` (:func:`.maps.field_map`): at the images' pixels where the link reads
    images, else a Cycles bake at the UVs where the corners are baked or read the surface's
    positions (a Noise Texture: :func:`.linked_nodes.positional`)."""
    key = key if key is not None else tree_key(socket)
    name = obj.original.name if hasattr(obj, "original") else obj.name
    found = evaluate(obj, mesh, bpy_material, socket, key)
    node_name, socket_id = socket.node.name, socket.identifier

    def make():
        node = bpy_material.node_tree.nodes[node_name]
        live = next(s for s in node.inputs if s.identifier == socket_id)
        if not found.baked and not linked_nodes.positional(live):
            return _direct_map(_mesh_of(name), live)
        return bake_map(
            bpy.data.objects[name], lambda: _bake_material(bpy_material, node_name, socket_id), found.values
        )

    job = (name, bpy_material.name, "linked")
    return maps.field_map(field_key(name, mesh, key), job, make, defer=_defer or _maps_later)


def noise_graph_of(obj, socket):
    """The link as a Noise Texture the shader computes per pixel (:mod:`.noise_graph`), or None;
    at Generated coordinates after Deform modifiers or shape keys, from where the vertices were
    before them (the spec's ``orco``: the batch carries those positions)."""
    how = generated.kind(obj)
    space = generated.original_texspace(obj) if how is not None else None
    return noise_graph.recognise(socket, space, how in (generated.ORIGINAL, generated.EVALUATED))


def corner_parameters(obj_eval, mesh, bpy_material, socket, thickness_range):
    """(per-corner parameter in [0, 1] along the table's range, non-finite count, the map for
    the batch: (corner UVs, parameter map, repeat) or None, whether a map is awaited, the
    Noise Texture the shader computes per pixel instead of a map, or None). A Noise Texture's
    corners that are being computed (:class:`Pending`, a large mesh) are the middle of the range
    meanwhile: the shader draws the noise per pixel without them."""
    graph = noise_graph_of(obj_eval, socket)
    try:
        field = evaluate(obj_eval, mesh, bpy_material, socket)
    except Pending:
        if graph is None or (graph.noise.orco and generated.needs_evaluation(obj_eval)):
            raise  # (the per-pixel noise would need the positions being computed)
        middle = np.full(len(mesh.loops), 0.5)
        return middle, 0, None, True, graph.spec(thickness_range)
    lo, hi = thickness_range
    values = field.values
    finite = np.isfinite(values)
    param = np.where(finite, (np.where(finite, values, lo) - lo) / max(hi - lo, 1e-9), 0.5)
    nan_count = int(values.size - np.count_nonzero(finite))
    if graph is not None:
        return np.clip(param, 0.0, 1.0), nan_count, None, False, graph.spec(thickness_range)
    found_map, _, waiting = linked_map(obj_eval, mesh, bpy_material, socket)
    return np.clip(param, 0.0, 1.0), nan_count, _batch_map(found_map, thickness_range), waiting, None


@contextlib.contextmanager
def deferring():
    """Inside: a field that needs a bake raises :class:`Pending` and is queued (the draw)."""
    global _defer
    previous, _defer = _defer, True
    try:
        yield
    finally:
        _defer = previous


def is_deferring() -> bool:
    """Whether work that must not run in the draw is queued instead (inside :func:`deferring`)."""
    return _defer


def has_pending() -> bool:
    """Whether bakes or maps wait for :func:`run_pending`."""
    return bool(PENDING) or bool(maps.PENDING)


def baking() -> bool:
    """Whether Cycles bakes of the corners wait (the film is not drawn yet; maps aside)."""
    return bool(PENDING)


def pending_count() -> int:
    """Bakes and maps queued: the timer redraws when it falls."""
    return len(PENDING) + len(maps.PENDING)


def _run_linked(name: str, bpy_material, node_name: str, socket_id: str) -> None:
    node = bpy_material.node_tree.nodes[node_name]
    socket = next(s for s in node.inputs if s.identifier == socket_id)
    evaluate(bpy.data.objects[name], _mesh_of(name), bpy_material, socket)


def run_pending() -> list[str]:
    """Run the queued bakes (main thread, outside drawing), and the queued maps once settled
    (:data:`.maps.SETTLE_S`; else they stay queued: :func:`has_pending`); returns the errors met."""
    global _maps_later
    errors = (ValueError, ReferenceError, KeyError, StopIteration, RuntimeError)
    _maps_later = True  # a bake's map waits for its own turn (the edits settled)
    try:
        failed = PENDING.run(errors)
    finally:
        _maps_later = False
    failed += maps.run_settled(errors)
    return [f"{key[1]}: {exc}" for key, exc in failed]
