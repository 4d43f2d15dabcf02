"""The Principled BSDF ↔ a precompute Material: reading a thin film, writing the settings back.

- :func:`principled_node` — the Principled BSDF a material's output shows;
- :func:`read_principled` — the Material a Principled BSDF with a thin film describes (Cycles
  interop: per-channel colour like Cycles, a metal as a Gulbrandsen (n, k) fit), and what the
  preview cannot follow;
- :func:`write_back_to_principled` — the extension's settings into the Principled BSDF, so
  Cycles' final render matches the preview as far as Cycles' single film allows.

The socket names are Blender 4.0+'s, checked against 5.2.
"""

from __future__ import annotations

import math

from ...precompute.materials import validate
from ...precompute.materials.conductors import metal_rgb, real_index
from ...precompute.materials.material import Layer, Material
from ..colour_space import working_space
from ..thickness import linked, thickness_nodes
from .conversion import description_from_props, f32

__all__ = [
    "SOCKET_BASE_COLOR",
    "SOCKET_FILM_IOR",
    "SOCKET_IOR",
    "SOCKET_METALLIC",
    "SOCKET_ROUGHNESS",
    "SOCKET_SPECULAR_TINT",
    "SOCKET_THICKNESS",
    "SOCKET_THIN_WALL",
    "SOCKET_TRANSMISSION",
    "diffuse_base",
    "linked_thickness_socket",
    "principled_node",
    "read_principled",
    "write_back_to_principled",
]

#: Principled BSDF socket names (Blender 4.0+; checked against 5.2).
SOCKET_THICKNESS = "Thin Film Thickness"
SOCKET_FILM_IOR = "Thin Film IOR"
SOCKET_IOR = "IOR"
SOCKET_ROUGHNESS = "Roughness"
SOCKET_METALLIC = "Metallic"
SOCKET_BASE_COLOR = "Base Color"
SOCKET_SPECULAR_TINT = "Specular Tint"
SOCKET_TRANSMISSION = "Transmission Weight"
#: The thin-wall switch (Blender 5.2, a boolean input): a sheet with the film on both faces.
SOCKET_THIN_WALL = "Thin Wall"

#: Extra Material fields for a Principled preview: Cycles' film-free multiscatter compensation,
#: where precompute offers that choice.
_CYCLES_PARITY = {"multiscatter": "cycles"} if "multiscatter" in Material.__dataclass_fields__ else {}

#: A Base Color whose every channel is at most this is black: no diffuse base. Cycles drops a
#: closure whose weight is below CLOSURE_WEIGHT_CUTOFF (1e-5, kernel/svm/types.h), and the
#: Principled diffuse closure's weight is Base Color × the layering weight ≤ Base Color.
BLACK_BASE_COLOR = 1e-5


#: Principled inputs the film's preview and its EEVEE output leave out, each with the value at
#: which it has no effect and what it is (Cycles renders them).
UNRENDERED = (
    ("Coat Weight", 0.0, "a clear coat over the film"),
    ("Sheen Weight", 0.0, "sheen"),
    ("Emission Strength", 0.0, "emission"),
    ("Anisotropic", 0.0, "anisotropic roughness"),
    ("Specular IOR Level", 0.5, "a specular level other than 0.5"),
    ("Alpha", 1.0, "alpha below 1"),
)
#: What only a diffuse base uses, left out the same way.
UNRENDERED_UNDER_BASE = (
    ("Subsurface Weight", 0.0, "subsurface scattering (the base is Lambertian)"),
    ("Diffuse Roughness", 0.0, "the base's roughness (the base is Lambertian)"),
)


def unrendered(node, base: bool, dielectric: bool) -> list[str]:
    """Notes naming the inputs of the Principled BSDF ``node`` that are set (or linked) to
    something the film's preview and its EEVEE output leave out (:data:`UNRENDERED`; with a
    diffuse ``base`` also :data:`UNRENDERED_UNDER_BASE`; a ``dielectric``'s Specular Tint)."""
    checks = UNRENDERED + (UNRENDERED_UNDER_BASE if base else ())
    if dielectric:
        checks += ((SOCKET_SPECULAR_TINT, (1.0, 1.0, 1.0), "a tinted specular reflection"),)
    notes = []
    for name, neutral, what in checks:
        socket = node.inputs.get(name)
        if socket is None:
            continue
        value = socket.default_value
        value = tuple(value)[: len(neutral)] if isinstance(neutral, tuple) else float(value)
        if name == "Emission Strength" and not socket.is_linked:
            colour = node.inputs.get("Emission Color")
            if colour is not None and not colour.is_linked and max(tuple(colour.default_value)[:3]) <= 0.0:
                continue
        far = (
            max(abs(a - b) for a, b in zip(value, neutral, strict=True))
            if isinstance(neutral, tuple)
            else abs(value - neutral)
        )
        if socket.is_linked or far > 1e-6:
            shown = (
                "linked"
                if socket.is_linked
                else (", ".join(f"{v:g}" for v in value) if isinstance(value, tuple) else f"{value:g}")
            )
            notes.append(
                f"'{name}' of '{node.name}' ({shown}): {what} is rendered by Cycles, not by the film's "
                "preview or its EEVEE output"
            )
    return notes


def diffuse_base(base_color, transmission: float) -> tuple | None:
    """The diffuse base a dielectric Principled BSDF shows under its film, or None.

    Cycles weights the Principled diffuse lobe by Base Color × (1 − Transmission) × the
    specular layer's layering weight: a black Base Color has no diffuse lobe at all, and a grey
    one a Lambertian lobe of that albedo (the layering weight is the bake's,
    ``bake.layering_weight``). A transmissive dielectric (Transmission ≥ 0.5: glass, water, a
    soap bubble) is previewed as the film alone.
    """
    base = tuple(float(v) for v in base_color[:3])
    if transmission >= 0.5 or max(base) <= BLACK_BASE_COLOR:
        return None
    return base


# ----------------------------------------------------------------------------------------------
# Finding the node
# ----------------------------------------------------------------------------------------------
def _tree(bpy_material):
    return getattr(bpy_material, "node_tree", None)


def _output_node(tree):
    """The active Material Output node (falling back to any), or None."""
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    for node in outputs:
        if getattr(node, "is_active_output", False):
            return node
    return outputs[0] if outputs else None


def principled_node(bpy_material):
    """The Principled BSDF feeding the material output's Surface, else the first one, else None."""
    tree = _tree(bpy_material)
    if tree is None:
        return None
    output = _output_node(tree)
    if output is not None:
        surface = output.inputs.get("Surface")
        if surface is not None and surface.is_linked:
            node = surface.links[0].from_node
            if node.bl_idname == "ShaderNodeBsdfPrincipled":
                return node
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeBsdfPrincipled":
            return node
    return None


def linked_thickness_socket(bpy_material):
    """The Principled BSDF's Thin Film Thickness socket when a link drives it, else None."""
    node = principled_node(bpy_material)
    if node is None or SOCKET_THICKNESS not in node.inputs:
        return None
    socket = node.inputs[SOCKET_THICKNESS]
    return socket if socket.is_linked else None


# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------
def _socket_value(node, name: str, notes: list[str]):
    """An input's own value; a linked input uses its default value and adds a warning."""
    socket = node.inputs[name]
    value = socket.default_value
    value = tuple(value) if hasattr(value, "__len__") else float(value)
    if not all(math.isfinite(v) for v in (value if isinstance(value, tuple) else (value,))):
        shown = ", ".join(f"{v:g}" for v in value) if isinstance(value, tuple) else f"{value:g}"
        raise ValueError(f"Principled BSDF '{node.name}' input '{name}' is {shown}, not finite")
    if socket.is_linked:
        shown = f"{value:g}" if isinstance(value, float) else ", ".join(f"{v:.3g}" for v in value[:3])
        notes.append(
            f"'{name}' of '{node.name}' is driven by a link (a texture?): the preview uses its "
            f"unlinked value {shown}"
        )
    return value


def read_principled(bpy_material) -> tuple[Material | None, list[str]]:
    """(Material, notes) of the material's Principled BSDF thin film; (None, []) without one.

    Film index = Thin Film IOR, thickness = Thin Film Thickness, substrate = IOR (dielectric)
    or, for Metallic > 0.5, Blender's F82-tint metal of Base Color and Specular Tint (the
    ``{"f82_tint": …}`` index: Cycles' own metal in the per-channel mode, a Gulbrandsen (n, k)
    fit spectrally); roughness = Roughness; per-channel colour like Cycles; ambient 1. An opaque
    dielectric shows a Base Color that is not black as a diffuse base (:func:`diffuse_base`).
    A linked Thin Film Thickness is evaluated over the scene's objects using the material
    (:func:`.linked.material_range`): its min/max is the table's thickness range, with a note
    saying how it was obtained (raises :class:`.linked.Pending` while a bake is queued, and
    ValueError when it cannot be evaluated). Other linked sockets use their unlinked values,
    with a note. A zero thickness is not previewed:
    it is the bare Principled BSDF, which Blender's own viewport already shows. A NaN or Inf
    input (set from Python) raises ValueError naming the node and the input.
    """
    node = principled_node(bpy_material)
    if node is None or SOCKET_THICKNESS not in node.inputs:
        return None, []
    notes: list[str] = []
    where = f"Principled BSDF '{node.name}' input"
    socket = node.inputs[SOCKET_THICKNESS]
    found = linked.material_range(bpy_material, socket) if socket.is_linked else None
    if found is None:
        thickness = f32(_socket_value(node, SOCKET_THICKNESS, notes))
        thickness_range = None
    else:
        thickness, thickness_range = _linked_thickness(found, notes)
    if not thickness > 0.0:
        return None, notes if found is not None else []
    validate.real(f"{where} '{SOCKET_THICKNESS}'", thickness, 0.0, validate.MAX_THICKNESS_NM)
    film_ior = f32(_socket_value(node, SOCKET_FILM_IOR, notes))
    validate.real(f"{where} '{SOCKET_FILM_IOR}'", film_ior, 0.0, validate.MAX_INDEX_N, lo_open=True)
    roughness = min(1.0, max(0.0, f32(_socket_value(node, SOCKET_ROUGHNESS, notes))))
    metallic = f32(_socket_value(node, SOCKET_METALLIC, notes))
    base = tuple(min(1.0, max(0.0, f32(v))) for v in _socket_value(node, SOCKET_BASE_COLOR, notes)[:3])
    if metallic > 0.5:
        tint = tuple(min(1.0, max(0.0, f32(v))) for v in _socket_value(node, SOCKET_SPECULAR_TINT, notes)[:3])
        substrate = {"f82_tint": {"f0": list(base), "tint": list(tint)}}
        base_color = None
        if metallic < 1.0:
            notes.append(f"Metallic {metallic:g} is previewed as a pure metal (Metallic 1)")
    else:
        substrate = f32(_socket_value(node, SOCKET_IOR, notes))
        validate.real(f"{where} '{SOCKET_IOR}'", substrate, 0.0, validate.MAX_INDEX_N, lo_open=True)
        transmission = f32(_socket_value(node, SOCKET_TRANSMISSION, notes))
        base_color = diffuse_base(base, transmission)
        if metallic > 0.0:
            notes.append(f"Metallic {metallic:g} is previewed as a dielectric (Metallic 0)")
        if 0.0 < transmission < 1.0:
            notes.append(f"Transmission {transmission:g} is previewed as {round(transmission):d}")
    notes += unrendered(node, base_color is not None, metallic <= 0.5)
    desc = Material(
        layers=(Layer(film_ior, thickness),),
        substrate=substrate,
        ambient=1.0,
        roughness=roughness,
        base_color=base_color,
        colour_mode="per_channel",
        colour_space=working_space(),
        thickness_range_nm=thickness_range,
        **_CYCLES_PARITY,
    )
    return desc, notes


#: The linked thickness's range is rounded outward to this step (nm), so that a re-evaluation
#: giving the same field up to float noise keeps the same table key.
RANGE_STEP_NM = 0.01


def _linked_thickness(found, notes: list[str]) -> tuple[float, tuple | None]:
    """(mid thickness, range or None) of an evaluated linked thickness, with a note saying what
    drives it and at what resolution (:func:`.linked.material_range`)."""
    lo, hi, how = found
    lo = math.floor(max(0.0, lo) / RANGE_STEP_NM) * RANGE_STEP_NM
    hi = math.ceil(max(0.0, hi) / RANGE_STEP_NM) * RANGE_STEP_NM
    if not hi > 0.0:
        notes.append(f"'{SOCKET_THICKNESS}' is linked and evaluates to 0 nm everywhere ({how}): no film")
        return 0.0, None
    notes.append(f"thickness {lo:g}–{hi:g} nm from the link into '{SOCKET_THICKNESS}': {how}")
    if hi - lo <= RANGE_STEP_NM:
        return f32(hi), None
    return f32(0.5 * (lo + hi)), (f32(lo), f32(hi))


# ----------------------------------------------------------------------------------------------
# Writing back
# ----------------------------------------------------------------------------------------------
def _ensure_principled(bpy_material):
    tree = _tree(bpy_material)
    if tree is None:
        bpy_material.use_nodes = True  # only pre-5.0 materials can lack a tree
        tree = bpy_material.node_tree
    node = principled_node(bpy_material)
    output = _output_node(tree)
    if output is None:
        output = tree.nodes.new("ShaderNodeOutputMaterial")
        output.location = (300.0, 0.0)
    if node is None:
        node = tree.nodes.new("ShaderNodeBsdfPrincipled")
        node.location = (output.location.x - 300.0, output.location.y)
    surface = output.inputs["Surface"]
    if not surface.is_linked:
        tree.links.new(node.outputs["BSDF"], surface)
    return node


def _set_socket(node, name: str, value, notes: list[str]) -> None:
    socket = node.inputs[name]
    socket.default_value = value
    if socket.is_linked:
        notes.append(f"'{name}' is linked in '{node.name}': Cycles uses the link, not the written value")


def _write_thickness_graph(bpy_material, node, props, thickness_range, notes: list[str]) -> float:
    """Link the thickness source, as nodes (:func:`.thickness_nodes.build`), into Thin Film
    Thickness so Cycles renders the variation; returns the socket's own value (the middle)."""
    lo, hi = (float(v) for v in thickness_range)
    middle = 0.5 * (lo + hi)
    tree = bpy_material.node_tree
    socket = node.inputs[SOCKET_THICKNESS]
    if props.thickness_source == "IMAGE" and props.thickness_image is None:
        notes.append(f"thickness varies {lo:g}–{hi:g} nm from no image: wrote the middle, {middle:g} nm")
        return middle
    for link in list(socket.links):
        tree.links.remove(link)
    location = (node.location.x - 100.0, node.location.y - 400.0)
    tree.links.new(thickness_nodes.build(tree, props, lo, hi, location), socket)
    socket.default_value = middle
    if props.thickness_source == "NOISE":
        notes.append(
            "the preview's value noise is written as Blender's Noise Texture: same scale and range, "
            "another pattern (choose the Blender Noise source for the same pattern in both)"
        )
    return middle


def _write_thin_wall(node, props, desc, substrate: float) -> None:
    """Thin Wall on where the preview sees through the film as a wall (addon/materials/transparency.py):
    a film on air (*Automatic*) or a *Thin Sheet*; off otherwise."""
    if SOCKET_THIN_WALL not in node.inputs:
        return
    choice = getattr(props, "transparency", "AUTO")
    free = abs(substrate - float(desc.ambient)) < 1e-6
    wall = desc.base_color is None and (choice == "SHEET" or (choice == "AUTO" and free))
    node.inputs[SOCKET_THIN_WALL].default_value = bool(wall)


def write_back_to_principled(bpy_material) -> list[str]:
    """Write the extension's settings into the material's Principled BSDF; returns warnings.

    Creates a Principled BSDF connected to the output if there is none. Thin Film Thickness is
    the top layer's thickness; when it varies, the source is written as nodes linked into it
    (:func:`.thickness_nodes.build`: Noise Texture / Image / Attribute → Map Range min–max,
    replacing an earlier write), so Cycles renders the variation. Thin Film IOR the top
    layer's n at 550 nm; a dielectric substrate sets IOR (Transmission 1 unless the diffuse base
    is on, which sets Base Color; else Base Color white, as Cycles tints the transmission by it;
    Thin Wall where the preview draws a wall: a film on air, a *Thin Sheet*), a conductor sets
    Metallic 1 with Base Color = its normal-incidence reflectance and Specular Tint = its F82
    tint, both integrated from the spectrum.
    Cycles has one film: a multilayer writes only its top layer (with a warning).
    """
    props = bpy_material.thinfilm_sh
    desc = description_from_props(props)
    notes: list[str] = []
    node = _ensure_principled(bpy_material)
    if desc.layers:
        top = desc.layers[0]
        thickness = float(top.thickness_nm)
        if desc.thickness_range_nm is not None:
            thickness = _write_thickness_graph(bpy_material, node, props, desc.thickness_range_nm, notes)
        film = real_index(top.index)
        if film.imag != 0.0 or isinstance(top.index, dict):
            notes.append(f"the film index is written as n = {film.real:.4g} at 550 nm (no k, no dispersion)")
        if not node.inputs[SOCKET_THICKNESS].is_linked:
            _set_socket(node, SOCKET_THICKNESS, thickness, notes)
        _set_socket(node, SOCKET_FILM_IOR, max(1.0, film.real), notes)
        if film.real < 1.0:
            notes.append(f"film n {film.real:.4g} < 1 is clamped to 1 by the Principled BSDF")
        if len(desc.layers) > 1:
            notes.append(
                f"the Principled BSDF has a single film: wrote the top layer of {len(desc.layers)}; "
                "Cycles renders will not match the multilayer preview"
            )
    else:
        _set_socket(node, SOCKET_THICKNESS, 0.0, notes)
    substrate = real_index(desc.substrate)
    conductor = isinstance(desc.substrate, dict) or substrate.imag > 0.0
    if conductor:
        base, tint = metal_rgb(desc.substrate, desc.colour_space)
        _set_socket(node, SOCKET_METALLIC, 1.0, notes)
        _set_socket(node, SOCKET_BASE_COLOR, (*base, 1.0), notes)
        _set_socket(node, SOCKET_SPECULAR_TINT, (*tint, 1.0), notes)
        if desc.base_color is not None:
            notes.append("a metal has no diffuse base in the Principled BSDF: the diffuse color is dropped")
    else:
        _set_socket(node, SOCKET_METALLIC, 0.0, notes)
        _set_socket(node, SOCKET_IOR, substrate.real, notes)
        _set_socket(node, SOCKET_SPECULAR_TINT, (1.0, 1.0, 1.0, 1.0), notes)
        if desc.base_color is not None:
            _set_socket(node, SOCKET_BASE_COLOR, (*desc.base_color, 1.0), notes)
            _set_socket(node, SOCKET_TRANSMISSION, 0.0, notes)
        else:
            _set_socket(node, SOCKET_TRANSMISSION, 1.0, notes)
            # Cycles tints the Principled transmission by Base Color (Blender's default 0.8: a
            # window letting 0.8 through); the preview's glass is untinted.
            _set_socket(node, SOCKET_BASE_COLOR, (1.0, 1.0, 1.0, 1.0), notes)
        _write_thin_wall(node, props, desc, substrate.real)
    _set_socket(node, SOCKET_ROUGHNESS, float(desc.roughness), notes)
    if desc.ambient != 1.0:
        notes.append(f"ambient index {desc.ambient:g} has no Principled equivalent (Cycles assumes 1)")
    if desc.model != "exact":
        notes.append(f"model {desc.model!r} is previewed; Cycles always uses its exact film model")
    return notes
