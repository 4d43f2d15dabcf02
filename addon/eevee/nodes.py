"""The film's node group for EEVEE and its place in the material: an EEVEE-only Material Output.

The group (one per material, named ``TF EEVEE Film · <material>``) reads the film's image
(:mod:`.image`, :func:`precompute.bakes.eevee_table.film_image`) at the pixel's view angle and film
thickness and shades with EEVEE's own closures:

- θo = acos |N · I| (Geometry: *Normal*, or the material's own normal link; *Incoming*), mapped
  to the image's width, and θ' = the half-vector angle of the lobe light's mean direction c
  (read from the dominant-direction image in the reflection direction, an equirect lookup
  built of math nodes), where the specular band is read; the *Thickness* input (nm) mapped through the
  table's rows to its height (Map Range, clamped), one band of rows per quantity; each band
  read bilinearly from four *Closest* texels (EEVEE mipmaps *Linear* images by screen
  derivatives, which would mix rows where the thickness changes fast and columns near normal
  incidence, where acos is steep);
- a **Glossy BSDF** (GGX, single scattering) of the *specular* band at θ' times the *inverse*
  band (1/E) at θo: EEVEE multiplies it by its split sum E, so it returns the film's albedo;
- a **Diffuse BSDF** of *Base Color* × the *diffuse* band (a diffuse base under the film);
- a **Transparent BSDF** of the *transmission* band (a thin wall: soap bubble, window), or a
  **Refraction BSDF** of it (solid glass); for shadow rays a thin wall lets through its fitted
  curve (:func:`precompute.bakes.eevee_table.shadow_fit`), a few math nodes instead of the image.

The material gets a second Material Output, target *EEVEE*, fed by the group; its own output
(target *All*) is left as it is: Blender picks the output whose target matches the engine
before an *All* one (``ntreeShaderOutputNode``), so Cycles renders the Principled film and
EEVEE the group. :func:`remove` deletes exactly what :func:`ensure` added.

Every constant that follows the table (its size, thickness range, bands) is a socket value
(:func:`set_constants`): changing it does not recompile EEVEE's shader. A change of what the
group is made of (:class:`Structure`) rebuilds its inside.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

__all__ = [
    "GROUP_PREFIX",
    "NODE_GROUP",
    "NODE_OUTPUT",
    "SHADOW_EXPONENT",
    "SHADOW_R0",
    "TAG",
    "Structure",
    "band_textures",
    "ensure",
    "equirect_lookup",
    "film_image_of",
    "find",
    "remove",
    "set_constants",
    "set_image",
    "set_light",
]

#: Names of the two nodes added to a material's tree, and the node groups' name prefix.
NODE_GROUP = "TF EEVEE Film"
NODE_OUTPUT = "TF EEVEE Output"
GROUP_PREFIX = "TF EEVEE Film · "
#: Custom property marking what the extension added (on the two nodes and the group).
TAG = "thinfilm_eevee"
#: Version of the group's inside: a group built by another version is rebuilt.
LAYOUT_VERSION = 8
#: Nodes holding a thin wall's shadow curve (:func:`_shadow_transmittance`): r0, e.
SHADOW_R0, SHADOW_EXPONENT = "shadow r0", "shadow exponent"
#: The group's inputs.
IN_THICKNESS, IN_ROUGHNESS, IN_NORMAL, IN_BASE = "Thickness", "Roughness", "Normal", "Base Color"


@dataclass(frozen=True)
class Structure:
    """What the group is made of; equal structures differ only in socket values.

    ``bands``: the image's bands in row order (precompute.bakes.eevee_table.BANDS); ``normal``: the
    group has a *Normal* input (the material's own normal is linked); ``wall``: "" (opaque),
    "transparent" (a thin wall: Transparent BSDF) or "refraction" (solid glass).
    """

    bands: tuple = ("specular", "inverse")
    normal: bool = False
    wall: str = ""

    def key(self) -> str:
        """A text naming the structure and the group's layout version (stored on the group)."""
        return repr([LAYOUT_VERSION, *sorted(asdict(self).items())])


def _node(tree, kind: str, name: str, x: float, y: float, **settings):
    node = tree.nodes.new(kind)
    node.name = node.label = name
    node.location = (x, y)
    for key, value in settings.items():
        setattr(node, key, value)
    return node


def _math(tree, operation: str, name: str, x: float, y: float):
    return _node(tree, "ShaderNodeMath", name, x, y, operation=operation)


def _interface(group, structure: Structure) -> None:
    group.interface.clear()
    group.interface.new_socket(IN_THICKNESS, in_out="INPUT", socket_type="NodeSocketFloat")
    group.interface.new_socket(IN_ROUGHNESS, in_out="INPUT", socket_type="NodeSocketFloat")
    if structure.normal:
        group.interface.new_socket(IN_NORMAL, in_out="INPUT", socket_type="NodeSocketVector")
    if "diffuse" in structure.bands:
        group.interface.new_socket(IN_BASE, in_out="INPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("BSDF", in_out="OUTPUT", socket_type="NodeSocketShader")


def _split(tree, links, value, name: str, y: float):
    """(floor, fraction) of a texel coordinate: the two texels either side and the weight."""
    low = _math(tree, "FLOOR", f"{name}0", -700, y)
    links.new(value, low.inputs[0])
    weight = _math(tree, "SUBTRACT", f"f{name}", -550, y)
    links.new(value, weight.inputs[0])
    links.new(low.outputs[0], weight.inputs[1])
    return low.outputs[0], weight.outputs[0]


def _view_cosine(tree, links, normal, geometry):
    """cos θo = min(|N·I|, 1)."""
    dot = _node(tree, "ShaderNodeVectorMath", "N·I", -1650, 500, operation="DOT_PRODUCT")
    links.new(normal, dot.inputs[0])
    links.new(geometry.outputs["Incoming"], dot.inputs[1])
    absolute = _math(tree, "ABSOLUTE", "|N·I|", -1500, 500)
    links.new(dot.outputs["Value"], absolute.inputs[0])
    clamp = _math(tree, "MINIMUM", "cos θo", -1350, 500)
    clamp.inputs[1].default_value = 1.0
    links.new(absolute.outputs[0], clamp.inputs[0])
    return clamp.outputs[0]


def _light_cosine(tree, links, normal, geometry, cos_view, light):
    """cos θ' = √((1 + I·c)/2), c the lobe light's mean direction read from the ``light`` image
    (:func:`equirect_lookup`, in the reflection direction R = 2(N·I)N − I; stored as (ℓc + 1)/2,
    ℓ = 0.5 + 0.5 s, s the light objects' share of the lobe's light), mixed with cos θo by the
    weight d + (1 − d) s, d the socket values of node "light weight" (0: no World analysed
    yet, :func:`set_constants`): a light object's highlight is read at its half vector."""
    incoming = geometry.outputs["Incoming"]
    dot = _node(tree, "ShaderNodeVectorMath", "N·I (R)", -1650, 800, operation="DOT_PRODUCT")
    links.new(normal, dot.inputs[0])
    links.new(incoming, dot.inputs[1])
    twice = _node(tree, "ShaderNodeVectorMath", "2(N·I)N", -1500, 800, operation="SCALE")
    links.new(normal, twice.inputs[0])
    double = _math(tree, "MULTIPLY", "2 N·I", -1500, 950)
    links.new(dot.outputs["Value"], double.inputs[0])
    double.inputs[1].default_value = 2.0
    links.new(double.outputs[0], twice.inputs["Scale"])
    reflected = _node(tree, "ShaderNodeVectorMath", "R", -1350, 800, operation="SUBTRACT")
    links.new(twice.outputs["Vector"], reflected.inputs[0])
    links.new(incoming, reflected.inputs[1])
    lookup = equirect_lookup(tree, links, reflected.outputs["Vector"], light, "light", (-1200, 1100))
    decoded = _node(tree, "ShaderNodeVectorMath", "2t − 1", -1050, 800, operation="MULTIPLY_ADD")
    links.new(lookup, decoded.inputs[0])
    decoded.inputs[1].default_value = (2.0, 2.0, 2.0)
    decoded.inputs[2].default_value = (-1.0, -1.0, -1.0)
    unit = _node(tree, "ShaderNodeVectorMath", "c", -950, 800, operation="NORMALIZE")
    links.new(decoded.outputs["Vector"], unit.inputs[0])
    length = _node(tree, "ShaderNodeVectorMath", "ℓ", -950, 950, operation="LENGTH")
    links.new(decoded.outputs["Vector"], length.inputs[0])
    share = _math(tree, "MULTIPLY_ADD", "s = 2ℓ − 1", -800, 950)
    share.use_clamp = True
    share.inputs[1].default_value = 2.0
    share.inputs[2].default_value = -1.0
    links.new(length.outputs["Value"], share.inputs[0])
    weight = _math(tree, "MULTIPLY_ADD", "light weight", -650, 950)
    weight.inputs[1].default_value = 1.0
    weight.inputs[2].default_value = 0.0
    links.new(share.outputs[0], weight.inputs[0])
    toward = _node(tree, "ShaderNodeVectorMath", "I·c", -800, 800, operation="DOT_PRODUCT")
    links.new(incoming, toward.inputs[0])
    links.new(unit.outputs["Vector"], toward.inputs[1])
    half = _math(tree, "MULTIPLY_ADD", "(1 + I·c)/2", -650, 800)
    half.use_clamp = True
    half.inputs[1].default_value = 0.5
    half.inputs[2].default_value = 0.5
    links.new(toward.outputs["Value"], half.inputs[0])
    root = _math(tree, "SQRT", "cos θ'", -500, 800)
    links.new(half.outputs[0], root.inputs[0])
    mix = _node(tree, "ShaderNodeMix", "dominant", -350, 700, data_type="FLOAT")
    links.new(weight.outputs[0], mix.inputs["Factor"])
    links.new(cos_view, mix.inputs["A"])
    links.new(root.outputs[0], mix.inputs["B"])
    return mix.outputs["Result"]


def equirect_lookup(tree, links, direction, image, name: str, at=(0.0, 0.0)):
    """The equirect ``image`` in ``direction`` (a vector socket, world space), Blender's
    Environment Texture mapping (u = ½ − atan2(y, x)/2π, v = ½ + atan2(z, √(x² + y²))/π), read
    by an Image Texture node ``name`` (*Closest*: the texel, no mipmaps). EEVEE's own Environment
    Texture node did not follow a linked direction in an object's material here (every
    direction returned one texel), so the mapping is built from math nodes. Returns the colour."""
    x, y = at
    split = _node(tree, "ShaderNodeSeparateXYZ", f"{name} xyz", x, y)
    links.new(direction, split.inputs["Vector"])
    azimuth = _math(tree, "ARCTAN2", f"{name} φ", x + 150, y)
    links.new(split.outputs["Y"], azimuth.inputs[0])
    links.new(split.outputs["X"], azimuth.inputs[1])
    u = _math(tree, "MULTIPLY_ADD", f"{name} u", x + 300, y)
    u.inputs[1].default_value = -0.5 / math.pi
    u.inputs[2].default_value = 0.5
    links.new(azimuth.outputs[0], u.inputs[0])
    flat = _node(tree, "ShaderNodeCombineXYZ", f"{name} xy", x + 150, y - 150)
    links.new(split.outputs["X"], flat.inputs["X"])
    links.new(split.outputs["Y"], flat.inputs["Y"])
    across = _node(tree, "ShaderNodeVectorMath", f"{name} ρ", x + 300, y - 150, operation="LENGTH")
    links.new(flat.outputs["Vector"], across.inputs[0])
    elevation = _math(tree, "ARCTAN2", f"{name} ψ", x + 450, y - 150)
    links.new(split.outputs["Z"], elevation.inputs[0])
    links.new(across.outputs["Value"], elevation.inputs[1])
    v = _math(tree, "MULTIPLY_ADD", f"{name} v", x + 600, y - 150)
    v.inputs[1].default_value = 1.0 / math.pi
    v.inputs[2].default_value = 0.5
    links.new(elevation.outputs[0], v.inputs[0])
    uv = _node(tree, "ShaderNodeCombineXYZ", f"{name} uv", x + 750, y)
    links.new(u.outputs[0], uv.inputs["X"])
    links.new(v.outputs[0], uv.inputs["Y"])
    texture = _node(tree, "ShaderNodeTexImage", name, x + 900, y, interpolation="Closest", extension="EXTEND")
    texture.image = image
    links.new(uv.outputs["Vector"], texture.inputs["Vector"])
    return texture.outputs["Color"]


def _columns(tree, links, cosine, tag: str, y: float):
    """(u0, u1, fx): the two texel columns either side of the angle acos(``cosine``) and the
    weight; px = θ (A − 1)/(π/2) in node "x ``tag``" (:func:`set_constants`)."""
    angle = _math(tree, "ARCCOSINE", f"θ {tag}", -1000, y)
    links.new(cosine, angle.inputs[0])
    column = _math(tree, "MULTIPLY", f"x {tag}", -850, y)
    links.new(angle.outputs[0], column.inputs[0])
    low, weight = _split(tree, links, column.outputs[0], f"x {tag}", y)
    u0 = _offset(tree, links, low, f"u0 {tag}", -450, y)
    u1 = _offset(tree, links, low, f"u1 {tag}", -450, y - 120)
    return u0, u1, weight


def _texel(tree, links, image, name: str, u, v, x: float, y: float):
    """The image at texture coordinates (u, v) with *Closest* interpolation: one texel, no
    filtering and no mipmaps (EEVEE filters *Linear* images with mipmaps chosen by the screen
    derivatives, which mix a table's rows and columns where the thickness or angle changes fast)."""
    combine = _node(tree, "ShaderNodeCombineXYZ", f"uv {name}", x, y)
    links.new(u, combine.inputs["X"])
    links.new(v, combine.inputs["Y"])
    texture = _node(
        tree, "ShaderNodeTexImage", TEXEL + name, x + 170, y, interpolation="Closest", extension="EXTEND"
    )
    texture.image = image
    links.new(combine.outputs["Vector"], texture.inputs["Vector"])
    return texture.outputs["Color"]


def _mix(tree, links, name: str, factor, a, b, x: float, y: float):
    mix = _node(tree, "ShaderNodeMix", name, x, y, data_type="RGBA", blend_type="MIX")
    links.new(factor, mix.inputs["Factor"])
    links.new(a, mix.inputs["A"])
    links.new(b, mix.inputs["B"])
    return mix.outputs["Result"]


def _offset(tree, links, value, name: str, x: float, y: float):
    """value · 1/size + (offset + 0.5)/size (constants in node ``name``, :func:`set_constants`)."""
    node = _math(tree, "MULTIPLY_ADD", name, x, y)
    links.new(value, node.inputs[0])
    return node.outputs[0]


def _band_lookup(tree, links, image, band: int, columns, rows):
    """The band's bilinear lookup from four *Closest* texels (:func:`_texel`): ``columns`` =
    (u0, u1, fx), ``rows`` = (lower row, fy) within the band."""
    u0, u1, fx = columns
    low, fy = rows
    y = -200 - 700 * band
    v0 = _offset(tree, links, low, f"v0 {band}", -450, y)
    v1 = _offset(tree, links, low, f"v1 {band}", -450, y - 150)
    corners = [
        _texel(tree, links, image, f"{band}{i}{j}", u, v, -300, y - 170 * (2 * j + i))
        for j, v in enumerate((v0, v1))
        for i, u in enumerate((u0, u1))
    ]
    bottom = _mix(tree, links, f"lerp x {band}0", fx, corners[0], corners[1], 100, y)
    top = _mix(tree, links, f"lerp x {band}1", fx, corners[2], corners[3], 100, y - 250)
    return _mix(tree, links, f"lerp y {band}", fy, bottom, top, 280, y - 100)


def _build(group, structure: Structure, image) -> None:
    """The inside of the group for ``structure`` (its nodes replaced)."""
    tree, links = group, group.links
    tree.nodes.clear()
    _interface(group, structure)
    inputs = _node(tree, "NodeGroupInput", "Group Input", -1700, 0)
    output = _node(tree, "NodeGroupOutput", "Group Output", 950, 0)
    geometry = _node(tree, "ShaderNodeNewGeometry", "Geometry", -1850, 600)
    normal = inputs.outputs[IN_NORMAL] if structure.normal else geometry.outputs["Normal"]
    cos_view = _view_cosine(tree, links, normal, geometry)
    cos_light = _light_cosine(tree, links, normal, geometry, cos_view, None)
    view = _columns(tree, links, cos_view, "v", 450)
    light = _columns(tree, links, cos_light, "l", 250)
    row = _node(tree, "ShaderNodeMapRange", "row", -1050, 0, clamp=True)
    links.new(inputs.outputs[IN_THICKNESS], row.inputs["Value"])
    row_value = row.outputs["Result"]
    shadow_ray = None
    if structure.wall:  # EEVEE's transparent shadows evaluate the wall: there at the middle row
        row_value, shadow_ray = _shadow_row(tree, links, row_value)
    rows = _split(tree, links, row_value, "y", 0)
    colours = {
        name: _band_lookup(tree, links, image, i, light if name == "specular" else view, rows)
        for i, name in enumerate(structure.bands)
    }
    if structure.wall == "transparent":
        through = colours["transmission"]
        colours["transmission"] = _shadow_transmittance(tree, links, cos_view, shadow_ray, through)
    scaled = _node(tree, "ShaderNodeMix", "A / E", 450, 150, data_type="RGBA", blend_type="MULTIPLY")
    scaled.inputs["Factor"].default_value = 1.0
    links.new(colours["specular"], scaled.inputs["A"])
    links.new(colours["inverse"], scaled.inputs["B"])
    glossy = _node(tree, "ShaderNodeBsdfGlossy", "Film", 650, 300, distribution="GGX")
    links.new(scaled.outputs["Result"], glossy.inputs["Color"])
    links.new(inputs.outputs[IN_ROUGHNESS], glossy.inputs["Roughness"])
    links.new(normal, glossy.inputs["Normal"])
    shader = glossy.outputs["BSDF"]
    for name, extra in (("diffuse", _diffuse), ("transmission", _transmission)):
        if name in colours:
            add = _node(tree, "ShaderNodeAddShader", f"+ {name}", 750, -60 - 150 * len(name))
            links.new(shader, add.inputs[0])
            links.new(extra(tree, links, inputs, colours[name], normal, structure), add.inputs[1])
            shader = add.outputs["Shader"]
    links.new(shader, output.inputs["BSDF"])
    group[TAG + "_structure"] = structure.key()


def _shadow_row(tree, links, row_value):
    """The thickness row a wall is read at: its own for the camera and reflections, the middle row
    for shadow rays (*Light Path → Is Shadow Ray*). EEVEE evaluates a transparent wall's nodes for
    every shadow-map sample (the material's *Transparent Shadows*); with the row a constant there,
    its compiler drops the thickness source (a Noise Texture: half the soap bubble scene's
    frame) from the shadow pass. A film lets nearly the same through at any thickness (T = 1 − R),
    so the shadow barely changes. Returns (the row, *Is Shadow Ray*)."""
    path = _node(tree, "ShaderNodeLightPath", "Light Path", -1050, 350)
    shadow = _node(tree, "ShaderNodeMix", "shadow row", -870, 150, data_type="FLOAT")
    links.new(path.outputs["Is Shadow Ray"], shadow.inputs["Factor"])
    links.new(row_value, shadow.inputs["A"])
    return shadow.outputs["Result"], path.outputs["Is Shadow Ray"]


def _shadow_transmittance(tree, links, cos_view, shadow_ray, colour):
    """A thin wall's transmittance: the *transmission* band for the camera and reflections, for
    shadow rays the wall's fitted curve T = (1 − r)/(1 + r), r = r0 + (1 − r0)(1 − c)^e at the
    light's cosine c (:func:`precompute.bakes.eevee_table.shadow_model`; r0 and e are socket values,
    :func:`set_constants`). EEVEE evaluates a transparent wall's nodes for every shadow-map
    sample: there these few math nodes replace the image's four texel reads per band."""
    one_minus = _math(tree, "SUBTRACT", "shadow 1 − c", 150, -800)
    one_minus.inputs[0].default_value = 1.0
    links.new(cos_view, one_minus.inputs[1])
    power = _math(tree, "POWER", SHADOW_EXPONENT, 300, -800)
    links.new(one_minus.outputs[0], power.inputs[0])
    power.inputs[1].default_value = 5.0  # Schlick's curve of a 4 % face until set_constants
    reflect = _node(tree, "ShaderNodeMix", SHADOW_R0, 450, -800, data_type="RGBA", blend_type="MIX")
    reflect.inputs["A"].default_value = (0.04, 0.04, 0.04, 1.0)
    links.new(power.outputs[0], reflect.inputs["Factor"])
    reflect.inputs["B"].default_value = (1.0, 1.0, 1.0, 1.0)
    through, back = (
        _node(tree, "ShaderNodeVectorMath", name, 600, y, operation=op)
        for name, y, op in (("shadow 1 − r", -760, "SUBTRACT"), ("shadow 1 + r", -900, "ADD"))
    )
    for node in (through, back):  # 1 − r and 1 + r
        node.inputs[0].default_value = (1.0, 1.0, 1.0)
        links.new(reflect.outputs["Result"], node.inputs[1])
    ratio = _node(tree, "ShaderNodeVectorMath", "shadow T", 750, -800, operation="DIVIDE")
    links.new(through.outputs["Vector"], ratio.inputs[0])
    links.new(back.outputs["Vector"], ratio.inputs[1])
    return _mix(tree, links, "shadow or view", shadow_ray, colour, ratio.outputs["Vector"], 900, -650)


def _diffuse(tree, links, inputs, colour, normal, structure):
    tint = _node(tree, "ShaderNodeMix", "base × weight", 0, -300, data_type="RGBA", blend_type="MULTIPLY")
    tint.inputs["Factor"].default_value = 1.0
    links.new(inputs.outputs[IN_BASE], tint.inputs["A"])
    links.new(colour, tint.inputs["B"])
    diffuse = _node(tree, "ShaderNodeBsdfDiffuse", "Base", 150, -300)
    links.new(tint.outputs["Result"], diffuse.inputs["Color"])
    links.new(normal, diffuse.inputs["Normal"])
    return diffuse.outputs["BSDF"]


def _transmission(tree, links, inputs, colour, normal, structure):
    if structure.wall == "refraction":
        bsdf = _node(tree, "ShaderNodeBsdfRefraction", "Through", 150, -500, distribution="GGX")
        links.new(inputs.outputs[IN_ROUGHNESS], bsdf.inputs["Roughness"])
        links.new(normal, bsdf.inputs["Normal"])
    else:
        bsdf = _node(tree, "ShaderNodeBsdfTransparent", "Through", 150, -500)
    links.new(colour, bsdf.inputs["Color"])
    return bsdf.outputs["BSDF"]


def _put(socket, value) -> None:
    """Set a socket's value only when it differs: every write is an update of the node tree
    (0.2 ms each, 5 ms for a group's constants), and most syncs change none of them."""
    if abs(float(socket.default_value) - float(value)) > 1e-6 * max(1.0, abs(float(value))):
        socket.default_value = value


def set_constants(group, layout, ior: float = 1.0, dominant: float = 0.0, lit: bool = False) -> None:
    """Write the image's axes into the group's socket values (no shader recompile):
    ``layout`` is a :class:`precompute.bakes.eevee_table.FilmImage` (or anything with its ``width``,
    ``height``, ``rows`` and ``thickness_nm``); ``ior``: a refraction's relative index;
    ``layout.shadow`` (where it has one): a thin wall's shadow curve, r0 and e;
    ``dominant``: how much the specular band is read at the lobe light's angle θ' rather than
    the view angle where the World alone lights it (0: no dominant-direction image is set); the
    light objects' share s raises it to d + (1 − d) s where ``lit`` (a direction image is set;
    without one the share is not read).

    Texel coordinates: the view column px = θo (A − 1)/(π/2), the row py = (d − lo)/(hi − lo)
    (T − 1) (clamped); a texel (i, j) of band b is read at ((i + 0.5)/A, (j + bT + 0.5)/H).
    """
    nodes = group.nodes
    width, height, rows = int(layout.width), int(layout.height), int(layout.rows)
    for tag in ("v", "l"):
        _put(nodes[f"x {tag}"].inputs[1], (width - 1) / (0.5 * math.pi))
        for name, offset in ((f"u0 {tag}", 0.5), (f"u1 {tag}", 1.5)):
            _put(nodes[name].inputs[1], 1.0 / width)
            _put(nodes[name].inputs[2], offset / width)
    lo, hi = layout.thickness_nm
    row = nodes["row"]
    _put(row.inputs["From Min"], float(lo))
    _put(row.inputs["From Max"], float(hi) if hi > lo else float(lo) + 1.0)
    _put(row.inputs["To Min"], 0.0)
    _put(row.inputs["To Max"], float(rows - 1))
    if "shadow row" in nodes:
        _put(nodes["shadow row"].inputs["B"], 0.5 * float(rows - 1))
    band = 0
    while f"v0 {band}" in nodes:
        for name, offset in ((f"v0 {band}", 0.5), (f"v1 {band}", 1.5)):
            _put(nodes[name].inputs[1], 1.0 / height)
            _put(nodes[name].inputs[2], (band * rows + offset) / height)
        band += 1
    _put(nodes["light weight"].inputs[1], 1.0 - float(dominant) if lit else 0.0)  # s (1 − d) + d
    _put(nodes["light weight"].inputs[2], float(dominant))
    shadow = getattr(layout, "shadow", None)
    if SHADOW_R0 in nodes and shadow is not None:
        reflect = nodes[SHADOW_R0].inputs["A"]
        now = [float(c) for c in reflect.default_value[:3]]
        if any(abs(a - float(b)) > 1e-6 for a, b in zip(now, shadow[:3], strict=True)):
            reflect.default_value = (*shadow[:3], 1.0)
        _put(nodes[SHADOW_EXPONENT].inputs[1], float(shadow[3]))
    through = nodes.get("Through")
    if through is not None and "IOR" in through.inputs:
        _put(through.inputs["IOR"], float(ior))


def find(tree):
    """(group node, output node) the extension added to a material's tree, each None if absent."""
    if tree is None:
        return None, None
    group = tree.nodes.get(NODE_GROUP)
    output = tree.nodes.get(NODE_OUTPUT)
    group = group if group is not None and group.get(TAG) else None
    output = output if output is not None and output.get(TAG) else None
    return group, output


def _new_group(material_name: str):
    import bpy  # the add-on layer: imported here so the module's docs and constants load without it

    group = bpy.data.node_groups.new(GROUP_PREFIX + material_name, "ShaderNodeTree")
    group[TAG] = 1
    return group


def ensure(tree, material_name: str, structure: Structure):
    """The group node and EEVEE output in ``tree``, made or repaired, the group's inside built for
    ``structure`` when it differs; returns the group node. A group shared with another material
    (a copied or appended material) is copied first, so each material owns its group. The
    material's own outputs and nodes are not touched."""
    node, output = find(tree)
    if node is None:
        anchor = _anchor(tree)
        node = tree.nodes.new("ShaderNodeGroup")
        node.name = node.label = NODE_GROUP
        node.location = (anchor[0], anchor[1] - 260.0)
        node[TAG] = 1
    group = node.node_tree
    if group is None or group.users > 1:  # a copied material shares its original's: own one
        group = group.copy() if group is not None else _new_group(material_name)
        group.name = GROUP_PREFIX + material_name
        group[TAG] = 1
        node.node_tree = group
    if group.get(TAG + "_structure") != structure.key():
        _build(group, structure, None)
    if output is None:
        output = tree.nodes.new("ShaderNodeOutputMaterial")
        output.name = output.label = NODE_OUTPUT
        output.target = "EEVEE"
        output.location = (node.location.x + 250.0, node.location.y)
        output[TAG] = 1
    if not output.inputs["Surface"].is_linked or output.inputs["Surface"].links[0].from_node != node:
        tree.links.new(node.outputs[0], output.inputs["Surface"])
    return node


def set_light(group, image) -> None:
    """Point the group's dominant-direction lookup (Environment Texture "light") at ``image``."""
    node = group.nodes.get("light")
    if node is not None and node.image != image:
        node.image = image


#: Name prefix of the band lookups' Image Texture nodes (the film image's readers).
TEXEL = "texel "


def band_textures(group) -> list:
    """The Image Texture nodes of ``group`` that read the film image (not the dominant-direction
    lookup, not an image thickness source built inside the group)."""
    return [n for n in group.nodes if n.bl_idname == "ShaderNodeTexImage" and n.name.startswith(TEXEL)]


def film_image_of(group):
    """The film image ``group`` reads, or None."""
    return next((n.image for n in band_textures(group) if n.image is not None), None)


def set_image(group, image) -> None:
    """Point every band lookup of ``group`` at ``image``."""
    for node in band_textures(group):
        if node.image != image:
            node.image = image


def _anchor(tree) -> tuple[float, float]:
    """Where to put the added nodes: under the material's active output."""
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeOutputMaterial" and getattr(node, "is_active_output", False):
            return float(node.location.x), float(node.location.y)
    return 300.0, 0.0


def remove(tree) -> object | None:
    """Remove the group node and EEVEE output from ``tree``; returns the group (node tree) they
    used, for the caller to delete when nothing else uses it, or None."""
    node, output = find(tree)
    group = node.node_tree if node is not None else None
    for added in (node, output):
        if added is not None:
            tree.nodes.remove(added)
    return group
