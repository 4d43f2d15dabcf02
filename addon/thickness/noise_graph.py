"""A Noise Texture linked into a Principled BSDF's Thin Film Thickness, drawn per pixel.

The usual procedural film, Noise Texture (→ Map Range) → *Thin Film Thickness*, needs no map:
the shader computes Blender's Noise Texture at each pixel from the object-space position
(``tf_perlin.glsl``, :class:`precompute.materials.perlin.NoiseSpec`), with no bake, no UVs and
no resolution limit. :func:`recognise` reads such a link: a Noise Texture the direct evaluator
mirrors (:mod:`.linked_nodes`: fBm, 3-D or 4-D, normalized, distorted or not, identity mapping;
its inputs unlinked), at Texture Coordinate's Object or Generated coordinates, through Mapping
nodes (Point, Texture, Vector; folded into a matrix) or not (Generated, the
default, in the original mesh's texture space; after Deform modifiers or shape keys where the
vertices were before them: ``generated.generated_space``), optionally through a Color Ramp (its
Color's luminance or its Alpha, read from Cycles' table of it: ``TF_THICKNESS_RAMP``), then
through any chain of linear Map Ranges and affine Math nodes (Add, Subtract, Multiply, Divide by
a constant, Multiply Add; clamped or not) with unlinked other inputs, folded into one gain, bias
and clamp, and Reroutes. Anything else is evaluated per corner and baked into a map as before
(:mod:`.linked`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ...precompute.materials.perlin import NoiseSpec
from .generated import texspace_affine
from .linked_nodes import identity_mapping, luminance_weights, mapping_affine, ramp_table

__all__ = ["NoiseGraph", "recognise"]


@dataclass(frozen=True)
class NoiseGraph:
    """A recognised link: the Noise Texture (``noise``: its Fac, or its Color Ramp's value at Fac
    where ``noise.ramp`` holds the table; gain 1, bias 0, unclamped) and the thickness it gives,
    ``a`` · x + ``b`` nm, clamped to [``low``, ``high``] nm, of that value x."""

    noise: NoiseSpec
    a: float = 1.0
    b: float = 0.0
    low: float = -math.inf
    high: float = math.inf

    def nm_range(self) -> tuple[float, float]:
        """The thickness over Fac in [0, 1] (the normalized fBm's range; a ramp's values there),
        in nm."""
        x = (min(self.noise.ramp), max(self.noise.ramp)) if self.noise.ramp else (0.0, 1.0)
        ends = np.clip([self.a * x[0] + self.b, self.a * x[1] + self.b], self.low, self.high)
        return float(ends.min()), float(ends.max())

    def spec(self, thickness_range) -> NoiseSpec:
        """The noise for the shader: Fac to the parameter along the table's ``thickness_range``."""
        lo, hi = (float(v) for v in thickness_range)
        span = max(hi - lo, 1e-9)
        low = -1e30 if math.isinf(self.low) else (self.low - lo) / span
        high = 1e30 if math.isinf(self.high) else (self.high - lo) / span
        return replace(self.noise, gain=self.a / span, bias=(self.b - lo) / span, low=low, high=high)


def _source(socket):
    """The node and output socket feeding ``socket`` through Reroutes, or None."""
    while socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted or link.from_node.mute:
            return None
        node = link.from_node
        if node.bl_idname != "NodeReroute":
            return node, link.from_socket
        socket = node.inputs[0]
    return None


def _constants(node, names) -> list[float] | None:
    """The inputs' values, or None where one is linked (an input the node lacks reads 0)."""
    sockets = [node.inputs.get(name) for name in names]
    if any(s is not None and s.is_linked for s in sockets):
        return None
    return [0.0 if s is None else float(s.default_value) for s in sockets]


def _map_range(node) -> tuple[float, float, float, float] | None:
    """(a, b, low, high): a linear float Map Range's output as a · value + b, clamped or not."""
    if node.data_type != "FLOAT" or node.interpolation_type != "LINEAR":
        return None
    values = _constants(node, ("From Min", "From Max", "To Min", "To Max"))
    if values is None or values[1] == values[0]:
        return None
    from_min, from_max, to_min, to_max = values
    a = (to_max - to_min) / (from_max - from_min)
    low, high = (min(to_min, to_max), max(to_min, to_max)) if node.clamp else (-math.inf, math.inf)
    return a, to_min - from_min * a, low, high


def _math(node):
    """(a, b, low, high, the linked input) of a Math node that is affine in its one linked
    input (Add, Subtract, Multiply, Divide by a constant, Multiply Add; its Clamp to [0, 1]), or
    None."""
    count = 3 if node.operation == "MULTIPLY_ADD" else 2
    inputs = list(node.inputs)[:count]
    linked = [i for i, s in enumerate(inputs) if s.is_linked]
    if node.operation not in _AFFINE or len(linked) != 1:
        return None
    k = linked[0]
    c = [0.0 if s.is_linked else float(s.default_value) for s in inputs]
    found = _AFFINE[node.operation](k, c)
    if found is None:
        return None
    low, high = (0.0, 1.0) if node.use_clamp else (-math.inf, math.inf)
    return (*found, low, high, inputs[k])


#: Math operations affine in input k, the others' values c: (a, b) of a · x + b, or None.
_AFFINE = {
    "ADD": lambda k, c: (1.0, c[1 - k]),
    "SUBTRACT": lambda k, c: (1.0, -c[1]) if k == 0 else (-1.0, c[0]),
    "MULTIPLY": lambda k, c: (c[1 - k], 0.0),
    "DIVIDE": lambda k, c: (1.0 / c[1], 0.0) if k == 0 and c[1] != 0.0 else None,
    "MULTIPLY_ADD": lambda k, c: (c[1], c[2]) if k == 0 else ((c[0], c[2]) if k == 1 else (0.0, c[0] * c[1])),
}


def _inner(outer: tuple, inner: tuple) -> tuple:
    """The composition g ∘ f of g(y) = clamp(a y + b, low, high) (``outer``) and f (``inner``,
    the same form) as that form: the inner clamp's ends mapped through g and clamped by g's."""
    a, b, low, high = outer
    a1, b1, l1, h1 = inner
    if a == 0.0:
        return outer
    ends = sorted(a * e + b for e in (l1, h1))
    return a * a1, a * b1 + b, min(max(ends[0], low), high), min(max(ends[1], low), high)


def _mapping(node) -> tuple[np.ndarray, np.ndarray] | None:
    """(M, t) of a Mapping node with unlinked Location, Rotation and Scale
    (:func:`.linked_nodes.mapping_affine`), or None."""
    names = [n for n in ("Location", "Rotation", "Scale") if node.inputs[n].enabled]
    if any(node.inputs[n].is_linked for n in names):
        return None
    values = {n: tuple(node.inputs[n].default_value) for n in names}
    zero = (0.0, 0.0, 0.0)
    return mapping_affine(node.vector_type, *(values.get(n, zero) for n in ("Location", "Rotation", "Scale")))


def _coordinates(vector, texspace) -> tuple[np.ndarray, np.ndarray, bool] | None:
    """(M (3, 3), t (3,), whether they are Generated): the coordinates reaching the Noise
    Texture's ``vector`` input as M · p + t of the object-space position p, through Mappings, or
    None."""
    found = _source(vector)
    if found is not None and found[0].bl_idname == "ShaderNodeMapping":
        inner_vector = found[0].inputs["Vector"]  # unlinked: a constant, not Generated
        inner = _coordinates(inner_vector, texspace) if inner_vector.is_linked else None
        outer = _mapping(found[0])
        if outer is None or inner is None:
            return None
        return outer[0] @ inner[0], outer[0] @ inner[1] + outer[1], inner[2]
    if vector.is_linked:
        if found is None or found[0].bl_idname != "ShaderNodeTexCoord":
            return None
        coords, output = found
        if coords.object is not None or coords.from_instancer:
            return None
        if output.identifier == "Object":
            return np.eye(3), np.zeros(3), False
        if output.identifier != "Generated":
            return None
    if texspace is None:  # Generated coordinates of no mesh's (generated.generated_space)
        return None
    scale, offset = texspace_affine(texspace)
    return np.diag(scale), offset, True


def recognise(socket, texspace, orco: bool = False) -> NoiseGraph | None:
    """The link into ``socket`` as a :class:`NoiseGraph`, or None where the shader cannot compute
    it per pixel. ``texspace``: (location, size) of the texture space of the mesh's Generated
    coordinates (``generated.generated_space``), or None; ``orco``: they are where the vertices
    were before a deformation, not the positions (the spec's ``orco``)."""
    found = _source(socket)
    affine = (1.0, 0.0, -math.inf, math.inf)
    while found is not None and found[0].bl_idname in ("ShaderNodeMapRange", "ShaderNodeMath"):
        node = found[0]
        if node.bl_idname == "ShaderNodeMapRange":
            step, value = _map_range(node), node.inputs["Value"]
            if step is None or found[1].identifier != "Result":
                return None
        else:
            math_step = _math(node)
            if math_step is None:
                return None
            step, value = math_step[:4], math_step[4]
        affine = _inner(affine, step)
        found = _source(value)
    a, b, low, high = affine
    table, interpolate = (), True
    if found is not None and found[0].bl_idname == "ShaderNodeValToRGB":
        rgba, interpolate = ramp_table(found[0])
        x = rgba[:, 3] if found[1].identifier == "Alpha" else rgba[:, :3] @ luminance_weights()
        table = tuple(float(v) for v in x)
        found = _source(found[0].inputs["Fac"])
    if found is None or found[0].bl_idname != "ShaderNodeTexNoise" or found[1].identifier != "Fac":
        return None
    noise = found[0]
    dimensions = {"3D": 3, "4D": 4}.get(noise.noise_dimensions)
    if dimensions is None or noise.noise_type != "FBM" or not noise.normalize or not identity_mapping(noise):
        return None
    names = ("Scale", "Detail", "Roughness", "Lacunarity", "Distortion", "W")
    values = _constants(noise, names)
    coordinates = _coordinates(noise.inputs["Vector"], texspace)
    if values is None or coordinates is None:
        return None
    scale, detail, roughness, lacunarity, distortion, w = values
    spec = NoiseSpec(
        dimensions=dimensions,
        scale=scale,
        w=w if dimensions == 4 else 0.0,
        detail=detail,
        roughness=roughness,
        lacunarity=lacunarity,
        space_offset=tuple(float(v) for v in coordinates[1]),
        low=-1e30,
        high=1e30,
        ramp=table,
        ramp_interpolate=interpolate,
        distortion=distortion,
        space_matrix=tuple(float(v) for v in coordinates[0].ravel()),
        orco=orco and coordinates[2],
    )
    return NoiseGraph(spec, a, b, low, high)
