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

Results are cached (:data:`SH_CACHE`) by :func:`world_key`, a content hash of everything that
affects them (the node tree with all settings and links, image files' path/size/mtime, l_max,
the working space) computed without reading any pixels, so the draw code can poll it cheaply.

Mapping and rotation
--------------------
The Environment Texture looks the image up at the direction d' = M d, where M is the Mapping
node's transform (POINT/VECTOR: d' ∝ R·S·d (+ location), TEXTURE: d' ∝ S⁻¹·Rᵀ·(d − location),
NORMAL: d' ∝ R·S⁻¹·d; R from the Euler XYZ rotation). With a uniform positive scale and no
location offset M is a rotation Q (up to a positive factor that the normalisation removes), so
L(d) = I(Q d) = I∘(Qᵀ)⁻¹, whose coefficients are ``sh.rotation(l_max, Qᵀ) @ c_I``. A uniform
negative scale adds a point reflection, (−1)^l per band.

The panorama camera sits at the origin with rotation Euler (90°, 0, −90°): Blender's panorama
camera looks along its −Z axis with +Y up, so this turns its view to world +X with +Z up and
the rendered equirect then follows the Environment Texture convention (image centre = +X,
u = ¼ = +Y). ``tests/test_world.py`` proves it against direct projection.

Only this module talks to ``bpy``; the maths is in ``precompute``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile

import bpy
import numpy as np
from mathutils import Euler

from ..precompute import hdri, sh, table_io
from ..precompute.material import MAX_SH_ORDER
from . import caches

__all__ = [
    "DEFAULT_CACHE_SIZE",
    "MAX_PROJECTION_WIDTH",
    "PANORAMA_SAMPLES",
    "PANORAMA_WIDTH",
    "SH_CACHE",
    "WorldSH",
    "render_world_panorama",
    "working_space",
    "world_key",
    "world_sh",
]

#: Version of the key description; bump when the computation changes so old entries miss.
KEY_VERSION = 1

#: Images wider than this are downsampled (solid-angle-correct, :func:`hdri.downsample`) before
#: projection. 1024 px across 2π resolves bands far beyond the l ≤ 12 the preview uses.
MAX_PROJECTION_WIDTH = 1024

#: Panorama fallback: resolution (width; height = width/2) and Cycles samples per pixel.
#: At 256×128 and 32 samples bands 0–2 of the studio HDRIs agree with direct projection to
#: ~0.1–2 % of the l = 0 term (the error is the noise of tiny bright suns); a render takes 1–2 s.
PANORAMA_WIDTH = 256
PANORAMA_SAMPLES = 32

#: Size of the LRU of results :func:`world_sh` keeps (:data:`SH_CACHE`).
DEFAULT_CACHE_SIZE = 16

#: Rotation of the panorama camera that makes its equirect match the Environment Texture's.
PANORAMA_CAMERA_ROTATION = (math.pi / 2.0, 0.0, -math.pi / 2.0)

_DEFAULT_WORKING_SPACE = "Linear Rec.709"
_LINEAR_SPACES = ("Linear Rec.709", "Linear Rec.2020", "ACEScg")
_MAX_DESCRIBE_DEPTH = 4
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
        How they were obtained, e.g. "environment texture 'studio.exr'", "background colour",
        "panorama render (Sky Texture)", "viewport colour".
    key : str
        :func:`world_key` of the inputs (16 hex digits).
    rejected_pixels : int
        NaN/Inf pixels of the image or panorama that were left out (counted at full resolution).
    warnings : tuple of str
        Problems the user should know about (missing image, no World, ...).
    l_max : int
    working_space : str
        The blend file's working (scene linear) colour space, e.g. "Linear Rec.709".
    """

    coeffs: np.ndarray
    source: str
    key: str
    rejected_pixels: int = 0
    warnings: tuple = ()
    l_max: int = 8
    working_space: str = _DEFAULT_WORKING_SPACE


#: World SH results by :func:`world_key` (see :mod:`.caches`).
SH_CACHE = caches.register("world_sh", caches.LRU(DEFAULT_CACHE_SIZE), scope=caches.SESSION)


# ----------------------------------------------------------------------------------------------
# Colour space
# ----------------------------------------------------------------------------------------------


def working_space() -> str:
    """The blend file's working colour space (scene linear), e.g. "Linear Rec.709".

    Blender 5.x stores it per file in ``bpy.data.colorspace.working_space`` ("Linear Rec.709",
    "Linear Rec.2020" or "ACEScg"); older versions have none and use Linear Rec.709.
    """
    colorspace = getattr(bpy.data, "colorspace", None)
    name = getattr(colorspace, "working_space", "") if colorspace is not None else ""
    return name or _DEFAULT_WORKING_SPACE


def _srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding (the piecewise curve of Blender's "sRGB" space)."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((np.maximum(v, 0.04045) + 0.055) / 1.055) ** 2.4)


def _rgb_matrix(source: str, target: str) -> np.ndarray | None:
    """Linear RGB → RGB matrix between two working spaces, or None if it cannot be built here."""
    if source == target:
        return np.eye(3)
    try:  # colour-science is only needed for non-Rec.709 working spaces
        from ..precompute import spectra
    except ImportError:
        return None
    try:
        return spectra.rgb_to_rgb_matrix(source, target)
    except ValueError:
        return None


# ----------------------------------------------------------------------------------------------
# Keys: a cheap canonical description of everything that affects the result
# ----------------------------------------------------------------------------------------------


def _node_ui_properties() -> frozenset:
    base = {p.identifier for p in bpy.types.Node.bl_rna.properties}
    return frozenset(base - {"name", "mute"})


_SKIP_NODE_PROPS = _node_ui_properties()
_SKIP_STRUCT_PROPS = frozenset({"rna_type", "select", "select_left_handle", "select_right_handle"})


def _plain(value):
    """A bpy/mathutils value as JSON-friendly data (NaN/Inf become strings)."""
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else repr(value)
    if isinstance(value, set | frozenset):
        return sorted(str(v) for v in value)
    if isinstance(value, bpy.types.ID):
        return {"id": type(value).__name__, "name": value.name_full}
    try:
        return [_plain(v) for v in value]
    except TypeError:
        return repr(value)


def _file_stat(path: str):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]


def _image_path(image) -> str:
    return bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""


def _describe_image(image) -> dict:
    """What identifies an image's pixels, without loading them."""
    desc = {
        "name": image.name_full,
        "source": image.source,
        "filepath": image.filepath,
        "colorspace": image.colorspace_settings.name,
        "alpha_mode": image.alpha_mode,
        "is_dirty": bool(image.is_dirty),
    }
    if image.packed_file is not None:
        desc["packed_size"] = image.packed_file.size
    elif image.source in {"FILE", "SEQUENCE", "MOVIE", "TILED"}:
        path = _image_path(image)
        desc["abspath"] = path
        desc["stat"] = _file_stat(path)
    if image.source == "GENERATED":
        desc["generated"] = [
            image.generated_type,
            image.generated_width,
            image.generated_height,
            _plain(image.generated_color),
            bool(image.use_generated_float),
        ]
    return desc


def _describe_struct(struct, depth: int, seen: set, skip=_SKIP_STRUCT_PROPS) -> dict:
    """Every RNA property of ``struct`` (values, nested structs, collections, referenced IDs)."""
    out = {}
    for prop in struct.bl_rna.properties:
        ident = prop.identifier
        if ident in skip or ident.startswith("bl_"):
            continue
        try:
            value = getattr(struct, ident)
        except (AttributeError, RuntimeError, TypeError):
            continue
        if prop.type == "POINTER":
            out[ident] = _describe_pointer(value, depth, seen)
        elif prop.type == "COLLECTION":
            if depth <= 0:
                out[ident] = len(value)
            else:
                out[ident] = [_describe_pointer(item, depth, seen) for item in value]
        else:
            out[ident] = _plain(value)
    return out


def _describe_pointer(value, depth: int, seen: set):
    if value is None:
        return None
    if isinstance(value, bpy.types.Image):
        return _describe_image(value)
    if isinstance(value, bpy.types.NodeTree):
        return _describe_tree(value, seen)
    if isinstance(value, bpy.types.Object):
        return {"object": value.name_full, "matrix_world": _plain(value.matrix_world)}
    if isinstance(value, bpy.types.ID):
        return _plain(value)
    if depth <= 0:
        return type(value).__name__
    return _describe_struct(value, depth - 1, seen)


def _socket_value(socket):
    return _plain(socket.default_value) if hasattr(socket, "default_value") else None


def _describe_tree(tree, seen: set) -> dict | str:
    """Nodes (type, settings, socket values) and links of a node tree, node groups included."""
    if tree.name_full in seen:
        return {"tree": tree.name_full}
    seen = seen | {tree.name_full}
    nodes = {}
    for node in tree.nodes:
        desc = _describe_struct(node, _MAX_DESCRIBE_DEPTH, seen, skip=_SKIP_NODE_PROPS | _SKIP_STRUCT_PROPS)
        desc["bl_idname"] = node.bl_idname
        desc["inputs"] = [[s.identifier, _socket_value(s)] for s in node.inputs]
        desc["outputs"] = [[s.identifier, _socket_value(s)] for s in node.outputs]
        nodes[node.name] = desc
    links = sorted(
        [
            link.from_node.name,
            link.from_socket.identifier,
            link.to_node.name,
            link.to_socket.identifier,
            bool(link.is_muted),
            bool(link.is_valid),
        ]
        for link in tree.links
    )
    return {"tree": tree.name_full, "nodes": nodes, "links": links}


def _world_uses_nodes(world) -> bool:
    if world.node_tree is None:
        return False
    if bpy.app.version >= (5, 0, 0):  # use_nodes is deprecated and always on since 5.0
        return True
    return bool(world.use_nodes)


def _describe_world(world) -> dict | None:
    if world is None:
        return None
    desc = {"color": _plain(world.color), "use_nodes": _world_uses_nodes(world)}
    if desc["use_nodes"]:
        desc["tree"] = _describe_tree(world.node_tree, set())
    return desc


def world_key(scene, l_max: int = 8) -> str:
    """Content hash of everything :func:`world_sh` depends on; cheap (reads no pixels).

    Covers the World's node tree (every node setting, socket value and link, node groups and
    referenced objects), images (path, size and mtime of the file, or packed size; generated
    settings), the World's viewport colour, ``l_max`` and the working space. Edits to an
    image's pixels inside Blender are seen only through ``is_dirty`` (once).
    """
    description = {
        "version": KEY_VERSION,
        "l_max": int(l_max),
        "working_space": working_space(),
        "world": _describe_world(scene.world),
    }
    return table_io.content_key(description)


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
        raise _Fallback(f"image colour space '{name}'")
    matrix = _rgb_matrix(primaries, space)
    if matrix is None:
        raise _Fallback(f"image colour space '{name}' in working space '{space}'")
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


# ----------------------------------------------------------------------------------------------
# Panorama render
# ----------------------------------------------------------------------------------------------


def render_world_panorama(world, width: int = PANORAMA_WIDTH, samples: int = PANORAMA_SAMPLES) -> np.ndarray:
    """Render ``world`` alone as an equirect panorama with Cycles on the CPU.

    A temporary scene sharing the World (no objects) with a panorama camera at the origin is
    rendered to a 32-bit OpenEXR (scene linear) in a temporary folder and read back through
    Blender; the scene, camera and image are removed again, nothing else is touched. Must not
    be called from a draw callback (it runs the render operator).

    Returns
    -------
    ndarray, shape (width/2, width, 3), float32
        Scene-linear radiance, top row first, in the Environment Texture's equirect convention.
    """
    width = int(width)
    height = max(1, width // 2)
    had_render_result = "Render Result" in bpy.data.images
    scene = bpy.data.scenes.new(".thinfilm_sh panorama")
    cam_data = obj = image = None
    try:
        scene.world = world
        scene.render.engine = "CYCLES"
        if scene.render.engine != "CYCLES":
            raise RuntimeError("Cycles is not available")
        cycles = scene.cycles
        cycles.device = "CPU"
        cycles.samples = int(samples)
        cycles.use_adaptive_sampling = False
        cycles.use_denoising = False
        cycles.seed = 0
        scene.render.resolution_x = width
        scene.render.resolution_y = height
        scene.render.resolution_percentage = 100
        scene.render.film_transparent = False
        scene.render.use_compositing = False
        scene.render.use_sequencer = False
        scene.render.use_border = False
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.look = "None"
        scene.view_settings.exposure = 0.0
        scene.view_settings.gamma = 1.0
        settings = scene.render.image_settings
        settings.file_format = "OPEN_EXR"
        settings.color_depth = "32"
        settings.color_mode = "RGB"
        settings.color_management = "FOLLOW_SCENE"

        cam_data = bpy.data.cameras.new(".thinfilm_sh panorama")
        cam_data.type = "PANO"
        cam_data.panorama_type = "EQUIRECTANGULAR"
        cam_data.latitude_min, cam_data.latitude_max = -math.pi / 2.0, math.pi / 2.0
        cam_data.longitude_min, cam_data.longitude_max = -math.pi, math.pi
        obj = bpy.data.objects.new(".thinfilm_sh panorama", cam_data)
        obj.location = (0.0, 0.0, 0.0)
        obj.rotation_euler = PANORAMA_CAMERA_ROTATION
        scene.collection.objects.link(obj)
        scene.camera = obj

        with tempfile.TemporaryDirectory(prefix="thinfilm_sh_") as folder:
            path = os.path.join(folder, "world.exr")
            scene.render.filepath = path
            bpy.ops.render.render(write_still=True, scene=scene.name)
            if not os.path.isfile(path):
                raise RuntimeError("the panorama render wrote no image")
            image = bpy.data.images.load(path, check_existing=False)
            image.colorspace_settings.name = working_space()
            w, h = image.size[:]
            buf = np.empty(w * h * image.channels, dtype=np.float32)
            image.pixels.foreach_get(buf)
            rgb = np.ascontiguousarray(buf.reshape(h, w, image.channels)[::-1, :, :3])
    finally:
        if image is not None:
            bpy.data.images.remove(image)
        bpy.data.scenes.remove(scene)
        if obj is not None:
            bpy.data.objects.remove(obj)
        if cam_data is not None:
            bpy.data.cameras.remove(cam_data)
        if not had_render_result and "Render Result" in bpy.data.images:
            bpy.data.images.remove(bpy.data.images["Render Result"])
    return rgb


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
    source = "viewport colour" if world is not None else "no world (black)"
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
            world, l_max, "Environment Texture has no image: using the World's viewport colour"
        )
    if image.source not in {"FILE", "GENERATED"}:
        raise _Fallback(f"image source {image.source}")
    label = os.path.basename(image.filepath) if image.filepath else image.name
    if image.source == "FILE" and image.packed_file is None:
        path = _image_path(image)
        if not os.path.isfile(path):
            return _viewport_colour(
                world,
                l_max,
                f"Environment image '{label}' not found ({path}): using the World's viewport colour",
            )
    try:
        rgb, convert = _image_pixels(image, space)
    except OSError as exc:
        return _viewport_colour(
            world,
            l_max,
            f"Environment image '{label}' could not be read ({exc}): using the World's viewport colour",
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
        return colour, source, 0, [f"Could not render the World ({exc}): using its viewport colour"]
    coeffs, rejected = _project_image(rgb, l_max)
    if rejected:
        warnings.append(f"World panorama: {rejected} NaN/Inf pixels left out")
    return coeffs, f"panorama render ({reason})", rejected, warnings


def _compute(scene, l_max: int, space: str):
    world = scene.world
    if world is None:
        return _viewport_colour(None, l_max, "Scene has no World: black")
    if not _world_uses_nodes(world):
        return _viewport_colour(world, l_max, "World has no nodes: using its viewport colour")
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
            return _constant(l_max, rgb), "background colour", 0, []
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
        Anything with ``get`` and item assignment, keyed by :func:`world_key`; default
        :data:`SH_CACHE`, an LRU of :data:`DEFAULT_CACHE_SIZE` entries. Cached results are
        returned as they are (the same object; its array is read-only).

    Returns
    -------
    WorldSH

    Notes
    -----
    Never raises for odd Worlds: missing World, nodes, images or failing renders fall back
    to the viewport colour (or black) with a warning. The panorama route runs the render
    operator, so call this from an operator, timer or handler, not from a draw callback
    (use :func:`world_key` there to detect changes).
    """
    l_max = sh._check_l_max(l_max)
    cache = SH_CACHE if cache is None else cache
    key = world_key(scene, l_max)
    hit = cache.get(key)
    if hit is not None:
        return hit
    space = working_space()
    coeffs, source, rejected, warnings = _compute(scene, l_max, space)
    coeffs = np.array(coeffs, dtype=np.float64)
    coeffs.setflags(write=False)
    result = WorldSH(
        coeffs=coeffs,
        source=source,
        key=key,
        rejected_pixels=int(rejected),
        warnings=tuple(w for w in warnings if w),
        l_max=l_max,
        working_space=space,
    )
    cache[key] = result
    return result
