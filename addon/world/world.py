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
import functools
import math
import os
from dataclasses import dataclass

import numpy as np

from ...precompute import hdri, sh
from ...precompute.material import MAX_SH_ORDER
from .. import caches
from ..colour_space import DEFAULT_WORKING_SPACE, working_space
from .panorama import render_world_panorama
from .world_key import image_path, world_key, world_uses_nodes
from .world_nodes import (
    Fallback,
    active_world_output,
    linked_from,
    lookup_matrix,
    rotation_from_lookup,
    uses_light_path,
)

__all__ = [
    "DEFAULT_CACHE_SIZE",
    "FALLBACK_RADIANCE",
    "MAX_COEFFICIENT",
    "MAX_PROJECTION_WIDTH",
    "SH_CACHE",
    "WorldContent",
    "WorldParams",
    "WorldRead",
    "WorldSH",
    "analyse_read",
    "apply_params",
    "constant_sh",
    "content_scale",
    "finish",
    "read_world",
    "world_parts",
    "fallback_colour",
    "world_sh",
]

#: Images wider than this are downsampled (solid-angle-correct, :func:`hdri.downsample`) before
#: projection. 1024 px across 2π resolves bands far beyond the l ≤ 12 the preview uses.
MAX_PROJECTION_WIDTH = 1024

#: Size of the LRU of results :func:`world_sh` keeps (:data:`SH_CACHE`).
DEFAULT_CACHE_SIZE = 16

_LINEAR_SPACES = ("Linear Rec.709", "Linear Rec.2020", "ACEScg")


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
        from ...precompute import spectra
    except ImportError:
        return None
    try:
        return spectra.rgb_to_rgb_matrix(source, target)
    except ValueError:
        return None


# ----------------------------------------------------------------------------------------------
# Pixels
# ----------------------------------------------------------------------------------------------


def _image_pixels(image, space: str):
    """The image's pixels and how to make them scene linear; raises Fallback or OSError.

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
        raise Fallback(f"image color space '{name}'")
    matrix = _rgb_matrix(primaries, space)
    if matrix is None:
        raise Fallback(f"image color space '{name}' in working space '{space}'")
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


def _project_image(rgb: np.ndarray, l_max: int, convert=None) -> tuple[np.ndarray, int, np.ndarray]:
    """Project a top-first equirect (after ``convert``), downsampled to ≤ MAX_PROJECTION_WIDTH.

    Returns the coefficients, the rejected pixel count and the downsampled image (float64).

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
    return coeffs, rejected + int(info["rejected_pixels"]), small


# ----------------------------------------------------------------------------------------------
# The World's cheap parameters
# ----------------------------------------------------------------------------------------------


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
        (the Mapping in front of an Environment Texture, :func:`_rotation_from_lookup`); the
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


def _background(world):
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
    out = sh.rotation(l_max, np.asarray(rotation, dtype=np.float64).reshape(3, 3).T)
    out.setflags(write=False)
    return out


def _parameters(world) -> tuple[WorldParams, list]:
    """The World's cheap parameters and the (node, input) pairs they are read from."""
    bg = _background(world)
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
    params, without = _parameters(scene.world)
    return world_key(scene, l_max, without=without), params


def apply_params(coeffs, params: WorldParams, scale: float | None, turned: bool) -> np.ndarray:
    """Content SH → the World's: turned by the parameters' rotation (when ``turned``: the content
    is the image as read) and multiplied by ``scale`` (None: 1). Exact: SH rotations are."""
    c = np.asarray(coeffs, dtype=np.float64)
    l_max = sh.l_max_from_size(c.shape[0])
    if turned and params.parity < 0:
        bands = np.repeat(np.arange(l_max + 1), 2 * np.arange(l_max + 1) + 1)
        c = c * np.where(bands % 2 == 1, -1.0, 1.0)[:, None]
    p = np.asarray(params.rotation, dtype=np.float64).reshape(3, 3)
    if turned and not np.allclose(p, np.eye(3), rtol=0.0, atol=1e-15):
        c = _sh_rotation(l_max, tuple(params.rotation)) @ c
    return c * scale if scale is not None else c


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
        rgb, convert = _image_pixels(image, space)
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
    l_max = sh._check_l_max(l_max)
    params = _parameters(scene.world)[0] if params is None else params
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
        coeffs, rejected, small = _project_image(read.rgb, l_max, read.convert)
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
    not from a draw callback (use :func:`.world_key.world_key` there to detect changes). The
    viewport does the same in three steps, the slow one on a worker (:mod:`.world_job`):
    :func:`read_world`, :func:`analyse_read`, :func:`finish`.
    """
    l_max = sh._check_l_max(l_max)
    cache = SH_CACHE if cache is None else cache
    key = world_key(scene, l_max)
    hit = cache.get(key)
    if hit is not None:
        return hit
    params = _parameters(scene.world)[0]
    result = finish(scene, analyse_read(read_world(scene, l_max, params), l_max), params, key, l_max)
    cache[key] = result
    return result
