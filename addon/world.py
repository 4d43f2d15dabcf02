"""The scene's World as spherical harmonics: radiance coefficients in world space.

:func:`world_sh` turns ``scene.world`` into real SH coefficients of its radiance L(ω) (the
conventions of ``docs/conventions.md``: Blender world axes, z up, no Condon–Shortley phase),
in the blend file's working colour space (scene linear). It reads the World's node tree and
takes the cheapest exact route:

1. no World, or a World without a node tree (``use_nodes`` off before Blender 5.0): the
   World's viewport colour (black without a World), with a warning;
2. World Output ← Background ← Environment Texture (optionally through reroutes and Mapping
   nodes fed by Texture Coordinate "Generated"), Strength unlinked: the image's pixels are
   projected directly (:func:`precompute.sh.project_equirect`), times Strength, turned by the
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

import numpy as np
from mathutils import Euler

from ..precompute import hdri, sh
from ..precompute.material import MAX_SH_ORDER
from . import caches
from .panorama import render_world_panorama
from .world_key import DEFAULT_WORKING_SPACE, image_path, working_space, world_key, world_uses_nodes

__all__ = [
    "DEFAULT_CACHE_SIZE",
    "FALLBACK_RADIANCE",
    "MAX_COEFFICIENT",
    "MAX_PROJECTION_WIDTH",
    "SH_CACHE",
    "WorldSH",
    "fallback_colour",
    "world_sh",
]

#: Images wider than this are downsampled (solid-angle-correct, :func:`hdri.downsample`) before
#: projection. 1024 px across 2π resolves bands far beyond the l ≤ 12 the preview uses.
MAX_PROJECTION_WIDTH = 1024

#: Size of the LRU of results :func:`world_sh` keeps (:data:`SH_CACHE`).
DEFAULT_CACHE_SIZE = 16

_LINEAR_SPACES = ("Linear Rec.709", "Linear Rec.2020", "ACEScg")
#: Relative tolerance for "this Mapping is a rotation times a uniform scale".
_SIMILARITY_TOL = 1e-6


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

#: Largest |SH coefficient| (√(4π) × radiance) accepted. The shader sums up to 169 products of a
#: coefficient and a table entry (≤ ~1) in float32; 1e20 stays 10¹⁸ below float32's 3.4e38 and is
#: ~10¹⁵ times the brightest sky a scene uses. Beyond it the World counts as not evaluable.
MAX_COEFFICIENT = 1e20


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
# Colour space
# ----------------------------------------------------------------------------------------------


def _srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding (the piecewise curve of Blender's "sRGB" space)."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((np.maximum(v, 0.04045) + 0.055) / 1.055) ** 2.4)


def _rgb_matrix(source: str, target: str) -> np.ndarray | None:
    """Linear RGB → RGB matrix between two working spaces, or None if it cannot be built here."""
    if source == target:
        return np.eye(3)
    try:  # a failed import of the spectral code must not break the World's SH
        from ..precompute import spectra
    except ImportError:
        return None
    try:
        return spectra.rgb_to_rgb_matrix(source, target)
    except ValueError:
        return None


# ----------------------------------------------------------------------------------------------
# Reading the node tree
# ----------------------------------------------------------------------------------------------


class _Fallback(Exception):
    """The tree is not one of the shapes read directly: render a panorama instead."""


def _active_world_output(tree):
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    for preferred in (
        lambda n: n.is_active_output and n.target in {"ALL", "CYCLES"},
        lambda n: n.is_active_output,
        lambda n: True,
    ):
        found = [n for n in outputs if preferred(n)]
        if found:
            return found[0]
    return None


def _linked_from(socket):
    """(node, output socket) feeding ``socket`` through reroutes, or None when unlinked."""
    seen = 0
    while socket.is_linked:
        links = [link for link in socket.links]
        if len(links) != 1:
            raise _Fallback("multiple links")
        link = links[0]
        if link.is_muted or not link.is_valid:
            raise _Fallback("a muted or invalid link")
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            if node.mute:
                raise _Fallback("a muted reroute")
            socket = node.inputs[0]
            seen += 1
            if seen > 1000:
                raise _Fallback("a reroute loop")
            continue
        return node, link.from_socket
    return None


def _mapping_matrix(node) -> np.ndarray:
    """3×3 matrix A with (Mapping output) ∝ A · input for direction lookups; raises _Fallback."""
    for ident in ("Location", "Rotation", "Scale"):
        sock = node.inputs.get(ident)
        if sock is not None and sock.enabled and sock.is_linked:
            raise _Fallback(f"Mapping with a linked {ident}")
    kind = node.vector_type
    rot = Euler(tuple(node.inputs["Rotation"].default_value), "XYZ").to_matrix()
    r = np.array([list(row) for row in rot], dtype=np.float64)
    scale = np.array(tuple(node.inputs["Scale"].default_value), dtype=np.float64)
    location = node.inputs.get("Location")
    if kind in {"POINT", "TEXTURE"} and location is not None:
        if np.any(np.array(tuple(location.default_value)) != 0.0):
            raise _Fallback("Mapping with a location offset")
    if kind in {"POINT", "VECTOR"}:
        return r @ np.diag(scale)
    if np.any(scale == 0.0):
        raise _Fallback("Mapping with a zero scale")
    if kind == "TEXTURE":
        return np.diag(1.0 / scale) @ r.T
    if kind == "NORMAL":
        return r @ np.diag(1.0 / scale)
    raise _Fallback(f"Mapping of type {kind}")


def _texture_matrix(node) -> np.ndarray:
    """The Environment Texture's own (legacy) texture_mapping must be the identity."""
    tm = node.texture_mapping
    identity = (
        tuple(tm.translation) == (0.0, 0.0, 0.0)
        and tuple(tm.rotation) == (0.0, 0.0, 0.0)
        and tuple(tm.scale) == (1.0, 1.0, 1.0)
        and not tm.use_min
        and not tm.use_max
        and (tm.mapping_x, tm.mapping_y, tm.mapping_z) == ("X", "Y", "Z")
    )
    if not identity:
        raise _Fallback("Environment Texture with a texture mapping")
    return np.eye(3)


def _lookup_matrix(env_node) -> np.ndarray:
    """A with lookup direction d' ∝ A d for the Environment Texture's Vector input."""
    a = _texture_matrix(env_node)
    source = _linked_from(env_node.inputs["Vector"])
    while source is not None:
        node, out = source
        if node.mute:
            raise _Fallback(f"muted node '{node.name}'")
        if node.bl_idname == "ShaderNodeMapping":
            a = a @ _mapping_matrix(node)
            source = _linked_from(node.inputs["Vector"])
            if source is None:
                raise _Fallback("Mapping with an unlinked Vector")
            continue
        if node.bl_idname == "ShaderNodeTexCoord" and out.identifier == "Generated":
            return a
        raise _Fallback(f"texture coordinates from '{node.name}'")
    return a


def _rotation_from_lookup(a: np.ndarray) -> tuple[np.ndarray, int]:
    """Split A = s·Q (s > 0) into a proper rotation P and a parity ±1 with Q = parity·P."""
    gram = a @ a.T
    k = np.trace(gram) / 3.0
    if not k > 0.0 or np.max(np.abs(gram - k * np.eye(3))) > _SIMILARITY_TOL * k:
        raise _Fallback("Mapping with a non-uniform scale")
    q = a / math.sqrt(k)
    parity = 1 if np.linalg.det(q) > 0.0 else -1
    return parity * q, parity


# ----------------------------------------------------------------------------------------------
# Pixels
# ----------------------------------------------------------------------------------------------


def _image_pixels(image, space: str):
    """The image's pixels and how to make them scene linear; raises _Fallback or OSError.

    Returns ``(rgb, convert)``: ``rgb`` a float32 (H, W, 3) view, top row first, onto the
    buffer read from Blender (no copy), and ``convert`` None or a function that turns a block
    of it into linear RGB in ``space`` (applied block by block, to bound memory).
    """
    width, height = image.size[:]
    channels = image.channels
    if width == 0 or height == 0 or not image.has_data:
        raise OSError("no pixels could be loaded")
    buf = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(buf)
    pixels = buf.reshape(height, width, channels)[::-1]  # Blender stores the bottom row first
    if channels >= 3:
        rgb = pixels[..., :3]
    else:  # grey (and grey + alpha) images
        rgb = np.broadcast_to(pixels[..., :1], (height, width, 3))
    if image.is_float:  # Blender converts float buffers to scene linear when it loads them
        return rgb, None
    name = image.colorspace_settings.name
    if image.colorspace_settings.is_data or name == "Non-Color":
        return rgb, None  # data: the numbers are used as they are
    if name == "sRGB":
        decode, primaries = _srgb_to_linear, "Linear Rec.709"
    elif name in _LINEAR_SPACES:
        decode, primaries = None, name
    else:
        raise _Fallback(f"image color space '{name}'")
    matrix = _rgb_matrix(primaries, space)
    if matrix is None:
        raise _Fallback(f"image color space '{name}' in working space '{space}'")
    if decode is None and primaries == space:
        return rgb, None

    def convert(block: np.ndarray) -> np.ndarray:
        linear = decode(block) if decode is not None else block.astype(np.float64)
        return linear @ matrix.T if primaries != space else linear

    return rgb, convert


def _downsample_factor(height: int, width: int) -> int:
    """Smallest integer factor dividing both sizes that brings the width to ≤ MAX_PROJECTION_WIDTH."""
    start = max(1, -(-width // MAX_PROJECTION_WIDTH))
    for factor in range(start, 4 * start + 1):
        if height % factor == 0 and width % factor == 0:
            return factor
    return 1  # no divisor nearby: project at full resolution (exact, only slower)


#: Pixels converted and downsampled at a time (bounds the float64 temporaries to ~100 MB).
_BLOCK_PIXELS = 1 << 22


def _project_image(rgb: np.ndarray, l_max: int, convert=None) -> tuple[np.ndarray, int]:
    """Project a top-first equirect (after ``convert``), downsampled to ≤ MAX_PROJECTION_WIDTH.

    The image is processed in strips of whole columns: :func:`hdri.downsample` weighs rows by
    their solid angle, and a column strip keeps every row, so each strip's result is exactly
    that part of the whole image's. NaN/Inf pixels are set to zero and counted at full size.
    """
    height, width = rgb.shape[:2]
    factor = _downsample_factor(height, width)
    step = max(factor, (_BLOCK_PIXELS // max(height, 1)) // factor * factor)
    small = np.empty((height // factor, width // factor, 3), dtype=np.float64)
    rejected = 0
    for c0 in range(0, width, step):
        c1 = min(width, c0 + step)
        block = rgb[:, c0:c1]
        if convert is not None:
            block = convert(block)
        good = np.isfinite(block).all(axis=-1)
        if not good.all():
            rejected += int(good.size - np.count_nonzero(good))
            block = np.where(good[..., None], block, 0.0)
        small[:, c0 // factor : c1 // factor] = hdri.downsample(block, factor)
    coeffs, info = sh.project_equirect(small, l_max, return_info=True)
    return coeffs, rejected + int(info["rejected_pixels"])


def _uses_light_path(tree, seen=None) -> bool:
    seen = seen or set()
    if tree.name_full in seen:
        return False
    seen.add(tree.name_full)
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeLightPath":
            return True
        group = getattr(node, "node_tree", None)
        if group is not None and _uses_light_path(group, seen):
            return True
    return False


# ----------------------------------------------------------------------------------------------
# The cases
# ----------------------------------------------------------------------------------------------


def _constant(l_max: int, rgb) -> np.ndarray:
    coeffs = np.zeros(((l_max + 1) ** 2, 3))
    coeffs[0] = math.sqrt(4.0 * math.pi) * np.asarray(rgb, dtype=np.float64)[:3]
    return coeffs


def _viewport_colour(world, l_max: int, reason: str) -> tuple:
    colour = tuple(world.color) if world is not None else (0.0, 0.0, 0.0)
    source = "viewport color" if world is not None else "no world (black)"
    return _constant(l_max, colour), source, 0, [reason]


def _environment(world, bg, env, l_max: int, space: str):
    """Case 2; raises _Fallback for shapes it does not read directly."""
    if env.mute:
        raise _Fallback("muted Environment Texture")
    if env.projection != "EQUIRECTANGULAR":
        raise _Fallback(f"Environment Texture with {env.projection} projection")
    if bg.inputs["Strength"].is_linked:
        raise _Fallback("a linked Strength")
    strength = float(bg.inputs["Strength"].default_value)
    rotation, parity = _rotation_from_lookup(_lookup_matrix(env))
    image = env.image
    if image is None:
        return _viewport_colour(
            world, l_max, "Environment Texture has no image: using the World's viewport color"
        )
    if image.source not in {"FILE", "GENERATED"}:
        raise _Fallback(f"image source {image.source}")
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
        rgb, convert = _image_pixels(image, space)
    except OSError as exc:
        return _viewport_colour(
            world,
            l_max,
            f"Environment image '{label}' could not be read ({exc}): using the World's viewport color",
        )
    coeffs, rejected = _project_image(rgb, l_max, convert)
    if parity < 0:
        bands = np.repeat(np.arange(l_max + 1), 2 * np.arange(l_max + 1) + 1)
        coeffs = coeffs * np.where(bands % 2 == 1, -1.0, 1.0)[:, None]
    if not np.allclose(rotation, np.eye(3), rtol=0.0, atol=1e-15):
        coeffs = sh.rotation(l_max, rotation.T) @ coeffs
    warnings = []
    if rejected:
        warnings.append(f"Environment image '{label}': {rejected} NaN/Inf pixels left out")
    return coeffs * strength, f"environment texture '{label}'", rejected, warnings


def _panorama(world, l_max: int, reason: str):
    warnings = []
    if _uses_light_path(world.node_tree):
        warnings.append("World uses a Light Path node: its SH is what the camera sees")
    try:
        rgb = render_world_panorama(world)
    except (RuntimeError, OSError) as exc:
        colour, source, _, _ = _viewport_colour(world, l_max, "")
        return colour, source, 0, [f"Could not render the World ({exc}): using its viewport color"]
    coeffs, rejected = _project_image(rgb, l_max)
    if rejected:
        warnings.append(f"World panorama: {rejected} NaN/Inf pixels left out")
    return coeffs, f"panorama render ({reason})", rejected, warnings


def _compute(scene, l_max: int, space: str):
    world = scene.world
    if world is None:
        return _viewport_colour(None, l_max, "Scene has no World: black")
    if not world_uses_nodes(world):
        return _viewport_colour(world, l_max, "World has no nodes: using its viewport color")
    tree = world.node_tree
    output = _active_world_output(tree)
    if output is None or output.mute:
        return (
            _constant(l_max, (0.0, 0.0, 0.0)),
            "no world output (black)",
            0,
            ["World has no active World Output: black"],
        )
    try:
        surface = _linked_from(output.inputs["Surface"])
        if surface is None:
            return (
                _constant(l_max, (0.0, 0.0, 0.0)),
                "nothing connected (black)",
                0,
                ["Nothing is connected to the World Output's Surface: black"],
            )
        bg, _ = surface
        if bg.bl_idname != "ShaderNodeBackground" or bg.mute:
            raise _Fallback(bg.bl_rna.name)
        colour = _linked_from(bg.inputs["Color"])
        if colour is None:
            if bg.inputs["Strength"].is_linked:
                raise _Fallback("a linked Strength")
            rgb = np.array(tuple(bg.inputs["Color"].default_value)[:3]) * bg.inputs["Strength"].default_value
            return _constant(l_max, rgb), "background color", 0, []
        env, out = colour
        if env.bl_idname != "ShaderNodeTexEnvironment" or out.identifier != "Color":
            raise _Fallback(env.bl_rna.name)
        return _environment(world, bg, env, l_max, space)
    except _Fallback as why:
        return _panorama(world, l_max, str(why))


def world_sh(scene, l_max: int = MAX_SH_ORDER, *, cache=None) -> WorldSH:
    """Spherical-harmonic radiance of ``scene``'s World, in world space and scene linear.

    Parameters
    ----------
    scene : bpy.types.Scene
    l_max : int
        Highest band (0 ≤ l_max ≤ :data:`precompute.sh.MAX_L_MAX`).
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
    not from a draw callback (use :func:`.world_key.world_key` there to detect changes).
    """
    l_max = sh._check_l_max(l_max)
    cache = SH_CACHE if cache is None else cache
    key = world_key(scene, l_max)
    hit = cache.get(key)
    if hit is not None:
        return hit
    space = working_space()
    with np.errstate(all="ignore"):  # a NaN or huge Strength is caught below, not warned about
        coeffs, source, rejected, warnings = _compute(scene, l_max, space)
        coeffs = np.array(coeffs, dtype=np.float64)
    errors = ()
    if not _usable(coeffs):  # never NaN lighting: the documented fallback, and why
        world = scene.world
        bad = _bad_values(world) or [
            f"its lighting from {source} is not finite or beyond {MAX_COEFFICIENT:g}"
        ]
        colour, what = fallback_colour(world)
        coeffs = _constant(l_max, colour)
        name = f"World '{world.name}'" if world is not None else "The World"
        errors = (f"{name} cannot be evaluated ({'; '.join(bad)}): lit by {what} instead",)
        source = f"fallback ({what})"
    coeffs.setflags(write=False)
    result = WorldSH(
        coeffs=coeffs,
        source=source,
        key=key,
        rejected_pixels=int(rejected),
        warnings=tuple(w for w in warnings if w),
        l_max=l_max,
        working_space=space,
        errors=errors,
    )
    cache[key] = result
    return result
