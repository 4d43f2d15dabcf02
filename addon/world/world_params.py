"""A World's cheap parameters: what is applied to its content without recomputing it.

The Background's Strength and the rotation of a Mapping in front of an Environment Texture
(:class:`WorldParams`) are read apart from the World's *content* (:func:`world_parts`: the
content key leaves them out), so a Strength or rotation edit turns and scales the content's SH,
lamps and prefilters (:func:`apply_params`, exact: SH rotations are) instead of analysing the
World again. See :mod:`.world` for the maths of the Mapping.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ...precompute.materials.material import MAX_SH_ORDER
from ...precompute.sh import harmonics, rotations
from .world_key import world_key, world_uses_nodes
from .world_nodes import Fallback, active_world_output, linked_from, lookup_matrix, rotation_from_lookup

__all__ = ["MAX_COEFFICIENT", "WorldParams", "apply_params", "background_node", "parameters", "world_parts"]

#: Largest |SH coefficient| (√(4π) × radiance) accepted. The shader sums up to 169 products of a
#: coefficient and a table entry (≤ ~1) in float32; 1e20 stays 10¹⁸ below float32's 3.4e38 and is
#: ~10¹⁵ times the brightest sky a scene uses. Beyond it the World counts as not evaluable.
MAX_COEFFICIENT = 1e20


@dataclass(frozen=True)
class WorldParams:
    """A World's cheap parameters (:func:`world_parts`): applied to its content without recomputing it.

    Attributes
    ----------
    strength : float or None
        The Background's Strength when it is a parameter (unlinked, finite, the Background fed
        straight to the World Output); None when it is part of the content.
    rotation : tuple of 9 floats
        Proper rotation P, row-major, with parity: image direction ∝ parity · P · world direction
        (the Mapping in front of an Environment Texture, :func:`.world_nodes.rotation_from_lookup`); the
        identity when the World has no such Mapping or is read another way.
    parity : int
        ±1: −1 for a uniform negative scale (a point reflection).
    """

    strength: float | None = None
    rotation: tuple = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    parity: int = 1

    @property
    def matrix(self) -> np.ndarray:
        """Q = parity · P (3×3): the image direction of a world direction (the prefilter's lookup)."""
        return self.parity * np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)

    @property
    def turned(self) -> bool:
        """Whether Q is not the identity."""
        return bool(self.parity < 0 or not np.allclose(self.matrix, np.eye(3), rtol=0.0, atol=1e-15))


def background_node(world):
    """The Background node fed straight to the active World Output, or None."""
    if world is None or not world_uses_nodes(world):
        return None
    output = active_world_output(world.node_tree)
    if output is None or output.mute:
        return None
    try:
        surface = linked_from(output.inputs["Surface"])
    except Fallback:
        return None
    if surface is None or surface[0].bl_idname != "ShaderNodeBackground" or surface[0].mute:
        return None
    return surface[0]


def _environment_rotation(bg):
    """(P, parity, Mapping names) when the World is read from its Environment Texture's pixels
    (case 2 of the module docstring), else None."""
    if bg.inputs["Strength"].is_linked:
        return None
    try:
        colour = linked_from(bg.inputs["Color"])
        if colour is None:
            return None
        env, out = colour
        if env.bl_idname != "ShaderNodeTexEnvironment" or out.identifier != "Color" or env.mute:
            return None
        if env.projection != "EQUIRECTANGULAR":
            return None
        names: list = []
        rotation, parity = rotation_from_lookup(lookup_matrix(env, names))
    except Fallback:
        return None
    return rotation, parity, names


#: A rotation this close to one about z (mathutils' float32 Euler, the normalisation) is taken
#: as that rotation exactly: its SH rotation is then the cos/sin fast path (sh.rotation_z).
_Z_SNAP = 1e-6


def _snapped(p: np.ndarray) -> np.ndarray:
    """``p``, or the exact rotation about z it is within :data:`_Z_SNAP` of."""
    off = max(abs(p[0, 2]), abs(p[1, 2]), abs(p[2, 0]), abs(p[2, 1]), abs(p[2, 2] - 1.0))
    if off > _Z_SNAP:
        return p
    angle = math.atan2(p[1, 0], p[0, 0])
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@functools.lru_cache(maxsize=8)
def _sh_rotation(l_max: int, rotation: tuple) -> np.ndarray:
    """The SH rotation of the World's Pᵀ (cached: the SH and the SH without lamps share it)."""
    out = rotations.rotation(l_max, np.asarray(rotation, dtype=np.float64).reshape(3, 3).T)
    out.setflags(write=False)
    return out


def parameters(world) -> tuple[WorldParams, list]:
    """The World's cheap parameters and the (node, input) pairs they are read from."""
    bg = background_node(world)
    if bg is None:
        return WorldParams(), []
    without = []
    rotation, parity = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), 1
    found = _environment_rotation(bg)
    if found is not None:
        p, parity, names = found
        rotation = tuple(float(v) for v in _snapped(np.asarray(p)).reshape(-1))
        without += [(name, ident) for name in names for ident in ("Rotation", "Scale")]
    strength = None
    socket = bg.inputs["Strength"]
    if not socket.is_linked:
        value = float(socket.default_value)
        read_apart = found is not None or not bg.inputs["Color"].is_linked
        # a panorama render holds its strength: it scales only when that is not 0
        if math.isfinite(value) and abs(value) <= MAX_COEFFICIENT and (read_apart or value != 0.0):
            strength = value
            without.append((bg.name, "Strength"))
    return WorldParams(strength, rotation, parity), without


def world_parts(scene, l_max: int = MAX_SH_ORDER) -> tuple[str, WorldParams]:
    """(content key, parameters) of ``scene``'s World; cheap (reads no pixels).

    The *content key* is :func:`.world_key.world_key` without the parameters
    (:class:`WorldParams`: the Background's Strength, the rotation of a Mapping in front of an
    Environment Texture), so a change of those alone keeps the content key, and the World's SH,
    lamps and prefilter are turned and scaled (:func:`apply_params`) instead of recomputed.
    """
    params, without = parameters(scene.world)
    return world_key(scene, l_max, without=without), params


def apply_params(coeffs, params: WorldParams, scale: float | None, turned: bool) -> np.ndarray:
    """Content SH → the World's: turned by the parameters' rotation (when ``turned``: the content
    is the image as read) and multiplied by ``scale`` (None: 1). Exact: SH rotations are."""
    c = np.asarray(coeffs, dtype=np.float64)
    l_max = harmonics.l_max_from_size(c.shape[0])
    if turned and params.parity < 0:
        bands = np.repeat(np.arange(l_max + 1), 2 * np.arange(l_max + 1) + 1)
        c = c * np.where(bands % 2 == 1, -1.0, 1.0)[:, None]
    p = np.asarray(params.rotation, dtype=np.float64).reshape(3, 3)
    if turned and not np.allclose(p, np.eye(3), rtol=0.0, atol=1e-15):
        c = _sh_rotation(l_max, tuple(params.rotation)) @ c
    return c * scale if scale is not None else c
