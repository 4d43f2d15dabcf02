"""The extension's per-material settings: ``material.thinfilm_sh`` (:class:`ThinFilmMaterialSettings`).

Thicknesses are in nm (plain floats, subtype NONE: the panel puts "nm" in the labels). The
physical settings mirror :class:`precompute.material.Material`; turning them into one and back
is :mod:`.conversion`'s (which also marks a hand edit CUSTOM: :func:`.conversion.mark_custom`).
The Bake button's outputs live in memory (:data:`OUTPUTS`), never in the file.
"""

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

from ...precompute.material import MAX_SH_ORDER, PRESETS
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

INDEX_MODE_ITEMS = [
    ("CONSTANT", "Constant", "Constant complex index n + ik"),
    ("CAUCHY", "Cauchy", "Dispersive dielectric n(λ) = A + B/λ² + C/λ⁴ (λ in µm)"),
    ("METAL", "Metal", "Measured index of a metal"),
]

THICKNESS_SOURCE_ITEMS = [
    ("ATTRIBUTE", "Attribute", "A float mesh attribute in [0, 1] (points, corners or faces)"),
    ("NOISE", "Noise", "Procedural 3-D value noise of object-space positions"),
    ("IMAGE", "Image", "First channel of an image at the mesh's UVs"),
    (
        "BLENDER_NOISE",
        "Blender Noise",
        "Blender's own Noise Texture of object-space positions (baked with Cycles): written back to "
        "the Principled BSDF as nodes, so Cycles renders the same variation",
    ),
]

SUBSTRATE_MODE_ITEMS = [
    ("DIELECTRIC", "Dielectric", "Transparent substrate with a real index (glass, water, air)"),
    ("METAL", "Metal", "Measured index of a metal"),
    ("CUSTOM", "Custom", "Constant complex index n + ik"),
]

MODEL_ITEMS = [
    ("EXACT", "Exact", "Exact multiple-beam (Airy / transfer-matrix) interference"),
    ("GLASSNER2000", "Glassner 2000", "Glassner's single-film approximation (one layer only)"),
]

COLOUR_MODE_ITEMS = [
    ("SPECTRAL", "Spectral", "Spectral rendering: lighting turned into spectra, exact color"),
    ("PER_CHANNEL", "Per Channel", "RGB channels filtered independently, like Cycles' thin film"),
]

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
class ThinFilmLayer(PropertyGroup):
    """One film layer: its index and thickness."""

    index_mode: EnumProperty(
        name="Index",
        description="How the layer's refractive index is given: a constant, Cauchy's dispersion "
        "formula or a measured metal",
        items=INDEX_MODE_ITEMS,
        default="CONSTANT",
        update=_settings_changed,
    )
    n: FloatProperty(
        name="n",
        description="Refractive index of the layer (water 1.33, glass 1.5, titanium dioxide 2.4)",
        default=1.33,
        min=0.01,
        soft_min=1.0,
        soft_max=4.0,
        precision=4,
        update=_settings_changed,
    )
    k: FloatProperty(
        name="k",
        description="Extinction coefficient (0 = transparent)",
        default=0.0,
        min=0.0,
        soft_max=5.0,
        precision=4,
        update=_settings_changed,
    )
    cauchy_a: FloatProperty(
        name="A",
        description="Cauchy's A: the layer's refractive index at long (red) wavelengths",
        default=1.5,
        min=0.01,
        soft_min=1.0,
        soft_max=3.0,
        precision=4,
        update=_settings_changed,
    )
    cauchy_b: FloatProperty(
        name="B",
        description="Cauchy's B in µm²: how much the index rises toward blue (dispersion)",
        default=0.004,
        soft_min=0.0,
        soft_max=0.1,
        precision=5,
        update=_settings_changed,
    )
    cauchy_c: FloatProperty(
        name="C",
        description="Cauchy's C in µm⁴: a finer dispersion term, usually 0",
        default=0.0,
        soft_min=0.0,
        soft_max=0.01,
        precision=6,
        update=_settings_changed,
    )
    metal: EnumProperty(
        name="Metal",
        description="The metal whose measured refractive index the layer uses",
        items=METAL_ITEMS,
        update=_settings_changed,
    )
    thickness_nm: FloatProperty(
        name="Thickness",
        description="Thickness of the layer in nanometers: interference colors appear from about "
        "100 to 1500 nm; thicker films fade to white",
        default=500.0,
        min=0.0,
        soft_max=2000.0,
        precision=1,
        subtype="NONE",
        update=_settings_changed,
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
    vary_thickness: BoolProperty(
        name="Vary Thickness",
        description="Vary the top layer's thickness over the surface between the minimum and "
        "maximum thickness",
        default=True,
        update=_settings_changed,
    )
    thickness_min_nm: FloatProperty(
        name="Minimum Thickness",
        description="The top layer's thickness in nanometers where the thickness source is 0",
        default=0.0,
        min=0.0,
        soft_max=2000.0,
        precision=1,
        update=_settings_changed,
    )
    thickness_max_nm: FloatProperty(
        name="Maximum Thickness",
        description="The top layer's thickness in nanometers where the thickness source is 1",
        default=1000.0,
        min=0.0,
        soft_max=2000.0,
        precision=1,
        update=_settings_changed,
    )
    thickness_source: EnumProperty(
        name="Thickness Source",
        items=THICKNESS_SOURCE_ITEMS,
        default="NOISE",
        description="Where the top layer's thickness over the surface comes from",
    )
    thickness_attribute: StringProperty(
        name="Thickness Attribute",
        description="Name of a float mesh attribute from 0 (minimum thickness) to 1 (maximum thickness)",
        default="thickness",
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
    thickness_uv_map: StringProperty(
        name="Thickness UV Map",
        description="UV map that places the thickness image (empty: the active render UV map)",
        default="",
    )

    # Substrate and ambient.
    substrate_mode: EnumProperty(
        name="Substrate",
        description="What lies under the film: a transparent material, a measured metal or a custom "
        "complex index",
        items=SUBSTRATE_MODE_ITEMS,
        default="DIELECTRIC",
        update=_settings_changed,
    )
    substrate_ior: FloatProperty(
        name="Substrate IOR",
        description="Refractive index under the film (1.0: a free film in air such as a bubble, "
        "1.33 water, 1.5 glass)",
        default=1.0,
        min=0.01,
        soft_min=1.0,
        soft_max=4.0,
        precision=4,
        update=_settings_changed,
    )
    substrate_metal: EnumProperty(
        name="Substrate Metal",
        description="The metal under the film, with its measured refractive index",
        items=METAL_ITEMS,
        update=_settings_changed,
    )
    substrate_n: FloatProperty(
        name="Substrate n",
        description="Refractive index (real part) of the substrate",
        default=1.5,
        min=0.01,
        soft_max=4.0,
        precision=4,
        update=_settings_changed,
    )
    substrate_k: FloatProperty(
        name="Substrate k",
        description="Extinction coefficient of the substrate (0: transparent, metals 1 to 10)",
        default=0.0,
        min=0.0,
        soft_max=10.0,
        precision=4,
        update=_settings_changed,
    )
    ambient_ior: FloatProperty(
        name="Ambient IOR",
        description="Index of the medium around the object (air 1.0, water 1.33)",
        default=1.0,
        min=1.0,
        soft_max=2.0,
        precision=4,
        update=_settings_changed,
    )

    # Surface.
    roughness: FloatProperty(
        name="Roughness",
        description="GGX roughness as in the Principled BSDF (α = roughness²)",
        default=0.05,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
        update=_settings_changed,
    )
    diffuse_base: BoolProperty(
        name="Diffuse Base",
        description="Add a diffuse color under the film, as paint or pigment under a clear coat",
        default=False,
        update=_settings_changed,
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
    model: EnumProperty(
        name="Interference Model",
        description="How the film's interference is computed",
        items=MODEL_ITEMS,
        default="EXACT",
        update=_settings_changed,
    )

    # Viewing.
    transparency: EnumProperty(
        name="Transparency",
        description="What lies behind the film: hidden by it, or seen through it, tinted by its color",
        items=(
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
        default="AUTO",
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
    colour_mode: EnumProperty(
        name="Color Mode",
        description="How the film filters the light's color: spectrally (exact) or per RGB channel "
        "(as Cycles renders a Principled BSDF's thin film)",
        items=COLOUR_MODE_ITEMS,
        default="SPECTRAL",
    )
    illuminant: EnumProperty(
        name="Illuminant",
        items=ILLUMINANT_ITEMS,
        default="E",
        description="Spectrum assumed for white light in the world lighting",
    )

    # Quality (0 = auto).
    sh_order: EnumProperty(
        name="SH Order",
        description="Detail of the lighting, in spherical-harmonic bands: higher is sharper and "
        "slower to bake. Auto picks the smallest that holds the material's reflection",
        items=SH_ORDER_ITEMS,
        default="AUTO",
    )
    view_samples: IntProperty(
        name="View Angles",
        description="How many viewing angles the table holds (0: chosen automatically)",
        default=0,
        min=0,
        max=512,
    )
    thickness_samples: IntProperty(
        name="Thickness Samples",
        description="How many thicknesses the table holds across the range (0: chosen automatically)",
        default=0,
        min=0,
        max=512,
    )
    wavelength_count: IntProperty(
        name="Wavelengths",
        description="How many wavelengths of visible light (360–830 nm) the bake adds up (0: chosen "
        "automatically)",
        default=0,
        min=0,
        max=8192,
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
    last_bake_ms: FloatProperty(
        name="Last Bake Time (ms)",
        description="How long the last bake of this material took, in milliseconds",
        get=_output_getter("last_bake_ms", 0.0),
        set=_output_setter("last_bake_ms"),
        options=OUTPUT_OPTIONS,
    )
    last_plan: StringProperty(
        name="Last Bake Plan",
        description="What the last bake of this material chose (SH order, angles, wavelengths)",
        get=_output_getter("last_plan", ""),
        set=_output_setter("last_plan"),
        options=OUTPUT_OPTIONS,
    )
    last_error: StringProperty(
        name="Last Bake Error",
        description="Why the last bake of this material failed (empty when it succeeded)",
        get=_output_getter("last_error", ""),
        set=_output_setter("last_error"),
        options=OUTPUT_OPTIONS,
    )


classes = (ThinFilmLayer, ThinFilmMaterialSettings)
