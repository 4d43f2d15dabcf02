"""Putting a film's EEVEE path into a material, keeping its inputs fed, and taking it out again.

- :func:`apply` (main thread): the group node and EEVEE output (:func:`.nodes.ensure`), the
  image's pixels (:func:`.image.write`), the group's constants, its inputs (:func:`feed`) and,
  for a transparent film, the material's EEVEE settings (:func:`_settings`), the earlier values
  kept on the output node to be restored.
- :func:`feed`: each group input follows the material: a link into the Principled input is
  linked into the group too (textures, attributes: EEVEE evaluates them), an unlinked one is
  copied, value and F-curve (its keyframes play in F12, Render Animation and ``blender -b -a``
  with nothing of ours running), a constant is set.
- :func:`remove`: deletes the group node, the EEVEE output, their F-curves, the group and the
  image (when nothing else uses them), and restores the settings: the material is as before.

Linked (library) materials are never written: their group and image come from the library.
"""

from __future__ import annotations

import json

import bpy

from ...precompute.bakes import eevee_table
from ..materials import transparency
from ..thickness import thickness_nodes
from . import image as film_image_store
from . import nodes
from .source import Spec

__all__ = ["apply", "feed", "is_read_only", "remove", "restore_settings"]

#: The material's EEVEE settings a transparent film changes, by wall kind.
WALL_SETTINGS = {
    "transparent": {"surface_render_method": "BLENDED", "use_backface_culling": False},
    "refraction": {
        "surface_render_method": "DITHERED",
        "use_raytrace_refraction": True,
        "thickness_mode": "SPHERE",
    },
}
#: Custom property on the EEVEE output: the settings' values before the film changed them (JSON).
RESTORE = "thinfilm_eevee_restore"
#: Custom property on the group: the key of the thickness source built inside it.
SOURCE_KEY = "thinfilm_eevee_source"


def is_read_only(material) -> bool:
    """A linked material or a library override: the extension writes nothing into it."""
    return material.library is not None or material.override_library is not None


def _input_path(name: str) -> str:
    return f'nodes["{nodes.NODE_GROUP}"].inputs["{name}"].default_value'


def _channelbag(tree, create: bool = False):
    """The F-curves of the node tree's action (Blender 5's layered actions), or None."""
    from bpy_extras import anim_utils  # Blender's own helper for layered actions

    animation = tree.animation_data
    if animation is None or animation.action is None:
        return None
    if create:
        return anim_utils.action_ensure_channelbag_for_slot(animation.action, animation.action_slot)
    return anim_utils.action_get_channelbag_for_slot(animation.action, animation.action_slot)


def _keys(curve) -> list:
    return [
        (tuple(k.co), tuple(k.handle_left), tuple(k.handle_right), k.interpolation, k.easing)
        for k in curve.keyframe_points
    ] + [curve.extrapolation]


def _drop_curve(tree, name: str) -> None:
    bag = _channelbag(tree)
    found = bag.fcurves.find(_input_path(name)) if bag is not None else None
    if found is not None:
        bag.fcurves.remove(found)


def _mirror(tree, name: str, socket) -> None:
    """The group input ``name`` keyframed as the Principled ``socket`` is: its F-curve copied (a
    copy, not a driver: a driver reading the same node tree is a dependency cycle), so the film's
    animation plays in EEVEE with nothing of ours running. No curve when the socket has none."""
    bag = _channelbag(tree)
    source = bag.fcurves.find(socket.path_from_id() + ".default_value") if bag is not None else None
    if source is None:
        _drop_curve(tree, name)
        return
    target = bag.fcurves.find(_input_path(name))
    if target is not None and _keys(target) == _keys(source):
        return
    if target is not None:
        bag.fcurves.remove(target)
    target = bag.fcurves.new(_input_path(name))
    target.keyframe_points.add(len(source.keyframe_points))
    for made, key in zip(target.keyframe_points, source.keyframe_points, strict=True):
        made.co, made.handle_left, made.handle_right = key.co, key.handle_left, key.handle_right
        made.handle_left_type, made.handle_right_type = key.handle_left_type, key.handle_right_type
        made.interpolation, made.easing = key.interpolation, key.easing
    target.extrapolation = source.extrapolation
    target.update()


def _unlink(tree, socket) -> None:
    for link in list(socket.links):
        tree.links.remove(link)


def _link(tree, source, socket) -> None:
    if socket.is_linked and socket.links[0].from_socket == source:
        return
    _unlink(tree, socket)
    tree.links.new(source, socket)


def _set(socket, value) -> None:
    value = tuple(value) if isinstance(value, (tuple, list)) else value
    if isinstance(value, tuple) and len(socket.default_value) == 4 and len(value) == 3:
        value = (*value, 1.0)
    socket.default_value = value


def feed(material, group_node, spec: Spec, props=None) -> None:
    """Make each of the group's inputs follow the material (see the module docstring)."""
    tree = material.node_tree
    principled = tree.nodes.get(spec.principled_node) if spec.principled_node else None
    for name, how in spec.feeds.items():
        target = group_node.inputs.get(name)
        if target is None:
            continue
        if how.socket is not None and principled is not None and how.socket in principled.inputs:
            source = principled.inputs[how.socket]
            if source.is_linked:
                _drop_curve(tree, name)
                _link(tree, source.links[0].from_socket, target)
                continue
            _unlink(tree, target)
            _set(target, source.default_value)
            _mirror(tree, name, source)
            continue
        _drop_curve(tree, name)
        _unlink(tree, target)
        if how.build:
            _build_source(group_node.node_tree, props, spec)
        elif how.value is not None:
            _set(target, how.value)


def _build_source(group, props, spec: Spec) -> None:
    """The extension's own thickness source (noise, attribute, image) as nodes inside the group,
    feeding its row lookup: rebuilt only when the source's settings change."""
    lo, hi = spec.film.thickness_range_nm
    key = json.dumps(
        [
            props.thickness_source,
            props.thickness_attribute,
            getattr(props.thickness_image, "name", None),
            props.thickness_uv_map,
            float(props.noise_scale),
            int(props.noise_seed),
            float(lo),
            float(hi),
        ]
    )
    if group.get(SOURCE_KEY) == key and any(n.name.startswith(thickness_nodes.PREFIX) for n in group.nodes):
        return
    row = group.nodes["row"]
    source = thickness_nodes.build(
        group, props, float(lo), float(hi), (row.location.x - 200.0, row.location.y - 300.0)
    )
    group.links.new(source, row.inputs["Value"])
    group[SOURCE_KEY] = key


def _wanted(spec: Spec, material) -> dict:
    """The material's EEVEE settings for ``spec``'s wall (:data:`WALL_SETTINGS`); a thin wall's
    *Transparent Shadows* off where Cycles stops shadow rays at it
    (:func:`..materials.transparency.cycles_stops_shadow_rays`: a rough thin wall of an index
    other than 1, glass without *Thin Wall*). Elsewhere the setting stays the material's own
    (Blender's default lets the wall's light through: its shadow pass reads the wall's fitted
    curve, :mod:`.nodes`)."""
    kind = spec.structure.wall
    wanted = dict(WALL_SETTINGS.get(kind, {}))
    if kind == "transparent" and spec.wall is not None:
        if transparency.cycles_stops_shadow_rays(material, spec.wall, spec.film.roughness):
            wanted["use_transparent_shadow"] = False
    return wanted


def _settings(material, output, wanted: dict) -> None:
    """Set the wall's EEVEE settings ``wanted``, keeping the earlier values on ``output`` once."""
    kept = json.loads(output.get(RESTORE, "{}"))
    for name in [n for n in kept if n not in wanted]:  # a setting this wall no longer needs
        setattr(material, name, kept.pop(name))
    for name, value in wanted.items():
        if not hasattr(material, name):
            continue
        if name not in kept:
            kept[name] = getattr(material, name)
        if getattr(material, name) != value:
            setattr(material, name, value)
    output[RESTORE] = json.dumps(kept)


def restore_settings(material) -> None:
    """Put back the EEVEE settings a transparent film changed (kept on its EEVEE output)."""
    _group, output = nodes.find(material.node_tree)
    if output is None:
        return
    for name, value in json.loads(output.get(RESTORE, "{}")).items():
        if hasattr(material, name) and getattr(material, name) != value:
            setattr(material, name, value)
    output[RESTORE] = "{}"


def apply(material, spec: Spec, made, light=None) -> None:
    """Write ``made`` (a :class:`precompute.bakes.eevee_table.FilmImage`) and ``light`` (the
    dominant-direction pixels, :func:`precompute.bakes.eevee_table.dominant_directions`, or None: read
    at the view angle) as ``material``'s EEVEE film for ``spec``, creating or repairing its
    nodes. Main thread."""
    tree = material.node_tree
    node = nodes.ensure(tree, material.name, spec.structure)
    group = node.node_tree
    if light is not None:
        height, width = light.shape[:2]
        directions = film_image_store.ensure_light(group, material.name, width, height)
        if film_image_store.stored_key(directions) != spec.light_key:  # the World or roughness changed
            film_image_store.write(directions, light, spec.light_key)
        nodes.set_light(group, directions)
    picture = film_image_store.ensure(group, material.name, made.width, made.height)
    film_image_store.write(picture, made.pixels, spec.key)
    nodes.set_image(group, picture)
    weight = eevee_table.dominant_weight(spec.film.roughness) if light is not None else 0.0
    nodes.set_constants(group, made, spec.ior, dominant=weight, lit=light is not None)
    feed(material, node, spec, getattr(material, "thinfilm_sh", None))
    _group, output = nodes.find(tree)
    _settings(material, output, _wanted(spec, material))


def remove(material) -> bool:
    """Take the film's EEVEE path out of ``material`` (see the module docstring); True if there
    was one."""
    tree = material.node_tree
    node, output = nodes.find(tree)
    if node is None and output is None:
        return False
    restore_settings(material)
    for name in (nodes.IN_THICKNESS, nodes.IN_ROUGHNESS, nodes.IN_NORMAL, nodes.IN_BASE):
        _drop_curve(tree, name)
    group = nodes.remove(tree)
    if group is not None and group.users == 0 and group.get(nodes.TAG):
        pictures = {n.image for n in group.nodes if getattr(n, "image", None) is not None}
        bpy.data.node_groups.remove(group)
        for picture in pictures:
            if picture.users == 0 and picture.get(film_image_store.OWNER) is not None:
                bpy.data.images.remove(picture)
    return True
