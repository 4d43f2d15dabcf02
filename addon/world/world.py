"""The scene's World as spherical harmonics: radiance coefficients in world space.

:func:`world_sh` turns ``scene.world`` into real SH coefficients of its radiance L(ω) (the
conventions of ``docs/conventions.md``: Blender world axes, z up, no Condon–Shortley phase),
in the blend file's working colour space (scene linear). It reads the World's node tree and
takes the cheapest exact route:

1. no World, or a World without a node tree (``use_nodes`` off before Blender 5.0): the
   World's viewport colour (black without a World), with a warning;
2. World Output ← Background ← Environment Texture (optionally through reroutes and Mapping
   nodes fed by Texture Coordinate "Generated"), Strength unlinked: the image's pixels are
   projected directly (:func:`precompute.sh.projection.project_equirect`), times Strength, turned by the
   Mapping transform;
3. World Output ← Background with an unlinked Color: a constant, coefficient 0 = √(4π)·c;
4. anything else (Sky Texture, gradients, mixes, muted nodes, Mapping with a location offset
   or a non-uniform scale, images in colour spaces we do not convert, ...): a small
   equirectangular panorama of the World alone is rendered with Cycles on the CPU and
   projected. This is the ground truth the other routes are tested against.

Results are cached (:data:`SH_CACHE`) by :func:`.world_key.world_key`, a content hash of
everything that affects them (the node tree with all settings and links, image files'
path/size/mtime, l_max, the working space) computed without reading any pixels, so the draw
code can poll it cheaply.

Mapping and rotation
--------------------
The Environment Texture looks the image up at the direction d' = M d, where M is the Mapping
node's transform (POINT/VECTOR: d' ∝ R·S·d (+ location), TEXTURE: d' ∝ S⁻¹·Rᵀ·(d − location),
NORMAL: d' ∝ R·S⁻¹·d; R from the Euler XYZ rotation). With a uniform positive scale and no
location offset M is a rotation Q (up to a positive factor that the normalisation removes), so
L(d) = I(Q d) = I∘(Qᵀ)⁻¹, whose coefficients are ``sh.rotation(l_max, Qᵀ) @ c_I``. A uniform
negative scale adds a point reflection, (−1)^l per band.

The panorama render is :mod:`.panorama`; the maths is in ``precompute``.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np

from ...precompute.materials.material import MAX_SH_ORDER
from ...precompute.sh import harmonics
from .. import caches
from ..colour_space import DEFAULT_WORKING_SPACE, working_space
from .panorama import render_world_panorama
from .world_image import image_pixels, project_image
from .world_key import image_path, world_key, world_uses_nodes
from .world_nodes import (
    Fallback,
    active_world_output,
    linked_from,
    lookup_matrix,
    rotation_from_lookup,
    uses_light_path,
)
from .world_params import (
    MAX_COEFFICIENT,
    WorldParams,
    apply_params,
    parameters,
)

__all__ = [
    "DEFAULT_CACHE_SIZE",
    "FALLBACK_RADIANCE",
    "SH_CACHE",
    "WorldContent",
    "WorldRead",
    "WorldSH",
    "analyse_read",
    "constant_sh",
    "content_scale",
    "finish",
    "read_world",
    "fallback_colour",
    "world_sh",
]


#: Size of the LRU of results :func:`world_sh` keeps (:data:`SH_CACHE`).
DEFAULT_CACHE_SIZE = 16


@dataclasses.dataclass(frozen=True, eq=False)
class WorldSH:
    """SH radiance of a World (see :func:`world_sh`).

    Attributes
    ----------
    coeffs : ndarray, shape ((l_max+1)², 3), float64, read-only
        RGB radiance coefficients in world space (Blender axes, z up), scene linear in
        ``working_space``. Coefficient 0 is √(4π) × the mean radiance.
    source : str
        How they were obtained, e.g. "environment texture 'studio.exr'", "background color",
        "panorama render (Sky Texture)", "viewport color".
    key : str
        :func:`.world_key.world_key` of the inputs (16 hex digits).
    rejected_pixels : int
        NaN/Inf pixels of the image or panorama that were left out (counted at full resolution).
    warnings : tuple of str
        Problems the user should know about (missing image, no World, ...).
    l_max : int
    working_space : str
        The blend file's working (scene linear) colour space, e.g. "Linear Rec.709".
    errors : tuple of str
        Why the World could not be evaluated (a NaN or Inf Strength or Color, lighting too bright
        for float32), naming the values; ``coeffs`` are then the fallback lighting
        (:func:`fallback_colour`). Empty for a World that was evaluated.
    """

    coeffs: np.ndarray
    source: str
    key: str
    rejected_pixels: int = 0
    warnings: tuple = ()
    l_max: int = 8
    working_space: str = DEFAULT_WORKING_SPACE
    errors: tuple = ()


#: Radiance of the fallback lighting when neither the World nor its viewport colour is finite:
#: Blender's default World colour (sRGB 0.25, linear 0.0509): grey, never black.
FALLBACK_RADIANCE = 0.0509


def _usable(values) -> bool:
    v = np.asarray(values, dtype=np.float64)
    return bool(np.all(np.isfinite(v)) and np.all(np.abs(v) <= MAX_COEFFICIENT))


def fallback_colour(world) -> tuple[tuple, str]:
    """The fallback lighting's radiance (RGB) and its description: the World's viewport colour
    (World ▸ Viewport Display ▸ Color) when it is finite, non-negative and not black, else
    :data:`FALLBACK_RADIANCE` grey (never black: the film stays visible)."""
    colour = tuple(world.color)[:3] if world is not None else None
    if colour is not None and _usable(colour) and min(colour) >= 0.0 and max(colour) > 0.0:
        return colour, "the World's viewport color"
    return (FALLBACK_RADIANCE,) * 3, f"grey {FALLBACK_RADIANCE:g} (Blender's default World color)"


def _bad_values(world, limit: int = 3) -> list[str]:
    """Unlinked node inputs (and the viewport colour) of ``world`` that are NaN, Inf or beyond
    :data:`MAX_COEFFICIENT`, named as a user finds them: "Background 'Background' Strength = nan"."""
    found = []
    tree = getattr(world, "node_tree", None)
    for node in tree.nodes if tree is not None else ():
        for socket in node.inputs:
            if socket.is_linked or not hasattr(socket, "default_value"):
                continue
            value = socket.default_value
            try:
                values = tuple(value) if hasattr(value, "__len__") else (float(value),)
                ok = _usable(values)
            except (TypeError, ValueError):
                continue  # strings, shaders, …
            if not ok:
                shown = ", ".join(f"{float(v):g}" for v in values[:3])
                found.append(f"{node.bl_rna.name} '{node.name}' {socket.name} = {shown}")
    if world is not None and not _usable(tuple(world.color)):
        found.append("Viewport Display Color = " + ", ".join(f"{v:g}" for v in world.color))
    return found[:limit]


#: World SH results by :func:`.world_key.world_key` (see :mod:`.caches`).
SH_CACHE = caches.register("world_sh", caches.LRU(DEFAULT_CACHE_SIZE), scope=caches.SESSION)


# ----------------------------------------------------------------------------------------------
# The cases: what is read on the main thread (WorldRead), then analysed anywhere (WorldContent)
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class WorldRead:
    """What :func:`read_world` reads of a World with bpy (main thread), for :func:`analyse_read`.

    Either ``coeffs`` (a constant World's content SH) or ``rgb`` (an equirect, top row first,
    as read: an Environment Texture's pixels in the image's frame, or a Cycles panorama) with
    ``convert`` (None or a function to scene linear). ``factor`` multiplies the result (a
    Strength that is not a parameter); ``base``: the Strength the content holds when the World's
    Strength parameter scales it (None: it does not); ``turned``: the content is in the image's
    frame, turned by the parameters' rotation.
    """

    source: str
    coeffs: np.ndarray | None = None
    rgb: np.ndarray | None = None
    convert: object = None
    warnings: tuple = ()
    rejected: int = 0
    factor: float = 1.0
    base: float | None = None
    turned: bool = False
    panorama: bool = False
    pending: object = None  # a panorama a helper process renders (:func:`.panorama_helper.resolve`)


@dataclass(frozen=True, eq=False)
class WorldContent:
    """A World's content analysed (:func:`analyse_read`, pure numpy: any thread).

    ``coeffs``: content SH (l_max); ``image``: the equirect the SH came from (≤
    MAX_PROJECTION_WIDTH wide, float64; None for a constant); the rest as :class:`WorldRead`.
    """

    coeffs: np.ndarray
    image: np.ndarray | None
    read: WorldRead
    rejected: int
    warnings: tuple


def constant_sh(l_max: int, rgb) -> np.ndarray:
    """The SH (bands 0…``l_max``, RGB) of a constant radiance ``rgb``: coefficient 0 is √(4π)·c,
    the rest 0 (a Background colour, the fallback lighting, a World that failed)."""
    coeffs = np.zeros(((l_max + 1) ** 2, 3))
    coeffs[0] = math.sqrt(4.0 * math.pi) * np.asarray(rgb, dtype=np.float64)[:3]
    return coeffs


def _viewport_colour(world, l_max: int, reason: str) -> WorldRead:
    colour = tuple(world.color) if world is not None else (0.0, 0.0, 0.0)
    source = "viewport color" if world is not None else "no world (black)"
    return WorldRead(source, coeffs=constant_sh(l_max, colour), warnings=(reason,))


def _environment(world, bg, env, l_max: int, space: str, params: WorldParams) -> WorldRead:
    """Case 2; raises Fallback for shapes it does not read directly. The pixels as read: the
    rotation and (a parameter) Strength are applied to the result (:func:`apply_params`)."""
    if env.mute:
        raise Fallback("muted Environment Texture")
    if env.projection != "EQUIRECTANGULAR":
        raise Fallback(f"Environment Texture with {env.projection} projection")
    if bg.inputs["Strength"].is_linked:
        raise Fallback("a linked Strength")
    strength = float(bg.inputs["Strength"].default_value)
    rotation_from_lookup(lookup_matrix(env))  # raises Fallback where the rotation is not one
    image = env.image
    if image is None:
        return _viewport_colour(
            world, l_max, "Environment Texture has no image: using the World's viewport color"
        )
    if image.source not in {"FILE", "GENERATED"}:
        raise Fallback(f"image source {image.source}")
    label = os.path.basename(image.filepath) if image.filepath else image.name
    if image.source == "FILE" and image.packed_file is None:
        path = image_path(image)
        if not os.path.isfile(path):
            return _viewport_colour(
                world,
                l_max,
                f"Environment image '{label}' not found ({path}): using the World's viewport color",
            )
    try:
        rgb, convert = image_pixels(image, space)
    except OSError as exc:
        return _viewport_colour(
            world,
            l_max,
            f"Environment image '{label}' could not be read ({exc}): using the World's viewport color",
        )
    param = params.strength is not None
    return WorldRead(
        f"environment texture '{label}'",
        rgb=rgb,
        convert=convert,
        factor=1.0 if param else strength,
        base=1.0 if param else None,
        turned=True,
    )


def _panorama(world, params: WorldParams, reason: str, l_max: int, render=None) -> WorldRead:
    warnings = []
    if uses_light_path(world.node_tree):
        warnings.append("World uses a Light Path node: its SH is what the camera sees")
    source = f"panorama render ({reason})"
    pending = render(world) if render is not None else None
    if pending is not None:  # a helper process renders it: awaited off the main thread
        return WorldRead(
            source, warnings=tuple(warnings), base=params.strength, panorama=True, pending=pending
        )
    try:
        rgb = render_world_panorama(world)
    except (RuntimeError, OSError) as exc:
        read = _viewport_colour(world, l_max, "")
        return WorldRead(
            read.source,
            coeffs=read.coeffs,
            warnings=(f"Could not render the World ({exc}): using its viewport color",),
        )
    return WorldRead(source, rgb=rgb, warnings=tuple(warnings), base=params.strength, panorama=True)


def _black(source: str, warning: str, l_max: int) -> WorldRead:
    return WorldRead(source, coeffs=constant_sh(l_max, (0.0, 0.0, 0.0)), warnings=(warning,))


def _nodes(world, l_max: int, space: str, params: WorldParams, render=None) -> WorldRead:
    tree = world.node_tree
    output = active_world_output(tree)
    if output is None or output.mute:
        return _black("no world output (black)", "World has no active World Output: black", l_max)
    try:
        surface = linked_from(output.inputs["Surface"])
        if surface is None:
            return _black(
                "nothing connected (black)",
                "Nothing is connected to the World Output's Surface: black",
                l_max,
            )
        bg, _ = surface
        if bg.bl_idname != "ShaderNodeBackground" or bg.mute:
            raise Fallback(bg.bl_rna.name)
        colour = linked_from(bg.inputs["Color"])
        if colour is None:
            if bg.inputs["Strength"].is_linked:
                raise Fallback("a linked Strength")
            rgb = np.array(tuple(bg.inputs["Color"].default_value)[:3])
            if params.strength is not None:
                return WorldRead("background color", coeffs=constant_sh(l_max, rgb), base=1.0)
            strength = bg.inputs["Strength"].default_value
            return WorldRead("background color", coeffs=constant_sh(l_max, rgb * strength))
        env, out = colour
        if env.bl_idname != "ShaderNodeTexEnvironment" or out.identifier != "Color":
            raise Fallback(env.bl_rna.name)
        return _environment(world, bg, env, l_max, space, params)
    except Fallback as why:
        return _panorama(world, params, str(why), l_max, render)


def read_world(scene, l_max: int = MAX_SH_ORDER, params: WorldParams | None = None, render=None) -> WorldRead:
    """Read ``scene``'s World with bpy (main thread; :func:`analyse_read` does the rest anywhere).

    An Environment Texture World reads its image's pixels (no copy of Blender's buffer:
    ≈ 0.1–0.3 s for a 4k HDRI); a procedural World renders a small Cycles panorama
    (:func:`.panorama.render_world_panorama`, ≈ 1–3 s on the main thread); anything else is a
    constant. ``render``: None, or ``render(world)`` → a pending panorama or None, e.g.
    :func:`.panorama_helper.submit` (the viewport): a procedural World's read then holds the
    pending render in ``pending`` (:func:`.panorama_helper.resolve` waits for it on a worker),
    and it is rendered here only when ``render`` returns None.
    """
    l_max = harmonics.check_l_max(l_max)
    params = parameters(scene.world)[0] if params is None else params
    world = scene.world
    with np.errstate(all="ignore"):
        if world is None:
            return _viewport_colour(None, l_max, "Scene has no World: black")
        if not world_uses_nodes(world):
            return _viewport_colour(world, l_max, "World has no nodes: using its viewport color")
        return _nodes(world, l_max, working_space(), params, render)


def analyse_read(read: WorldRead, l_max: int = MAX_SH_ORDER) -> WorldContent:
    """The content SH of a :class:`WorldRead`: pure numpy, any thread (the image's projection,
    ≈ 0.2–1 s for a 4k HDRI)."""
    warnings = list(read.warnings)
    if read.rgb is None:
        return WorldContent(
            np.asarray(read.coeffs, dtype=np.float64), None, read, read.rejected, tuple(warnings)
        )
    with np.errstate(all="ignore"):
        coeffs, rejected, small = project_image(read.rgb, l_max, read.convert)
        if read.factor != 1.0:
            coeffs, small = coeffs * read.factor, small * read.factor
    if rejected:
        what = "World panorama" if read.panorama else f"Environment image '{read.source.split(chr(39))[1]}'"
        warnings.append(f"{what}: {rejected} NaN/Inf pixels left out")
    return WorldContent(coeffs, small, read, rejected, tuple(warnings))


def content_scale(content: WorldContent, params: WorldParams) -> float | None:
    """The factor the parameters' Strength puts on ``content`` (None: 1, it does not apply)."""
    base = content.read.base
    if base is None or params.strength is None:
        return None
    return params.strength / base


def finish(scene, content: WorldContent, params: WorldParams, key: str, l_max: int) -> WorldSH:
    """The :class:`WorldSH` of ``content`` under ``params`` (main thread: cheap, a rotation and a
    scale; never NaN lighting: the documented fallback, naming the bad values)."""
    with np.errstate(all="ignore"):
        coeffs = apply_params(content.coeffs, params, content_scale(content, params), content.read.turned)
        coeffs = np.array(coeffs, dtype=np.float64)
    source = content.read.source
    errors = ()
    if not _usable(coeffs):
        world = scene.world
        bad = _bad_values(world) or [
            f"its lighting from {source} is not finite or beyond {MAX_COEFFICIENT:g}"
        ]
        colour, what = fallback_colour(world)
        coeffs = constant_sh(l_max, colour)
        name = f"World '{world.name}'" if world is not None else "The World"
        errors = (f"{name} cannot be evaluated ({'; '.join(bad)}): lit by {what} instead",)
        source = f"fallback ({what})"
    coeffs.setflags(write=False)
    return WorldSH(
        coeffs=coeffs,
        source=source,
        key=key,
        rejected_pixels=int(content.rejected),
        warnings=tuple(w for w in content.warnings if w),
        l_max=l_max,
        working_space=working_space(),
        errors=errors,
    )


def world_sh(scene, l_max: int = MAX_SH_ORDER, *, cache=None) -> WorldSH:
    """Spherical-harmonic radiance of ``scene``'s World, in world space and scene linear.

    Parameters
    ----------
    scene : bpy.types.Scene
    l_max : int
        Highest band (0 ≤ l_max ≤ :data:`precompute.sh.harmonics.MAX_L_MAX`).
    cache : dict-like, optional
        Anything with ``get`` and item assignment, keyed by :func:`.world_key.world_key`; default
        :data:`SH_CACHE`, an LRU of :data:`DEFAULT_CACHE_SIZE` entries. Cached results are
        returned as they are (the same object; its array is read-only).

    Returns
    -------
    WorldSH

    Notes
    -----
    Never raises for odd Worlds: missing World, nodes, images or failing renders fall back
    to the viewport colour (or black) with a warning. A World whose values are not finite (a
    NaN or Inf Strength or Color set from Python) or too bright for float32 gives the fallback
    lighting of :func:`fallback_colour` and an entry in ``errors`` naming the values. The
    panorama route runs the render operator, so call this from an operator, timer or handler,
    not from a draw callback (use :func:`.world_key.world_key` there to detect changes). The
    viewport does the same in three steps, the slow one on a worker (:mod:`.world_job`):
    :func:`read_world`, :func:`analyse_read`, :func:`finish`.
    """
    l_max = harmonics.check_l_max(l_max)
    cache = SH_CACHE if cache is None else cache
    key = world_key(scene, l_max)
    hit = cache.get(key)
    if hit is not None:
        return hit
    params = parameters(scene.world)[0]
    result = finish(scene, analyse_read(read_world(scene, l_max, params), l_max), params, key, l_max)
    cache[key] = result
    return result
