"""Blender's light objects → :class:`precompute.shading.lights.Lights`, read every frame.

Read from the evaluated depsgraph on every draw (a few attribute reads per light): moving or
editing a light changes only the lights' uniform buffer, never a bake or the World's lighting.
What a film sees of a light: its type, power (times 2^exposure), colour (times its temperature
colour when used), size, cone, spread and *Specular* factor (the film is a specular layer);
a light whose object has *Glossy* ray visibility off does not reach it. Light linking: a light
with a receiver collection lights only the objects it includes (:func:`receives`).
No shadows from other objects.
"""

from __future__ import annotations

import numpy as np

from ...precompute.shading import lights as light_shading
from ..gpu.layout import MAX_LIGHTS


def _colour(light) -> np.ndarray:
    rgb = np.array(light.color[:3], dtype=np.float64)
    if getattr(light, "use_temperature", False):
        rgb = rgb * np.array(light.temperature_color[:3], dtype=np.float64)
    return rgb


def light_row(obj, matrix_world, glossy: bool = True) -> dict | None:
    """:func:`precompute.shading.lights.light_from_blender` of a light object (evaluated), or
    None when it cannot reach a film (glossy rays off, Specular 0, no power, an unknown type).
    ``glossy`` False: the light as diffuse surfaces see it (its glossy visibility and Specular
    factor not applied), as the glass's caustics light the ground."""
    light = obj.data
    if light is None or light.type not in light_shading.KINDS:
        return None
    if glossy and not getattr(obj, "visible_glossy", True):
        return None
    specular = float(getattr(light, "specular_factor", 1.0)) if glossy else 1.0
    energy = float(light.energy)
    if specular == 0.0 or energy == 0.0 or not np.isfinite(energy * specular):
        return None
    kw = {
        "exposure": float(getattr(light, "exposure", 0.0)),
        "normalize": bool(getattr(light, "normalize", True)),
        "specular_factor": specular,
    }
    if light.type == "SUN":
        kw["angle"] = float(light.angle)
    elif light.type in ("POINT", "SPOT"):
        kw["radius"] = float(light.shadow_soft_size)
        if light.type == "SPOT":
            kw["spot_size"] = float(light.spot_size)
            kw["spot_blend"] = float(light.spot_blend)
    else:
        kw.update(
            shape=light.shape, size=float(light.size), size_y=float(light.size_y), spread=float(light.spread)
        )
    return light_shading.light_from_blender(
        light.type, np.array(matrix_world, dtype=np.float64), _colour(light), energy, **kw
    )


def _receivers(obj):
    """(names included, names excluded) of a light's receiver collection, or None without one."""
    linking = getattr(obj, "light_linking", None)
    collection = getattr(linking, "receiver_collection", None) if linking is not None else None
    if collection is None:
        return None
    included, excluded = set(), set()
    # collection_objects / collection_children hold the link states, in the order of objects / children
    for obj, entry in zip(collection.objects, getattr(collection, "collection_objects", ()), strict=False):
        state = getattr(getattr(entry, "light_linking", None), "link_state", "INCLUDE")
        (excluded if state == "EXCLUDE" else included).add(obj.name)
    for child, entry in zip(
        collection.children, getattr(collection, "collection_children", ()), strict=False
    ):
        state = getattr(getattr(entry, "light_linking", None), "link_state", "INCLUDE")
        (excluded if state == "EXCLUDE" else included).update(o.name for o in child.all_objects)
    return included, excluded


def receives(receivers, object_name: str) -> bool:
    """Whether an object receives a light with these :func:`_receivers` (None: every object).

    As Cycles: with any included object only the included receive; otherwise all but the
    excluded."""
    if receivers is None:
        return True
    included, excluded = receivers
    if object_name in excluded:
        return False
    return object_name in included if included else True


def scene_lights(depsgraph) -> list:
    """[(row, receivers)] of the visible light objects in the depsgraph (evaluated transforms)."""
    out = []
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type != "LIGHT":
            continue
        row = light_row(obj, inst.matrix_world)
        if row is None:
            continue
        original = obj.original if hasattr(obj, "original") else obj
        out.append((row, _receivers(original)))
    return out


def lights_for(found, object_name: str) -> light_shading.Lights:
    """The :class:`~precompute.shading.lights.Lights` that ``object_name`` receives."""
    return light_shading.Lights.from_rows(row for row, rec in found if receives(rec, object_name))


def lights_summary(scene) -> str:
    """One line for the Surface panel: how many light objects light the films, and what is not
    done yet (no cast shadows; only the film's specular layer)."""
    count = sum(1 for obj in scene.objects if obj.type == "LIGHT" and obj.visible_get())
    if count == 0:
        return "Light objects: none"
    shown = min(count, MAX_LIGHTS)
    return f"Light objects: {shown} shade the film (no cast shadows yet)"
