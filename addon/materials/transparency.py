"""Which films let what lies behind them through, and as which wall (precompute.shading.transmit).

- The extension's settings (*Transparency*): *Automatic* sees through a film on air (the soap
  film preset: substrate = ambient, no diffuse base), a free-standing film, T = 1 − R; *Thin
  Sheet* sees through any film on a dielectric substrate as a thin sheet of it (a window);
  *Opaque* never.
- A Principled BSDF with *Transmission Weight* ≥ 0.5 (previewed as 1, like the reflection) and
  *Thin Wall* on: Cycles' thin wall (the film on both faces, the slab series of
  ``bsdf_thin_glass_fresnel``), its transmission tinted by *Base Color* as Cycles does; without
  *Thin Wall* (solid glass, water) solid glass of its IOR, tinted the same way:
  the World seen through the ray's exit from a sphere of that glass (docs/transparent-films.md);
  without *Thin Wall* at IOR 1 (glass of the ambient's index) the film alone, once on each wall
  a ray crosses, as the extension's own free film.

:func:`wall` gives the draw item's ``wall`` = (mode, η), or None for an opaque film.
"""

from __future__ import annotations

from ...precompute.shading import transmit
from .principled import (
    SOCKET_BASE_COLOR,
    SOCKET_IOR,
    SOCKET_METALLIC,
    SOCKET_ROUGHNESS,
    SOCKET_THIN_WALL,
    SOCKET_TRANSMISSION,
    principled_node,
)

__all__ = ["cycles_stops_shadow_rays", "wall"]


def _real_index(value) -> float | None:
    """A constant real index as a float, else None (dispersive, absorbing or metal substrates)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value)


def _extension_wall(props, desc) -> tuple | None:
    choice = getattr(props, "transparency", "AUTO")
    substrate = _real_index(desc.substrate)
    if choice == "OPAQUE" or substrate is None or desc.base_color is not None:
        return None
    eta = substrate / float(desc.ambient)
    if choice == "SHEET":
        return (transmit.WALL_SHEET, eta)
    return (transmit.WALL_SHEET, 1.0) if abs(eta - 1.0) < 1e-6 else None


def _input(node, name: str, default):
    socket = node.inputs.get(name)
    return default if socket is None else socket.default_value


def _principled_wall(bpy_material, desc) -> tuple | None:
    node = principled_node(bpy_material)
    substrate = _real_index(desc.substrate)
    if node is None or substrate is None or desc.base_color is not None:
        return None
    if float(_input(node, SOCKET_METALLIC, 0.0)) > 0.5 or float(_input(node, SOCKET_TRANSMISSION, 0.0)) < 0.5:
        return None
    eta = substrate / float(desc.ambient)
    tint = tuple(min(1.0, max(0.0, float(c))) for c in tuple(_input(node, SOCKET_BASE_COLOR, (1.0,) * 4))[:3])
    if bool(_input(node, SOCKET_THIN_WALL, False)):
        return (transmit.WALL_CYCLES, eta, *tint)
    if abs(eta - 1.0) < 1e-6:  # glass of the ambient's index: the film alone on each wall crossed
        return (transmit.WALL_SHEET, 1.0)  # a free film has no tint (Cycles' √tint per face is not drawn)
    return (transmit.WALL_SOLID, eta, *tint)


def wall(bpy_material, desc) -> tuple | None:
    """(mode, η) of the material's wall (:mod:`precompute.shading.transmit`), or None when the film
    is opaque; a Principled BSDF's wall adds its transmission tint, (mode, η, r, g, b): its
    *Base Color* (unlinked value), which Cycles multiplies its transmission by (Blender's default
    0.8 lets 0.8 through a thin wall at normal incidence, 0.8 through solid glass in and out).
    ``desc``: the material's description (:func:`.description.description`)."""
    if desc is None:
        return None
    props = getattr(bpy_material, "thinfilm_sh", None)
    if props is not None and props.enabled:
        return _extension_wall(props, desc)
    return _principled_wall(bpy_material, desc)


def cycles_stops_shadow_rays(bpy_material, wall, roughness: float) -> bool:
    """Whether Cycles stops shadow rays at the material's wall, read from its Principled BSDF
    (what Cycles renders): glass without *Thin Wall* always (a sunlit ground keeps 0.075 of its
    light under a smooth plate of IOR 1, 64 spp), a thin wall where
    :func:`precompute.shading.transmit.wall_stops_shadow_rays` says (rough, of an index other
    than 1). Without a Principled BSDF: the ``wall`` (mode, η) and ``roughness`` as a thin wall."""
    node = principled_node(bpy_material)
    if node is None or SOCKET_THIN_WALL not in node.inputs:
        return transmit.wall_stops_shadow_rays(float(wall[1]), roughness)
    if not bool(_input(node, SOCKET_THIN_WALL, False)):
        return True
    ior, rough = (node.inputs.get(name) for name in (SOCKET_IOR, SOCKET_ROUGHNESS))
    eta = float(wall[1]) if ior is None or ior.is_linked else float(ior.default_value)
    rough = roughness if rough is None or rough.is_linked else float(rough.default_value)
    return transmit.wall_stops_shadow_rays(eta, rough)
