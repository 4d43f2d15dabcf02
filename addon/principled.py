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

from ..precompute import validate
from ..precompute.conductors import metal_rgb, real_index
from ..precompute.material import Layer, Material
from .props import description_from_props, f32, working_space

__all__ = [
    "SOCKET_BASE_COLOR",
    "SOCKET_FILM_IOR",
    "SOCKET_IOR",
    "SOCKET_METALLIC",
    "SOCKET_ROUGHNESS",
    "SOCKET_SPECULAR_TINT",
    "SOCKET_THICKNESS",
    "SOCKET_TRANSMISSION",
    "diffuse_base",
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

#: Extra Material fields for a Principled preview: Cycles' film-free multiscatter compensation,
#: where precompute offers that choice.
_CYCLES_PARITY = {"multiscatter": "cycles"} if "multiscatter" in Material.__dataclass_fields__ else {}

#: A Base Color whose every channel is at most this is black: no diffuse base. Cycles drops a
#: closure whose weight is below CLOSURE_WEIGHT_CUTOFF (1e-5, kernel/svm/types.h), and the
#: Principled diffuse closure's weight is Base Color × the layering weight ≤ Base Color.
BLACK_BASE_COLOR = 1e-5


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
    Linked sockets use their unlinked values, with a note. A zero thickness is not previewed:
    it is the bare Principled BSDF, which Blender's own viewport already shows. A NaN or Inf
    input (set from Python) raises ValueError naming the node and the input.
    """
    node = principled_node(bpy_material)
    if node is None or SOCKET_THICKNESS not in node.inputs:
        return None, []
    notes: list[str] = []
    thickness = f32(_socket_value(node, SOCKET_THICKNESS, notes))
    if not thickness > 0.0:
        return None, []
    where = f"Principled BSDF '{node.name}' input"
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
    desc = Material(
        layers=(Layer(film_ior, thickness),),
        substrate=substrate,
        ambient=1.0,
        roughness=roughness,
        base_color=base_color,
        colour_mode="per_channel",
        colour_space=working_space(),
        **_CYCLES_PARITY,
    )
    return desc, notes


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


def write_back_to_principled(bpy_material) -> list[str]:
    """Write the extension's settings into the material's Principled BSDF; returns warnings.

    Creates a Principled BSDF connected to the output if there is none. Thin Film Thickness is
    the top layer's thickness (the middle of the range when it varies), Thin Film IOR the top
    layer's n at 550 nm; a dielectric substrate sets IOR (Transmission 1 unless the diffuse base
    is on, which sets Base Color), a conductor sets Metallic 1 with Base Color = its normal-
    incidence reflectance and Specular Tint = its F82 tint, both integrated from the spectrum.
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
            lo, hi = desc.thickness_range_nm
            thickness = 0.5 * (lo + hi)
            notes.append(
                f"thickness varies {lo:g}–{hi:g} nm: wrote the middle, {thickness:g} nm "
                "(drive Thin Film Thickness with a texture for the variation)"
            )
        film = real_index(top.index)
        if film.imag != 0.0 or isinstance(top.index, dict):
            notes.append(f"the film index is written as n = {film.real:.4g} at 550 nm (no k, no dispersion)")
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
            notes.append("a metal has no diffuse base in the Principled BSDF: the diffuse colour is dropped")
    else:
        _set_socket(node, SOCKET_METALLIC, 0.0, notes)
        _set_socket(node, SOCKET_IOR, substrate.real, notes)
        _set_socket(node, SOCKET_SPECULAR_TINT, (1.0, 1.0, 1.0, 1.0), notes)
        if desc.base_color is not None:
            _set_socket(node, SOCKET_BASE_COLOR, (*desc.base_color, 1.0), notes)
            _set_socket(node, SOCKET_TRANSMISSION, 0.0, notes)
        else:
            _set_socket(node, SOCKET_TRANSMISSION, 1.0, notes)
    _set_socket(node, SOCKET_ROUGHNESS, float(desc.roughness), notes)
    if desc.ambient != 1.0:
        notes.append(f"ambient index {desc.ambient:g} has no Principled equivalent (Cycles assumes 1)")
    if desc.model != "exact":
        notes.append(f"model {desc.model!r} is previewed; Cycles always uses its exact film model")
    return notes
