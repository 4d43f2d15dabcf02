"""What the preview shows for a Blender material: a precompute Material, its key, its caveats.

- :func:`description` — the :class:`~precompute.materials.material.Material` of a Blender material: from
  the extension's settings when they are enabled (:mod:`.props`), else from a Principled
  BSDF with a thin film (:mod:`.principled`, Cycles interop), else None;
- :func:`warnings` — what the preview of a material cannot follow, and why it cannot be
  evaluated at all (it is then drawn as the magenta fallback, ``precompute.materials.material.FALLBACK``);
- :func:`description_key` — the cache key of a description: equal descriptions share one
  baked table (:mod:`.tables`) and one GPU texture.
"""

from __future__ import annotations

import json

from ...precompute.bakes import planner
from ...precompute.materials.material import Material
from ...precompute.shading import policy
from ..colour_space import unsupported_working_space
from ..thickness.linked import Pending
from .conversion import description_from_props
from .principled import read_principled

__all__ = ["described", "description", "description_key", "warnings"]


def description(bpy_material) -> Material | None:
    """What the preview shows for ``bpy_material``, or None if it has no thin film.

    1. The extension's settings (``material.thinfilm_sh``) when enabled.
    2. Otherwise a Principled BSDF with Thin Film Thickness > 0 (the one feeding the output's
       Surface, else the first): film index = Thin Film IOR, thickness = Thin Film Thickness,
       substrate = IOR (dielectric) or, for Metallic > 0.5, Blender's F82-tint metal of Base
       Color and Specular Tint; roughness = Roughness; Cycles' colour pipeline (the per-channel
       mode); ambient 1; a dielectric's Base Color, unless black, as a diffuse base layered as
       Cycles layers it. A linked Thin Film Thickness is evaluated over the objects using the
       material (:mod:`.linked`; None while its Cycles bake is queued inside the draw); other
       linked sockets use their unlinked values (see :func:`warnings`).
    3. Otherwise None. A zero thickness is not previewed: it is the bare Principled BSDF; nor is
       a Principled film whose *Preview Principled Film* switch is off.

    A film drawn by the split sum alone gets the automatic SH order 0
    (:func:`precompute.shading.policy.drawn_material`).

    Raises ValueError (naming the material and the parameter) for invalid settings: every
    value is checked when the Material is built (precompute.materials.validate), so nothing invalid
    reaches a bake. The draw shows such a material as the magenta fallback.
    """
    return described(bpy_material)[0]


def described(bpy_material) -> tuple[Material | None, bool]:
    """(:func:`description`, whether it is None only because a linked thickness is being
    evaluated: queued for the viewport's timer, the draw shows the material's last entry)."""
    props = getattr(bpy_material, "thinfilm_sh", None)
    try:
        if props is not None and props.enabled:
            return policy.drawn_material(description_from_props(props)), False
        if props is not None and not props.preview_principled:
            return None, False  # the artist switched the Principled film's preview off
        found = read_principled(bpy_material)[0]
        return (None if found is None else policy.drawn_material(found)), False
    except Pending:  # a linked thickness is being baked: drawn when it is done
        return None, True
    except ValueError as exc:
        raise ValueError(f"material {bpy_material.name!r}: {exc}") from None


def warnings(bpy_material) -> list[str]:
    """What the preview of ``bpy_material`` does not follow (empty when everything is shown),
    first why it cannot be evaluated at all, if so: the panel shows these lines."""
    props = getattr(bpy_material, "thinfilm_sh", None)
    if props is not None and props.enabled:
        notes = []
        try:
            description_from_props(props)
        except ValueError as exc:
            notes.append(f"{exc}: drawn in magenta (the fallback) until it is fixed")
        if props.vary_thickness and props.thickness_source == "ATTRIBUTE" and not props.thickness_attribute:
            notes.append("thickness source ATTRIBUTE needs an attribute name")
        if props.vary_thickness and props.thickness_source == "IMAGE" and props.thickness_image is None:
            notes.append("thickness source IMAGE needs an image")
    else:
        try:
            notes = read_principled(bpy_material)[1]
        except Pending as exc:
            notes = [f"{exc}: drawn when the bake is done"]
        except ValueError as exc:
            notes = [f"{exc}: drawn in magenta (the fallback) until it is fixed"]
    notes.extend(_gltf_notes(bpy_material))
    space = unsupported_working_space()
    if space:
        notes.append(f"working color space {space!r} is not supported: previewing in Linear Rec.709")
    return notes


def _gltf_notes(bpy_material) -> list[str]:
    """What the preview does not follow of a glTF file's KHR_materials_iridescence (kept by the
    import hook, :func:`.gltf.repair_import`, as the custom property of that name)."""
    kept = bpy_material.get("KHR_materials_iridescence") if hasattr(bpy_material, "get") else None
    try:
        factor = float(json.loads(kept)["iridescenceFactor"]) if isinstance(kept, str) else 1.0
    except (ValueError, KeyError, TypeError):
        return []
    if factor == 1.0:
        return []
    return [f"glTF iridescence factor {factor:g}: previewed (as Cycles renders it) at full strength"]


def description_key(desc: Material) -> str:
    """Cache key of a description: :func:`precompute.bakes.planner.table_key` (parameters + planner
    version)."""
    return planner.table_key(desc)
