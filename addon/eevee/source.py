"""What a material's EEVEE film is made from: its table's description, its wall, its inputs.

:func:`spec` reads a Blender material (main thread, no bake) and returns a :class:`Spec`:

- ``film``: the description (:func:`..description.description`) the image is baked from: the
  film alone (no diffuse base), SH order 0 (the albedo is the l = 0 entry, which does not depend
  on the order: a cheap bake), and, when the Principled BSDF's *Thin Film Thickness* is
  keyframed, a thickness axis over the values its curve takes in the scene's frame range, so an
  animation (F12 on every frame, ``blender -b -a``) reads the right row natively;
- ``base``: the same film with its diffuse base, and the base colour, when it has one;
- ``wall``: a transparent film's wall (:func:`..transparency.wall`) and how EEVEE shows it;
- ``feeds``: what drives the group's inputs: the Principled socket a link or an F-curve copies,
  or a constant;
- ``world``: the analysed World (the overlay's, ``scene_draw.world_lighting``) whose lobe-light
  directions the film's colour is read at (:func:`precompute.bakes.eevee_table.dominant_directions`);
- ``lights``: the scene's light objects as the film sees them (:mod:`.lights`), folded into
  those directions.

``Spec.key`` names everything the image depends on: an image holding that key is up to date.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

from ...precompute.bakes import eevee_table
from ...precompute.materials.material import Material
from ...precompute.shading import transmit
from ..materials import description, principled, transparency
from ..thickness import linked
from . import lights as light_objects
from .nodes import Structure

__all__ = ["Feed", "Spec", "WorldRef", "animated_range", "spec"]

#: The Principled inputs the group copies, by group input.
PRINCIPLED_FEEDS = {
    "Thickness": principled.SOCKET_THICKNESS,
    "Roughness": principled.SOCKET_ROUGHNESS,
    "Normal": "Normal",
    "Base Color": principled.SOCKET_BASE_COLOR,
}


@dataclass(frozen=True)
class Feed:
    """What drives one group input: ``socket`` (a Principled input: its link is followed, else a
    driver copies its value, so keyframes play) or ``value`` (a constant) or ``build`` (the
    extension's own thickness source, built as nodes inside the group)."""

    socket: str | None = None
    value: object = None
    build: bool = False


@dataclass(frozen=True)
class WorldRef:
    """The World the dominant-direction image is made from: the lighting's ``key`` (content and
    parameters), its analysed ``environment`` (:class:`precompute.world.environment.Environment`, the
    content's frame), ``matrix`` Q (image direction = Q · world direction, None: identity) and
    ``scale``, the World's radiance over the content's (its Strength), which weighs it against
    the light objects."""

    key: str
    environment: object
    matrix: object = None
    scale: float = 1.0


@dataclass(frozen=True)
class Spec:
    """A material's EEVEE film (see the module docstring)."""

    film: Material
    base: Material | None
    base_color: tuple | None
    wall: tuple | None
    structure: Structure
    feeds: dict
    ior: float
    principled_node: str | None
    world: WorldRef | None = None
    lights: object = None
    lights_key: str = "no lights"

    @functools.cached_property
    def key(self) -> str:
        """Everything the images depend on (computed once: a JSON hash of the descriptions)."""
        parts = [description.description_key(self.film), str(eevee_table.FORMAT_VERSION), repr(self.wall)]
        if self.base is not None:
            parts += [description.description_key(self.base), repr(self.base_color)]
        if self.world is not None:
            parts.append(self.world.key)
        if self.lights is not None:
            parts.append(self.lights_key)
        return "|".join(parts)

    @functools.cached_property
    def light_key(self) -> str | None:
        """What the dominant-direction image depends on: the World, the light objects and the
        film's roughness (an edit of the film alone does not rewrite it). None without either."""
        if self.world is None and self.lights is None:
            return None
        world = "no World" if self.world is None else self.world.key
        return f"{world}|{self.lights_key}|{float(self.film.roughness)!r}|{eevee_table.FORMAT_VERSION}"


def _fcurve_values(tree, path: str, scene) -> list[float] | None:
    """The values the F-curve animating ``path`` in ``tree`` takes at each frame of the scene's
    range (None when nothing animates it)."""
    animation = getattr(tree, "animation_data", None)
    action = getattr(animation, "action", None) if animation is not None else None
    if action is None:
        return None
    from bpy_extras import anim_utils  # Blender's own helper for layered actions (5.x)

    bag = anim_utils.action_get_channelbag_for_slot(action, animation.action_slot)
    if bag is None:
        return None
    curve = next((c for c in bag.fcurves if c.data_path == path), None)
    if curve is None:
        return None
    start, end = int(scene.frame_start), int(scene.frame_end)
    return [float(curve.evaluate(f)) for f in range(start, max(start, end) + 1)]


def animated_range(material, scene) -> tuple[float, float] | None:
    """(min, max) nm of a keyframed, unlinked Principled *Thin Film Thickness* over the scene's
    frame range, or None when it is not animated or does not change."""
    node = principled.principled_node(material)
    if node is None or principled.SOCKET_THICKNESS not in node.inputs:
        return None
    socket = node.inputs[principled.SOCKET_THICKNESS]
    if socket.is_linked:
        return None
    values = _fcurve_values(material.node_tree, socket.path_from_id() + ".default_value", scene)
    if not values:
        return None
    lo, hi = max(0.0, min(values)), max(values)
    return (lo, hi) if hi - lo > 1e-3 and math.isfinite(hi) else None


def _glossy_only(desc: Material) -> Material:
    """``desc`` as the image's table: no diffuse base, SH order 0 (the l = 0 entry only)."""
    quality = dataclasses.replace(desc.quality, sh_order=0)
    return desc.with_(base_color=None, quality=quality)


def _wall(material, desc) -> tuple[tuple | None, str, float]:
    """(wall, structure's wall kind, refraction's relative index)."""
    found = transparency.wall(material, desc)
    if found is None:
        return None, "", 1.0
    mode, eta = found[:2]
    wall = (int(mode), float(eta), *(float(c) for c in found[2:5]))  # a Principled wall's tint with it
    if int(mode) == transmit.WALL_SOLID:
        return wall, "refraction", float(eta)
    return wall, "transparent", 1.0


def _principled_feeds(material) -> tuple[dict, bool, str | None]:
    node = principled.principled_node(material)
    if node is None:
        return {}, False, None
    feeds = {name: Feed(socket=socket) for name, socket in PRINCIPLED_FEEDS.items() if socket in node.inputs}
    normal = node.inputs.get("Normal")
    return feeds, bool(normal is not None and normal.is_linked), node.name


def _props_feeds(props, desc: Material) -> dict:
    thickness = desc.layers[0].thickness_nm if desc.layers else 0.0
    varies = desc.thickness_range_nm is not None and bool(desc.layers)
    return {
        "Thickness": Feed(build=True) if varies else Feed(value=float(thickness)),
        "Roughness": Feed(value=float(desc.roughness)),
        "Base Color": Feed(value=tuple(desc.base_color or (0.0, 0.0, 0.0))),
    }


def may_show_film(material) -> bool:
    """Whether ``material`` may have a film for EEVEE, read cheaply (no bake, no linked
    thickness evaluated): the extension's film enabled, a Principled BSDF's Thin Film Thickness
    linked or above 0. False means :func:`spec` is None: the World need not be read for it."""
    props = getattr(material, "thinfilm_sh", None)
    if props is not None and props.enabled:
        return True
    node = principled.principled_node(material)
    if node is None or principled.SOCKET_THICKNESS not in node.inputs:
        return False
    socket = node.inputs[principled.SOCKET_THICKNESS]
    return socket.is_linked or socket.default_value > 0.0


def spec(material, scene=None, world: WorldRef | None = None, lights=None) -> Spec | None:
    """The :class:`Spec` of ``material``, or None when it shows no film. Raises ValueError for a
    film that cannot be evaluated (the panel shows why) and :class:`..linked.Pending` while a
    linked thickness waits for its Cycles bake (inside ``linked.deferring``): nothing is known
    then, and the caller leaves the material as it is. ``world``: the World whose lobe light
    directions the specular band is read at (None: at the view angle); ``lights``: the light
    objects as the film sees them (:class:`precompute.bakes.eevee_table.LobeLights`, None: none)."""
    props = getattr(material, "thinfilm_sh", None)
    own = props is not None and props.enabled
    if not own and principled.linked_thickness_socket(material) is not None and linked.baking():
        desc = description.description(material)
        if desc is None:
            raise linked.Pending(f"material {material.name!r}: its linked thickness is being baked")
    else:
        desc = description.description(material)
    if desc is None:
        return None
    film = _glossy_only(desc)
    if not own and scene is not None:
        found = animated_range(material, scene)
        if found is not None:
            film = film.with_(thickness_range_nm=found)
    wall, kind, ior = _wall(material, desc)
    if own:
        feeds, normal, node_name = _props_feeds(props, desc), False, None
    else:
        feeds, normal, node_name = _principled_feeds(material)
    base = (
        desc.with_(quality=film.quality, thickness_range_nm=film.thickness_range_nm)
        if desc.base_color
        else None
    )
    bands = (
        ("specular", "inverse")
        + (("diffuse",) if base is not None else ())
        + (("transmission",) if wall else ())
    )
    return Spec(
        film=film,
        base=base,
        base_color=tuple(desc.base_color) if desc.base_color else None,
        wall=wall,
        structure=Structure(bands=bands, normal=normal, wall=kind),
        feeds=feeds,
        ior=ior,
        principled_node=node_name,
        # the World weighs against the light objects even where it is not read at θ' itself
        world=world if eevee_table.dominant_weight(film.roughness) > 0.0 or lights is not None else None,
        lights=lights,
        lights_key=light_objects.key(lights),
    )
