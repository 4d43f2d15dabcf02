"""The direct evaluation of a linked thickness: numpy mirrors of Blender's shader nodes.

The nodes in :data:`DIRECT_NODES` — Value, Image Texture at a UV map (Non-Color or linear float
pixels, Linear or Closest, Repeat or Extend), Map Range (linear), Math (the common operations),
Mix (float, or colour Mix), Separate Color (RGB), Reroute, Noise Texture (3-D or 4-D fBm,
normalized, distorted or not: :func:`precompute.materials.perlin.noise_texture`) at Texture
Coordinate's Object or Generated coordinates, Mapping (Point, Texture, Vector), Color Ramp
(any interpolation and colour mode:
sampled through Blender's own ``ColorRamp.evaluate`` into Cycles' table,
:mod:`precompute.materials.ramp`) — are evaluated per face corner exactly as Blender's SVM nodes
compute them (:func:`link_values`); any other node raises :class:`Unsupported`, and
:mod:`.linked` bakes the link with Cycles instead. A colour reaching a float input is converted
as Blender converts it (:func:`converted`): its luminance, a vector's average.
"""

from __future__ import annotations

import numpy as np

from ...precompute.colour import rgb_spaces
from ...precompute.materials import ramp
from ...precompute.materials.perlin import noise_texture
from ..colour_space import working_space
from ..gpu.mesh import corner_positions, corner_vertices
from .generated import texspace_affine

__all__ = [
    "DIRECT_NODES",
    "INLINE_VERTICES",
    "MAP_MAX_SIZE",
    "POSITIONAL_NODES",
    "Unsupported",
    "converted",
    "euler_matrix",
    "corner_uv",
    "link_map",
    "identity_mapping",
    "link_values",
    "luminance_weights",
    "mapping_affine",
    "positional",
    "ramp_table",
    "sample",
    "texel_centres",
    "upstream",
    "uv_layer",
]

#: The largest side of a thickness map evaluated from images (:func:`link_map`): a larger image is
#: sampled at this many texel centres (bilinearly) instead of at each of its pixels.
MAP_MAX_SIZE = 1024

#: Node types evaluated directly (exact numpy mirrors of Blender's SVM nodes); anything else is baked.
DIRECT_NODES = (
    "ShaderNodeValue",
    "ShaderNodeTexImage",
    "ShaderNodeMapRange",
    "ShaderNodeMath",
    "ShaderNodeMix",
    "ShaderNodeSeparateColor",
    "NodeReroute",
    "ShaderNodeTexNoise",
    "ShaderNodeTexCoord",
    "ShaderNodeValToRGB",
    "ShaderNodeMapping",
)
#: Nodes whose value depends on the position on the surface, not on the UVs: a map of them is
#: baked at the UVs (:func:`positional`).
POSITIONAL_NODES = ("ShaderNodeTexNoise", "ShaderNodeTexCoord")
#: A positional link is evaluated inside the draw up to this many vertices (a Noise Texture in
#: numpy: ≈ 30 ms); past it the viewport's timer evaluates it (``linked.evaluate``).
INLINE_VERTICES = 4096
#: Image colour spaces whose pixels Blender reads unchanged (so numpy sees what Cycles sees).
_RAW_SPACES = {"Non-Color", "Linear Rec.709", "Linear CIE-XYZ E", "Raw"}


class Unsupported(Exception):
    """A node the direct evaluator does not mirror: the caller bakes with Cycles instead."""


def uv_layer(mesh, name: str):
    """The UV map an Image Texture reads: ``name`` (a UV Map node's), else the one active for
    rendering, else the active one; ValueError where the mesh has none."""
    layers = mesh.uv_layers
    layer = layers.get(name) if name else None
    if layer is None and not name:
        layer = next((u for u in layers if u.active_render), None) or layers.active
    if layer is None:
        raise ValueError(f"mesh {mesh.name!r} has no UV map {name or '(active)'} for the thickness image")
    return layer


def corner_uv(mesh, layer) -> np.ndarray:
    """(corners, 2) float64 UVs of ``layer`` (a UV map of ``mesh``)."""
    uv = np.empty(2 * len(mesh.loops), dtype=np.float32)
    layer.data.foreach_get("uv", uv)
    return uv.reshape(-1, 2).astype(np.float64)


class _Context:
    """What the direct evaluator reads from the mesh: corner count, UV maps, positions, notes on
    resolution. ``texspace``: the texture space (location, size) of the mesh's Generated
    coordinates (the original mesh's), or None where they cannot be read (a modifier of neither
    kind, an object that is not a mesh); ``orco``: (V, 3) the vertices' positions before a
    deformation, which Generated coordinates are then, else the positions are
    (generated.generated_space)."""

    def __init__(self, mesh, texspace=None, orco=None):
        self.mesh = mesh
        self.n = len(mesh.loops)
        self.notes: list[str] = []
        self.texspace = texspace
        self.orco = orco

    def uv(self, name: str) -> np.ndarray:
        return corner_uv(self.mesh, uv_layer(self.mesh, name))

    def positions(self) -> np.ndarray:
        """The corners' object-space positions (N, 3)."""
        return corner_positions(self.mesh).astype(np.float64)

    def generated(self) -> np.ndarray:
        """The corners' Generated coordinates: positions in the texture space, 0–1 across it (the
        vertices' positions before the deformation where ``orco`` gives them)."""
        if self.texspace is None:
            raise Unsupported("Generated coordinates of a deformed mesh")
        scale, offset = texspace_affine(self.texspace)
        points = self.positions() if self.orco is None else self.orco[corner_vertices(self.mesh)]
        return points * scale + offset


def texel_centres(height: int, width: int) -> np.ndarray:
    """UVs ((i + ½)/W, (j + ½)/H) of a (height, width) map's texel centres, (H·W, 2), row-major
    from v = 0."""
    u, v = np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(height) + 0.5) / height)
    return np.stack([u.ravel(), v.ravel()], axis=1)


class _GridContext(_Context):
    """The direct evaluator at the texel centres of a (height, width) map over UV map ``layer``
    instead of at the mesh's corners (:func:`link_map`)."""

    def __init__(self, mesh, layer: str, shape: tuple[int, int]):
        self.mesh = mesh
        self.layer = layer
        height, width = shape
        self.n = height * width
        self.notes = []
        self.grid = texel_centres(height, width)

    def positions(self) -> np.ndarray:
        raise Unsupported("positions between the corners")

    def uv(self, name: str) -> np.ndarray:
        if uv_layer(self.mesh, name).name != self.layer:
            raise Unsupported("images at two UV maps")
        return self.grid


def _as_float(value: np.ndarray) -> np.ndarray:
    if value.ndim == 2:  # a colour reaches a float input converted (:func:`converted`)
        raise Unsupported("an unconverted colour where a float is read")
    return value


def luminance_weights() -> np.ndarray:
    """The weights of Blender's colour → float conversion in the file's working space: the Y row
    of its RGB → XYZ (D65) matrix, Cycles' ``rgb_to_y`` ((0.2126, 0.7152, 0.0722) in Linear
    Rec.709)."""
    return np.linalg.inv(rgb_spaces.scene_linear_matrix(working_space()))[1]


def converted(value: np.ndarray, source, target) -> np.ndarray:
    """The value of a link from ``source`` as the ``target`` socket receives it, as Blender
    converts it implicitly: a colour into a float input is its luminance
    (:func:`luminance_weights`), a vector its average; anything else unchanged."""
    if value.ndim == 2 and getattr(target, "type", "") == "VALUE":
        if getattr(source, "type", "") == "RGBA":
            return value @ luminance_weights()
        return value.mean(axis=1)
    return value


def _as_colour(value: np.ndarray) -> np.ndarray:
    return value if value.ndim == 2 else np.repeat(value[:, None], 3, axis=1)


def _input(node, key, ctx) -> np.ndarray:
    """The value reaching input ``key`` (name or identifier) of ``node``, per corner."""
    socket = next((s for s in node.inputs if s.identifier == key), None) or node.inputs[key]
    if socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            raise Unsupported("a muted or invalid link")
        return converted(_output(link.from_node, link.from_socket, ctx), link.from_socket, socket)
    value = socket.default_value
    if hasattr(value, "__len__"):
        return np.broadcast_to(np.asarray(tuple(value)[:3], dtype=np.float64), (ctx.n, 3))
    return np.full(ctx.n, float(value))


def _output(node, socket, ctx) -> np.ndarray:
    """The value of ``node``'s output ``socket`` per corner (float (N,) or colour (N, 3))."""
    if node.mute:
        raise Unsupported("a muted node")
    handler = _HANDLERS.get(node.bl_idname)
    if handler is None:
        raise Unsupported(node.bl_idname)
    return handler(node, socket, ctx)


def _value_node(node, socket, ctx):
    return np.full(ctx.n, float(node.outputs[0].default_value))


def _reroute(node, socket, ctx):
    return _input(node, node.inputs[0].identifier, ctx)


def _image_node(node, socket, ctx):
    """Blender's Image Texture at a UV map: pixel centres at (i + ½)/W, bilinear or closest."""
    image = node.image
    if image is None:
        return np.zeros(ctx.n) if socket.identifier == "Alpha" else np.zeros((ctx.n, 3))
    if node.inputs["Vector"].is_linked:
        vector = node.inputs["Vector"].links[0].from_node
        if vector.bl_idname != "ShaderNodeUVMap":
            raise Unsupported("an image texture at mapped coordinates")
        uv = ctx.uv(vector.uv_map)
    else:
        uv = ctx.uv("")
    if node.projection != "FLAT" or node.interpolation not in {"Linear", "Closest"}:
        raise Unsupported(f"image projection {node.projection} / {node.interpolation}")
    if node.extension not in {"REPEAT", "EXTEND"} or image.source not in {"FILE", "GENERATED"}:
        raise Unsupported(f"image extension {node.extension} / source {image.source}")
    space = image.colorspace_settings.name
    if space not in _RAW_SPACES and not (image.is_float and space.startswith("Linear")):
        raise Unsupported(f"image colour space {space}")
    width, height, channels = int(image.size[0]), int(image.size[1]), int(image.channels)
    if width * height == 0 or channels == 0:
        raise ValueError(f"image {image.name!r} has no pixels (is its file missing?)")
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(height, width, channels).astype(np.float64)
    ctx.notes.append(f"image {image.name!r} {width}×{height}")
    sampled = sample(pixels, uv, node.interpolation == "Closest", node.extension == "REPEAT")
    if socket.identifier == "Alpha":
        return sampled[:, 3] if channels == 4 else np.ones(ctx.n)
    rgb = sampled[:, :3] if channels >= 3 else np.repeat(sampled[:, :1], 3, axis=1)
    return rgb


def sample(pixels: np.ndarray, uv: np.ndarray, closest: bool, repeat: bool) -> np.ndarray:
    """Pixels (H, W, C), row 0 at the bottom, at UVs (N, 2): bilinear between pixel centres
    (a GPU texture's linear filter; edges repeated or extended)."""
    height, width = pixels.shape[:2]

    def wrap(i, size):
        return i % size if repeat else np.clip(i, 0, size - 1)

    x, y = uv[:, 0] * width, uv[:, 1] * height
    if closest:
        return pixels[wrap(np.floor(y).astype(np.int64), height), wrap(np.floor(x).astype(np.int64), width)]
    x, y = x - 0.5, y - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb, ya, yb = wrap(x0, width), wrap(x0 + 1, width), wrap(y0, height), wrap(y0 + 1, height)
    return (
        pixels[ya, xa] * (1 - fx) * (1 - fy)
        + pixels[ya, xb] * fx * (1 - fy)
        + pixels[yb, xa] * (1 - fx) * fy
        + pixels[yb, xb] * fx * fy
    )


def _map_range(node, socket, ctx):
    """Map Range (float, linear): (v − from_min)/(from_max − from_min) onto [to_min, to_max]."""
    if node.data_type != "FLOAT" or node.interpolation_type != "LINEAR":
        raise Unsupported(f"Map Range {node.data_type}/{node.interpolation_type}")
    value = _as_float(_input(node, "Value", ctx))
    f0, f1 = _as_float(_input(node, "From Min", ctx)), _as_float(_input(node, "From Max", ctx))
    t0, t1 = _as_float(_input(node, "To Min", ctx)), _as_float(_input(node, "To Max", ctx))
    span = f1 - f0
    factor = np.divide(value - f0, span, out=np.zeros_like(value), where=span != 0.0)  # Blender: 0
    result = t0 + factor * (t1 - t0)
    if node.clamp:
        result = np.clip(result, np.minimum(t0, t1), np.maximum(t0, t1))
    return result


def _safe_divide(a, b):
    return np.divide(a, b, out=np.zeros_like(a), where=b != 0.0)


_MATH = {
    "ADD": lambda a, b, c: a + b,
    "SUBTRACT": lambda a, b, c: a - b,
    "MULTIPLY": lambda a, b, c: a * b,
    "DIVIDE": lambda a, b, c: _safe_divide(a, b),
    "MULTIPLY_ADD": lambda a, b, c: a * b + c,
    "MINIMUM": lambda a, b, c: np.minimum(a, b),
    "MAXIMUM": lambda a, b, c: np.maximum(a, b),
    "ABSOLUTE": lambda a, b, c: np.abs(a),
    "LESS_THAN": lambda a, b, c: (a < b).astype(np.float64),
    "GREATER_THAN": lambda a, b, c: (a > b).astype(np.float64),
}


def _math(node, socket, ctx):
    """Math: the operations in :data:`_MATH`, with Blender's safe division (x/0 = 0) and clamp."""
    operation = _MATH.get(node.operation)
    if operation is None:
        raise Unsupported(f"Math {node.operation}")
    a, b, c = (_as_float(_input(node, node.inputs[i].identifier, ctx)) for i in range(3))
    result = operation(a, b, c)
    return np.clip(result, 0.0, 1.0) if node.use_clamp else result


def _mix(node, socket, ctx):
    """Mix: float, or colour with blend Mix: a + f·(b − a), the factor clamped when asked."""
    if node.data_type == "FLOAT":
        a, b = _as_float(_input(node, "A_Float", ctx)), _as_float(_input(node, "B_Float", ctx))
    elif node.data_type == "RGBA" and node.blend_type == "MIX" and not node.clamp_result:
        a, b = _as_colour(_input(node, "A_Color", ctx)), _as_colour(_input(node, "B_Color", ctx))
    else:
        raise Unsupported(f"Mix {node.data_type}/{getattr(node, 'blend_type', '')}")
    factor = _as_float(_input(node, "Factor_Float", ctx))
    if node.clamp_factor:
        factor = np.clip(factor, 0.0, 1.0)
    if a.ndim == 2:
        factor = factor[:, None]
    return a + factor * (b - a)


def _separate_colour(node, socket, ctx):
    if node.mode != "RGB":
        raise Unsupported(f"Separate Color {node.mode}")
    colour = _as_colour(_input(node, "Color", ctx))
    return colour[:, {"Red": 0, "Green": 1, "Blue": 2}[socket.identifier]]


def _constant(node, name: str, ctx) -> float:
    """An input's value, the same at every corner (a linked one evaluated), else Unsupported."""
    value = _as_float(_input(node, name, ctx))
    if value.size and np.ptp(value) != 0.0:
        raise Unsupported(f"a varying {name} of {node.name!r}")
    return float(value.flat[0]) if value.size else 0.0


def identity_mapping(node) -> bool:
    """Whether a texture node's hidden mapping leaves its coordinates as they are."""
    mapping = node.texture_mapping
    return (
        tuple(mapping.translation) == (0.0, 0.0, 0.0)
        and tuple(mapping.rotation) == (0.0, 0.0, 0.0)
        and tuple(mapping.scale) == (1.0, 1.0, 1.0)
        and (mapping.mapping_x, mapping.mapping_y, mapping.mapping_z) == ("X", "Y", "Z")
        and not (mapping.use_min or mapping.use_max)
    )


def _noise_node(node, socket, ctx):
    """Blender's Noise Texture *Fac*: 3-D or 4-D fBm, normalized, distorted or not."""
    if socket.identifier != "Fac":
        raise Unsupported("a Noise Texture's Color")
    dimensions = {"3D": 3, "4D": 4}.get(node.noise_dimensions)
    if dimensions is None or node.noise_type != "FBM" or not node.normalize:
        raise Unsupported(f"a {node.noise_dimensions} {node.noise_type} Noise Texture")
    if not identity_mapping(node):
        raise Unsupported("a mapped Noise Texture")
    vector = node.inputs["Vector"]
    points = _as_colour(_input(node, "Vector", ctx)) if vector.is_linked else ctx.generated()
    w = _constant(node, "W", ctx) if dimensions == 4 else 0.0
    ctx.notes.append(f"a {dimensions}-D Noise Texture")
    unique, corner = np.unique(points, axis=0, return_inverse=True)  # a vertex's corners share it
    return noise_texture(
        unique,
        w,
        dimensions,
        _constant(node, "Scale", ctx),
        _constant(node, "Detail", ctx),
        _constant(node, "Roughness", ctx),
        _constant(node, "Lacunarity", ctx),
        _constant(node, "Distortion", ctx),
    )[corner.reshape(-1)]


def ramp_table(node) -> tuple[np.ndarray, bool]:
    """(a Color Ramp node's table: (:data:`precompute.materials.ramp.TABLE_SIZE`, 4) RGBA at
    :func:`precompute.materials.ramp.table_positions`, by Blender's own evaluation; whether it
    is read interpolated, as Cycles reads it: not for a *Constant* ramp)."""
    colour_ramp = node.color_ramp
    table = np.array([tuple(colour_ramp.evaluate(float(t))) for t in ramp.table_positions()])
    return table, colour_ramp.interpolation != "CONSTANT"


def _colour_ramp(node, socket, ctx):
    """Color Ramp: its Color or Alpha at Fac, from Cycles' table (:func:`ramp_table`)."""
    table, interpolate = ramp_table(node)
    fac = _as_float(_input(node, "Fac", ctx))
    ctx.notes.append("a Color Ramp")
    if socket.identifier == "Alpha":
        return ramp.lookup(table[:, 3], fac, interpolate)
    return ramp.lookup(table[:, :3], fac, interpolate)


def euler_matrix(rotation) -> np.ndarray:
    """Blender's rotation matrix of XYZ Euler angles (radians): Rz · Ry · Rx."""
    (cx, cy, cz), (sx, sy, sz) = np.cos(rotation), np.sin(rotation)
    return np.array(
        [
            [cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz],
            [cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz],
            [-sy, cy * sx, cy * cx],
        ]
    )


def mapping_affine(vector_type: str, location, rotation, scale) -> tuple[np.ndarray, np.ndarray] | None:
    """(M (3, 3), t (3,)) with a Mapping node's output = M · vector + t, as Cycles' mapping
    computes it: *Point* R (S v) + L, *Texture* (Rᵀ (v − L)) / S (a zero scale gives 0),
    *Vector* R (S v); None for *Normal* (normalized: not affine)."""
    rot = euler_matrix(np.asarray(rotation, dtype=np.float64))
    s = np.asarray(scale, dtype=np.float64)
    loc = np.asarray(location, dtype=np.float64)
    if vector_type == "POINT":
        return rot @ np.diag(s), loc
    if vector_type == "VECTOR":
        return rot @ np.diag(s), np.zeros(3)
    if vector_type == "TEXTURE":
        inverse = np.diag(np.divide(1.0, s, out=np.zeros(3), where=s != 0.0)) @ rot.T
        return inverse, -(inverse @ loc)
    return None


def _vector_constant(node, name: str, ctx) -> np.ndarray:
    """A vector input's value, the same at every corner, else Unsupported."""
    value = _as_colour(_input(node, name, ctx))
    if value.shape[0] and np.ptp(value, axis=0).any():
        raise Unsupported(f"a varying {name} of {node.name!r}")
    return value[0] if value.shape[0] else np.zeros(3)


def _mapping(node, socket, ctx):
    """Mapping (Point, Texture, Vector) of its Vector input, its other inputs constant."""
    names = ("Location", "Rotation", "Scale")
    values = [_vector_constant(node, n, ctx) if node.inputs[n].enabled else np.zeros(3) for n in names]
    found = mapping_affine(node.vector_type, *values)
    if found is None:
        raise Unsupported(f"Mapping {node.vector_type}")
    return _as_colour(_input(node, "Vector", ctx)) @ found[0].T + found[1]  # unlinked: its value


def _texture_coordinate(node, socket, ctx):
    """Texture Coordinate's Object (of the mesh's own object) or Generated output."""
    if socket.identifier == "Object" and node.object is None and not node.from_instancer:
        return ctx.positions()
    if socket.identifier == "Generated" and not node.from_instancer:
        return ctx.generated()
    raise Unsupported(f"Texture Coordinate {socket.identifier}")


_HANDLERS = {
    "ShaderNodeValue": _value_node,
    "NodeReroute": _reroute,
    "ShaderNodeTexImage": _image_node,
    "ShaderNodeMapRange": _map_range,
    "ShaderNodeMath": _math,
    "ShaderNodeMix": _mix,
    "ShaderNodeSeparateColor": _separate_colour,
    "ShaderNodeTexNoise": _noise_node,
    "ShaderNodeTexCoord": _texture_coordinate,
    "ShaderNodeValToRGB": _colour_ramp,
    "ShaderNodeMapping": _mapping,
}


def link_values(mesh, socket, texspace=None, orco=None) -> tuple[np.ndarray, list[str], int]:
    """(the value linked into ``socket`` per face corner of ``mesh``, what it was sampled from,
    the corner count); ``texspace``, ``orco``: :class:`_Context`'s. Raises :class:`Unsupported`
    for a node it does not mirror."""
    ctx = _Context(mesh, texspace, orco)
    link = socket.links[0]
    value = converted(_output(link.from_node, link.from_socket, ctx), link.from_socket, socket)
    return _as_float(value), ctx.notes, ctx.n


def upstream(socket) -> list:
    """The nodes feeding ``socket`` (through any depth), sorted by name (a stable order)."""
    seen, order, stack = set(), [], [link.from_node for link in socket.links if link.is_valid]
    while stack:
        node = stack.pop()
        if node.name in seen:
            continue
        seen.add(node.name)
        order.append(node)
        stack.extend(link.from_node for inp in node.inputs for link in inp.links if link.is_valid)
    return sorted(order, key=lambda n: n.name)


def positional(socket) -> bool:
    """Whether the value reaching ``socket`` depends on the surface position (a Noise Texture, a
    Texture Coordinate): a map of it is baked at the UVs, not evaluated at texels."""
    return any(n.bl_idname in POSITIONAL_NODES for n in upstream(socket))


def _images(socket) -> list:
    """The Image Texture nodes with an image upstream of ``socket``."""
    return [n for n in upstream(socket) if n.bl_idname == "ShaderNodeTexImage" and n.image is not None]


def link_map(mesh, socket) -> tuple[np.ndarray, list[str], str, bool] | None:
    """(the value linked into ``socket`` at the texel centres of a map over one UV map, shape
    (H, W), row 0 at v = 0; notes; that UV map's name; whether the map repeats) where the link
    reads images at one UV map with one extension mode, else None (a constant, or images at two
    UV maps or modes: the corners alone). The map has the largest image's size, each side at
    most :data:`MAP_MAX_SIZE`: where it is the image's, its texels are the image's pixels run
    through the graph, and a GPU's bilinear filter of it is Cycles' of the image wherever the
    graph is linear. Raises :class:`Unsupported` as :func:`link_values` does."""
    images = _images(socket)
    if not images:
        return None
    layers, modes = set(), set()
    for node in images:
        vector = node.inputs["Vector"]
        name = vector.links[0].from_node.uv_map if vector.is_linked else ""
        if vector.is_linked and vector.links[0].from_node.bl_idname != "ShaderNodeUVMap":
            raise Unsupported("an image texture at mapped coordinates")
        layers.add(uv_layer(mesh, name).name)
        modes.add(node.extension)
    if len(layers) != 1 or len(modes) != 1:
        return None
    width = min(MAP_MAX_SIZE, max(int(n.image.size[0]) for n in images))
    height = min(MAP_MAX_SIZE, max(int(n.image.size[1]) for n in images))
    if width * height == 0:
        return None
    layer = layers.pop()
    ctx = _GridContext(mesh, layer, (height, width))
    link = socket.links[0]
    values = _as_float(converted(_output(link.from_node, link.from_socket, ctx), link.from_socket, socket))
    return values.reshape(height, width), ctx.notes, layer, modes.pop() == "REPEAT"
