"""The extension's per-material settings: ``material.thinfilm_sh`` (:class:`ThinFilmMaterialSettings`).

Thicknesses are in nm (plain floats, subtype NONE: the panel puts "nm" in the labels). The
physical settings mirror :class:`precompute.materials.material.Material`; turning them into one and back
is :mod:`.conversion`'s (which also marks a hand edit CUSTOM: :func:`.conversion.mark_custom`).
The Bake button's outputs live in memory (:data:`OUTPUTS`), never in the file.
"""

from typing import NamedTuple

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)
from bpy.types import PropertyGroup

from ...precompute.materials.material import MAX_SH_ORDER, PRESETS
from ...precompute.optics.metals import available_metals
from .. import caches
from .conversion import apply_preset, applying, mark_custom

# ----------------------------------------------------------------------------------------------
# Enum items (identifiers are stable: they are saved in .blend files)
# ----------------------------------------------------------------------------------------------
#: What each built-in preset looks like, for its tooltip (a preset without one gets a generic line).
PRESET_TOOLTIPS = {
    "soap_film": "A soap bubble: a thin water film in air, swirling from gold to magenta and blue",
    "oil_on_water": "A thin oil slick floating on water, in rainbow bands",
    "anodised_titanium": "Anodized titanium: an oxide layer on the metal, bronze, purple and blue",
    "heat_tinted_steel": "Heat-tinted steel: the straw, brown and blue oxide colors of tempered steel",
    "beetle_multilayer": "A beetle's shell: a stack of alternating layers with a strong metallic green",
    "coated_car_window": "A car window with a thin anti-reflective coating: a faint purple sheen",
}


def _items(*rows: str) -> list[tuple[str, str, str]]:
    """Enum items (identifier, name, description) from "IDENTIFIER | Name | description" rows."""
    return [tuple(part.strip() for part in row.split("|", 2)) for row in rows]


PRESET_ITEMS = [
    (
        name.upper(),
        name.replace("_", " ").title().replace("Anodised", "Anodized"),  # US English in the UI
        PRESET_TOOLTIPS.get(name, f"The built-in {name.replace('_', ' ')} preset"),
    )
    for name in PRESETS
] + [("CUSTOM", "Custom", "Settings edited by hand")]

METAL_ITEMS = [
    (name.upper(), name.title(), f"The measured refractive index (n + ik) of {name} in visible light")
    for name in available_metals()
]

INDEX_MODE_ITEMS = _items(
    "CONSTANT | Constant | Constant complex index n + ik",
    "CAUCHY | Cauchy | Dispersive dielectric n(λ) = A + B/λ² + C/λ⁴ (λ in µm)",
    "METAL | Metal | Measured index of a metal",
)

THICKNESS_SOURCE_ITEMS = _items(
    "ATTRIBUTE | Attribute | A float mesh attribute in [0, 1] (points, corners or faces)",
    "NOISE | Noise | Procedural 3-D value noise of object-space positions",
    "IMAGE | Image | First channel of an image at the mesh's UVs",
    "BLENDER_NOISE | Blender Noise | Blender's own Noise Texture of object-space positions, computed "
    "as Cycles does: written back to the Principled BSDF as nodes, so Cycles renders the same variation",
)

SUBSTRATE_MODE_ITEMS = _items(
    "DIELECTRIC | Dielectric | Transparent substrate with a real index (glass, water, air)",
    "METAL | Metal | Measured index of a metal",
    "CUSTOM | Custom | Constant complex index n + ik",
)

MODEL_ITEMS = _items(
    "EXACT | Exact | Exact multiple-beam (Airy / transfer-matrix) interference",
    "GLASSNER2000 | Glassner 2000 | Glassner's single-film approximation (one layer only)",
)

COLOUR_MODE_ITEMS = _items(
    "SPECTRAL | Spectral | Spectral rendering: lighting turned into spectra, exact color",
    "PER_CHANNEL | Per Channel | RGB channels filtered independently, like Cycles' thin film",
)

ILLUMINANT_ITEMS = [
    ("E", "E", "Equal-energy white (Blender's working spaces are E-balanced here)"),
    ("D65", "D65", "CIE daylight, 6504 K"),
    ("A", "A", "CIE incandescent, 2856 K"),
] + [(f"FL{i}", f"FL{i}", f"CIE fluorescent lamp FL{i} (line spectrum)") for i in range(1, 13)]

SH_ORDER_ITEMS = [("AUTO", "Auto", "Smallest band that holds the specular lobe")] + [
    (str(l), str(l), f"Spherical harmonics up to band {l}") for l in range(MAX_SH_ORDER + 1)
]


# ----------------------------------------------------------------------------------------------
# Update callbacks
# ----------------------------------------------------------------------------------------------
def _settings_changed(self, context):
    """A physical setting was edited by hand: no preset describes it any more."""
    settings = getattr(self.id_data, "thinfilm_sh", None)
    if settings is not None:
        mark_custom(settings)


def _preset_update(self, context):
    if applying() or self.preset == "CUSTOM":
        return
    apply_preset(self, self.preset)


def _enabled_update(self, context):
    # A material enabled for the first time gets the chosen preset's film.
    if self.enabled and len(self.layers) == 0 and self.preset != "CUSTOM":
        apply_preset(self, self.preset)


# ----------------------------------------------------------------------------------------------
# Outputs: what the Bake button found, kept in memory (never saved, never animated)
# ----------------------------------------------------------------------------------------------
#: Runtime outputs by (material session id, name): ``last_bake_ms``, ``last_plan``,
#: ``last_error`` read and write here through getters and setters, so Blender stores nothing
#: in the file, nothing can be keyed, and baking a linked material changes no library data.
OUTPUTS: dict = caches.register("material_outputs", {}, scope=caches.FILE)
#: Hidden from the UI's property lists, not animatable, editable on linked data.
OUTPUT_OPTIONS = {"HIDDEN", "LIBRARY_EDITABLE"}


def _output_getter(name: str, default):
    def get(self):
        return OUTPUTS.get((self.id_data.session_uid, name), default)

    return get


def _output_setter(name: str):
    def set_(self, value):
        OUTPUTS[(self.id_data.session_uid, name)] = value

    return set_


# ----------------------------------------------------------------------------------------------
# Property groups
# ----------------------------------------------------------------------------------------------
class _Limits(NamedTuple):
    """A physical setting's slider: hard minimum, soft minimum, soft maximum (None: Blender's
    default) and the digits shown."""

    min: float | None
    soft_min: float | None
    soft_max: float | None
    precision: int


#: The sliders of the film's float settings (:class:`_Limits`).
_INDEX = _Limits(0.01, 1.0, 4.0, 4)  # a refractive index: water 1.33, glass 1.5, TiO2 2.4
_EXTINCTION = _Limits(0.0, None, 5.0, 4)  # a layer's extinction coefficient k
_CAUCHY_A = _Limits(0.01, 1.0, 3.0, 4)
_CAUCHY_B = _Limits(None, 0.0, 0.1, 5)  # µm²
_CAUCHY_C = _Limits(None, 0.0, 0.01, 6)  # µm⁴
_NM = _Limits(0.0, None, 2000.0, 1)  # a thickness in nm: colours from about 100 to 1500 nm
_SUBSTRATE_N = _Limits(0.01, None, 4.0, 4)
_SUBSTRATE_K = _Limits(0.0, None, 10.0, 4)  # metals 1 to 10
_AMBIENT = _Limits(1.0, None, 2.0, 4)  # air 1.0, water 1.33
_FACTOR = _Limits(0.0, None, None, 2)  # 0 to 1 (max=1.0): Blender's default precision, 2
#: The tooltip of the thickness range's ends.
_END_TIP = "The top layer's thickness in nanometers where the thickness source is {}"


def _physical(name: str, description: str, default: float, limits: _Limits, **extra):
    """A float setting of the film (an index, a thickness in nm, the roughness): editing it by
    hand marks the preset CUSTOM; its slider's ``limits`` (:class:`_Limits`); ``extra``: more of
    ``FloatProperty``'s options (a hard maximum, a subtype)."""
    bounds = {
        key: limits[i] for i, key in enumerate(("min", "soft_min", "soft_max")) if limits[i] is not None
    }
    return FloatProperty(
        name=name,
        description=description,
        default=default,
        precision=limits.precision,
        update=_settings_changed,
        **bounds,
        **extra,
    )


def _choice(name: str, description: str, items, default: str):
    """A choice of how the film is shown or baked (not its physics: the preset stays)."""
    return EnumProperty(name=name, description=description, items=items, default=default)


def _text(name: str, description: str, default: str):
    """A name the thickness is read by (an attribute, a UV map)."""
    return StringProperty(name=name, description=description, default=default)


def _physical_choice(name: str, description: str, items, default=None):
    """A choice of the film's physics (an index mode, a metal, a model): editing it by hand marks
    the preset CUSTOM."""
    extra = {} if default is None else {"default": default}
    return EnumProperty(name=name, description=description, items=items, update=_settings_changed, **extra)


def _physical_switch(name: str, description: str, default: bool):
    """A switch of the film's physics: editing it by hand marks the preset CUSTOM."""
    return BoolProperty(name=name, description=description, default=default, update=_settings_changed)


def _count(name: str, description: str, maximum: int):
    """A table size of the bake's quality, 0 (chosen automatically) to ``maximum``."""
    return IntProperty(name=name, description=description, default=0, min=0, max=maximum)


def _output(kind, name: str, description: str, key: str, default):
    """One of the Bake button's outputs: a ``kind`` property read and written through
    :data:`OUTPUTS` under ``key`` (never saved, never animated, editable on linked data)."""
    return kind(
        name=name,
        description=description,
        get=_output_getter(key, default),
        set=_output_setter(key),
        options=OUTPUT_OPTIONS,
    )


class ThinFilmLayer(PropertyGroup):
    """One film layer: its index and thickness."""

    index_mode: _physical_choice(
        "Index",
        "How the layer's refractive index is given: a constant, Cauchy's dispersion "
        "formula or a measured metal",
        INDEX_MODE_ITEMS,
        "CONSTANT",
    )
    n: _physical(
        "n",
        "Refractive index of the layer (water 1.33, glass 1.5, titanium dioxide 2.4)",
        1.33,
        _INDEX,
    )
    k: _physical("k", "Extinction coefficient (0 = transparent)", 0.0, _EXTINCTION)
    cauchy_a: _physical(
        "A",
        "Cauchy's A: the layer's refractive index at long (red) wavelengths",
        1.5,
        _CAUCHY_A,
    )
    cauchy_b: _physical(
        "B",
        "Cauchy's B in µm²: how much the index rises toward blue (dispersion)",
        0.004,
        _CAUCHY_B,
    )
    cauchy_c: _physical("C", "Cauchy's C in µm⁴: a finer dispersion term, usually 0", 0.0, _CAUCHY_C)
    metal: _physical_choice("Metal", "The metal whose measured refractive index the layer uses", METAL_ITEMS)
    thickness_nm: _physical(
        "Thickness",
        "Thickness of the layer in nanometers: interference colors appear from about "
        "100 to 1500 nm; thicker films fade to white",
        500.0,
        _NM,
    )


class ThinFilmMaterialSettings(PropertyGroup):
    """Thin-film interference settings of one material (``material.thinfilm_sh``)."""

    enabled: BoolProperty(
        name="Thin Film SH",
        description="Preview this material with physically based thin-film interference",
        default=False,
        update=_enabled_update,
    )
    preset: EnumProperty(
        name="Preset",
        description="Fill the film, substrate and surface settings from a preset",
        items=PRESET_ITEMS,
        default="SOAP_FILM",
        update=_preset_update,
    )

    # Film stack, from the ambient side down.
    layers: CollectionProperty(
        type=ThinFilmLayer,
        name="Film Layers",
        description="The film's layers, from the air side (top) down to the substrate",
    )
    active_layer_index: IntProperty(
        name="Active Film Layer",
        description="The film layer selected in the list",
        default=0,
        min=0,
        options=set(),  # a list selection: not animatable
    )

    # Top-layer thickness over the surface.
    vary_thickness: _physical_switch(
        "Vary Thickness",
        "Vary the top layer's thickness over the surface between the minimum and maximum thickness",
        True,
    )
    thickness_min_nm: _physical("Minimum Thickness", _END_TIP.format(0), 0.0, _NM)
    thickness_max_nm: _physical("Maximum Thickness", _END_TIP.format(1), 1000.0, _NM)
    thickness_source: _choice(
        "Thickness Source",
        "Where the top layer's thickness over the surface comes from",
        THICKNESS_SOURCE_ITEMS,
        "NOISE",
    )
    thickness_attribute: _text(
        "Thickness Attribute",
        "Name of a float mesh attribute from 0 (minimum thickness) to 1 (maximum thickness)",
        "thickness",
    )
    noise_scale: FloatProperty(
        name="Noise Scale",
        description="How fine the thickness noise is: higher values give smaller swirls",
        default=2.0,
        min=0.0,
        soft_max=50.0,
    )
    noise_seed: IntProperty(
        name="Noise Seed", description="Another number gives another noise pattern", default=0, min=0
    )
    thickness_image: PointerProperty(
        type=bpy.types.Image,
        name="Thickness Image",
        description="Image whose first channel gives the thickness (0 minimum, 1 maximum); set its "
        "color space to Non-Color",
    )
    thickness_uv_map: _text(
        "Thickness UV Map", "UV map that places the thickness image (empty: the active render UV map)", ""
    )

    # Substrate and ambient.
    substrate_mode: _physical_choice(
        "Substrate",
        "What lies under the film: a transparent material, a measured metal or a custom complex index",
        SUBSTRATE_MODE_ITEMS,
        "DIELECTRIC",
    )
    substrate_ior: _physical(
        "Substrate IOR",
        "Refractive index under the film (1.0: a free film in air such as a bubble, 1.33 water, 1.5 glass)",
        1.0,
        _INDEX,
    )
    substrate_metal: _physical_choice(
        "Substrate Metal", "The metal under the film, with its measured refractive index", METAL_ITEMS
    )
    substrate_n: _physical("Substrate n", "Refractive index (real part) of the substrate", 1.5, _SUBSTRATE_N)
    substrate_k: _physical(
        "Substrate k",
        "Extinction coefficient of the substrate (0: transparent, metals 1 to 10)",
        0.0,
        _SUBSTRATE_K,
    )
    ambient_ior: _physical(
        "Ambient IOR",
        "Index of the medium around the object (air 1.0, water 1.33)",
        1.0,
        _AMBIENT,
    )

    # Surface.
    roughness: _physical(
        "Roughness",
        "GGX roughness as in the Principled BSDF (α = roughness²)",
        0.05,
        _FACTOR,
        max=1.0,
        subtype="FACTOR",
    )
    diffuse_base: _physical_switch(
        "Diffuse Base", "Add a diffuse color under the film, as paint or pigment under a clear coat", False
    )
    diffuse_color: FloatVectorProperty(
        name="Diffuse Color",
        description="Color of the diffuse base under the film",
        subtype="COLOR",
        size=3,
        min=0.0,
        max=1.0,
        default=(0.05, 0.05, 0.05),
        update=_settings_changed,
    )
    model: _physical_choice(
        "Interference Model", "How the film's interference is computed", MODEL_ITEMS, "EXACT"
    )

    # Viewing.
    transparency: _choice(
        "Transparency",
        "What lies behind the film: hidden by it, or seen through it, tinted by its color",
        (
            (
                "AUTO",
                "Automatic",
                "See through a film on air (a soap bubble: the substrate is the surrounding medium, "
                "no diffuse base); other films are opaque",
            ),
            ("OPAQUE", "Opaque", "The film hides what lies behind it"),
            (
                "SHEET",
                "Thin Sheet",
                "A thin transparent sheet of the substrate (a window): the film on its front face, "
                "what lies behind seen through it, tinted by the film's transmittance",
            ),
        ),
        "AUTO",
    )
    world_lamps: BoolProperty(
        name="World Lamps",
        description=(
            "Shade the World's small, very bright lamps (HDRI lamps, suns) per light direction, "
            "with the film's color at each lamp's angle, instead of through the blurred World "
            "lighting. Off: cheaper, but glossy films under lamp-lit HDRIs lose color"
        ),
        default=True,
    )
    colour_mode: _choice(
        "Color Mode",
        "How the film filters the light's color: spectrally (exact) or per RGB channel "
        "(as Cycles renders a Principled BSDF's thin film)",
        COLOUR_MODE_ITEMS,
        "SPECTRAL",
    )
    illuminant: _choice(
        "Illuminant", "Spectrum assumed for white light in the world lighting", ILLUMINANT_ITEMS, "E"
    )

    # Quality (0 = auto).
    sh_order: _choice(
        "SH Order",
        "Detail of the lighting, in spherical-harmonic bands: higher is sharper and "
        "slower to bake. Auto picks the smallest that holds the material's reflection",
        SH_ORDER_ITEMS,
        "AUTO",
    )
    view_samples: _count(
        "View Angles", "How many viewing angles the table holds (0: chosen automatically)", 512
    )
    thickness_samples: _count(
        "Thickness Samples",
        "How many thicknesses the table holds across the range (0: chosen automatically)",
        512,
    )
    wavelength_count: _count(
        "Wavelengths",
        "How many wavelengths of visible light (360–830 nm) the bake adds up (0: chosen automatically)",
        8192,
    )

    # Previewing a Principled BSDF's own thin film (when the extension's settings are off).
    preview_principled: BoolProperty(
        name="Preview Principled Film",
        description="Preview the thin film of this material's Principled BSDF in the viewport when "
        "Thin Film SH is off (Cycles renders it either way)",
        default=True,
        options=set(),
    )

    # Outputs of the Bake button: kept for this session only (OUTPUTS), never saved in the
    # file nor animated, and writable on linked materials (baking changes no library data).
    last_bake_ms: _output(
        FloatProperty,
        "Last Bake Time (ms)",
        "How long the last bake of this material took, in milliseconds",
        "last_bake_ms",
        0.0,
    )
    last_plan: _output(
        StringProperty,
        "Last Bake Plan",
        "What the last bake of this material chose (SH order, angles, wavelengths)",
        "last_plan",
        "",
    )
    last_error: _output(
        StringProperty,
        "Last Bake Error",
        "Why the last bake of this material failed (empty when it succeeded)",
        "last_error",
        "",
    )


classes = (ThinFilmLayer, ThinFilmMaterialSettings)
