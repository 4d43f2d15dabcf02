"""The extension's thickness sources as Blender shader nodes.

:func:`build` writes the graph that gives a Principled BSDF's *Thin Film Thickness* the same
variation the preview draws, so Cycles renders it too (write-back,
:func:`.principled.write_back_to_principled`):

- BLENDER_NOISE and NOISE: Texture Coordinate (Object) → Noise Texture (4-D, W = seed, the
  scale) → Map Range (0–1 → min–max). BLENDER_NOISE *is* this node's value in the preview
  (``precompute.materials.perlin``, ``glsl/tf_perlin.glsl``: the node as Cycles computes it),
  so the two match; the extension's own value noise (NOISE) has another pattern of the same
  scale.
- IMAGE: UV Map → Image Texture (Linear, Repeat) → Separate Color (Red) → Map Range: exactly
  the preview's bilinear first channel.
- ATTRIBUTE: Attribute (the name) → Map Range (clamped, as the preview clips to [0, 1]).

Every node it makes is named with :data:`PREFIX`, so writing again replaces the old graph.
"""

from __future__ import annotations

__all__ = ["NOISE_DETAIL", "PREFIX", "build", "remove"]

#: Names of the nodes written for the thickness (removed before writing again).
PREFIX = "TFSH Thickness"
#: The Noise Texture's Detail, Roughness and Lacunarity (Blender's defaults).
NOISE_DETAIL, NOISE_ROUGHNESS, NOISE_LACUNARITY = 2.0, 0.5, 2.0


def remove(tree) -> None:
    """Remove the nodes an earlier :func:`build` wrote."""
    for node in [n for n in tree.nodes if n.name.startswith(PREFIX)]:
        tree.nodes.remove(node)


def _node(tree, kind: str, role: str, x: float, y: float):
    node = tree.nodes.new(kind)
    node.name = node.label = f"{PREFIX} {role}"
    node.location = (x, y)
    return node


def _noise(tree, props, x, y):
    coords = _node(tree, "ShaderNodeTexCoord", "Coordinates", x - 600, y)
    noise = _node(tree, "ShaderNodeTexNoise", "Noise", x - 400, y)
    noise.noise_dimensions = "4D"
    noise.inputs["W"].default_value = float(props.noise_seed)
    noise.inputs["Scale"].default_value = float(props.noise_scale)
    noise.inputs["Detail"].default_value = NOISE_DETAIL
    noise.inputs["Roughness"].default_value = NOISE_ROUGHNESS
    noise.inputs["Lacunarity"].default_value = NOISE_LACUNARITY
    tree.links.new(coords.outputs["Object"], noise.inputs["Vector"])
    return noise.outputs["Fac"]


def _image(tree, props, x, y):
    texture = _node(tree, "ShaderNodeTexImage", "Image", x - 500, y)
    texture.image = props.thickness_image
    texture.interpolation = "Linear"
    texture.extension = "REPEAT"
    if props.thickness_uv_map:
        uv = _node(tree, "ShaderNodeUVMap", "UV", x - 700, y)
        uv.uv_map = props.thickness_uv_map
        tree.links.new(uv.outputs["UV"], texture.inputs["Vector"])
    separate = _node(tree, "ShaderNodeSeparateColor", "Channel", x - 250, y)
    tree.links.new(texture.outputs["Color"], separate.inputs["Color"])
    return separate.outputs["Red"]


def _attribute(tree, props, x, y):
    attribute = _node(tree, "ShaderNodeAttribute", "Attribute", x - 400, y)
    attribute.attribute_name = props.thickness_attribute
    return attribute.outputs["Fac"]


_SOURCES = {"BLENDER_NOISE": _noise, "NOISE": _noise, "IMAGE": _image, "ATTRIBUTE": _attribute}


def build(tree, props, lo: float, hi: float, location=(0.0, 0.0)):
    """Write ``props``' thickness source into ``tree`` as nodes; returns the Map Range output
    (thickness in nm, ``lo`` + value·(``hi`` − ``lo``)) for the caller to link."""
    remove(tree)
    x, y = location
    value = _SOURCES[props.thickness_source](tree, props, x - 200, y)
    ranged = _node(tree, "ShaderNodeMapRange", "Range", x - 200, y)
    ranged.clamp = True
    ranged.inputs["From Min"].default_value = 0.0
    ranged.inputs["From Max"].default_value = 1.0
    ranged.inputs["To Min"].default_value = float(lo)
    ranged.inputs["To Max"].default_value = float(hi)
    tree.links.new(value, ranged.inputs["Value"])
    return ranged.outputs["Result"]
