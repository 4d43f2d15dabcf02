"""The scene's light objects as a film material's lobe light sees them (main thread, no bake).

EEVEE lights a Glossy closure by each light object with its own GGX lobe, and the film's colour
is one lookup at the angle θ' of the lobe light's mean direction (:mod:`.nodes`). So the light
objects join the World in that direction (:func:`precompute.bakes.eevee_table.dominant_directions`),
weighted by the irradiance they bring: :func:`material_lights` reads every visible light object
(:func:`..drawing.lights.light_row`: its power, colour, exposure, *Specular* factor, size, cone
and spread, as the overlay reads it) and takes its samples (a sun's direction, a point or spot
light's centre, an area light's cells: :func:`precompute.shading.lights.light_samples`) seen
from **one point: the centre of the bounding box of the objects using the material** (world
space, every object of the scene whose slots hold it). That is the approximation: for a point,
spot or area light near a large object the direction and distance vary over its surface; the
image holds them at its centre. Light linking and cast shadows are not followed.

:func:`signature` is what the timer compares to see a light added, removed, moved, recoloured
or re-powered (a few attribute reads per light).
"""

from __future__ import annotations

import numpy as np

from ...precompute.bakes import eevee_table
from ...precompute.shading import lights as light_shading
from ...precompute.world.prefilter import LUMINANCE
from ..drawing.lights import light_row

__all__ = ["SceneLights", "material_lights", "signature"]

#: Digits the key keeps of a sample's direction, luminance (relative) and footprint: an edit
#: below these does not rewrite the image.
KEY_DIGITS = 4


def _rows(scene) -> list:
    """:func:`..drawing.lights.light_row` of the scene's visible light objects (those that reach
    a film: glossy rays on, power and *Specular* above 0)."""
    out = []
    for obj in scene.objects:
        if obj.type != "LIGHT" or not obj.visible_get():
            continue
        row = light_row(obj, obj.matrix_world)
        if row is not None:
            out.append(row)
    return out


def signature(scene) -> tuple:
    """What the scene's lights are now, cheaply: (name, matrix, colour, power, settings) of each
    light object; any change to it may change a film's lobe light."""
    out = []
    for obj in scene.objects:
        if obj.type != "LIGHT":
            continue
        light = obj.data
        settings = tuple(
            getattr(light, name, None)
            for name in ("type", "energy", "exposure", "shadow_soft_size", "angle", "spot_size")
            + ("spot_blend", "size", "size_y", "shape", "spread", "specular_factor", "use_temperature")
            + ("temperature", "normalize")
        )
        out.append(
            (
                obj.name,
                obj.visible_get(),
                tuple(round(v, 6) for row in obj.matrix_world for v in row),
                tuple(light.color),
                settings,
            )
        )
    return tuple(out)


def _centre(objects) -> np.ndarray | None:
    """The centre of the union of ``objects``' world-space bounding boxes, or None."""
    corners = []
    for obj in objects:
        m = np.array(obj.matrix_world, dtype=np.float64)
        box = np.array([tuple(c) for c in obj.bound_box], dtype=np.float64)
        corners.append(box @ m[:3, :3].T + m[:3, 3])
    if not corners:
        return None
    found = np.concatenate(corners)
    return 0.5 * (found.min(axis=0) + found.max(axis=0))


class SceneLights:
    """The scene's light rows and each material's objects, read once for a sync of many
    materials."""

    def __init__(self, scene):
        self.rows = _rows(scene)
        self._scene = scene
        self._users = None

    def _objects(self, material) -> list:
        if self._users is None:
            self._users = {}
            for obj in self._scene.objects:
                for slot in getattr(obj, "material_slots", ()):
                    if slot.material is not None:
                        self._users.setdefault(slot.material.name, []).append(obj)
        return self._users.get(material.name, [])

    def for_material(self, material) -> eevee_table.LobeLights | None:
        """:func:`material_lights` of ``material`` from the rows read here."""
        if not self.rows:
            return None
        centre = _centre(self._objects(material))
        if centre is None:
            centre = np.zeros(3)  # a material on no object: the world origin
        return samples_at(self.rows, centre)


def samples_at(rows, centre) -> eevee_table.LobeLights | None:
    """The :class:`~precompute.bakes.eevee_table.LobeLights` of light ``rows`` seen from
    ``centre`` (3,) m, or None when none reaches it (a spot facing away, no power)."""
    lights = light_shading.Lights.from_rows(rows)
    directions, luminance, rho2 = [], [], []
    weights = np.asarray(LUMINANCE, dtype=np.float64)
    for k in range(lights.count):
        for l, e, r2 in light_shading.light_samples(lights, k, np.asarray(centre, dtype=np.float64)[None]):
            y = float(np.asarray(e).reshape(-1, 3)[0] @ weights)
            if np.isfinite(y) and y > 0.0:
                directions.append(np.asarray(l).reshape(-1, 3)[0])
                luminance.append(y)
                rho2.append(float(np.asarray(r2).reshape(-1)[0]))
    if not luminance:
        return None
    return eevee_table.LobeLights(np.array(directions), np.array(luminance), np.array(rho2))


def material_lights(material, scene) -> eevee_table.LobeLights | None:
    """The light objects as ``material``'s film sees them (see the module docstring)."""
    return SceneLights(scene).for_material(material)


def key(found: eevee_table.LobeLights | None) -> str:
    """The part of an image's key that names ``found`` (rounded: :data:`KEY_DIGITS`)."""
    if found is None:
        return "no lights"
    top = float(found.luminance.max())
    parts = [
        f"{d[0]:.{KEY_DIGITS}f},{d[1]:.{KEY_DIGITS}f},{d[2]:.{KEY_DIGITS}f}:{y / top:.{KEY_DIGITS}f}:{r:.3g}"
        for d, y, r in zip(found.direction, found.luminance, found.rho2, strict=True)
    ]
    return f"{top:.{KEY_DIGITS}g}|" + ";".join(parts)
