"""The extension's per-material settings: ``material.thinfilm_sh`` (:class:`ThinFilmMaterialSettings`).

Thicknesses are in nm (plain floats, subtype NONE: the panel puts "nm" in the labels). The
physical settings mirror :class:`precompute.material.Material`; :mod:`.materials` turns them
into one (``description_from_props``) and back (``fill_from_material``). Editing a physical
setting by hand switches ``preset`` to CUSTOM; choosing a preset fills the settings.
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

from ..precompute.material import MAX_SH_ORDER, PRESETS
from ..precompute.optics.metals import available_metals
from . import materials

# ----------------------------------------------------------------------------------------------
# Enum items (identifiers are stable: they are saved in .blend files)
# ----------------------------------------------------------------------------------------------
PRESET_ITEMS = [
    (name.upper(), name.replace("_", " ").title(), f"Preset '{name}' of precompute.material.PRESETS")
    for name in PRESETS
] + [("CUSTOM", "Custom", "Settings edited by hand")]

METAL_ITEMS = [
    (name.upper(), name.title(), f"Measured n + ik of {name} (precompute/data/metals)")
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
    ("SPECTRAL", "Spectral", "Spectral rendering: lighting upsampled to spectra, exact colour"),
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
        materials.mark_custom(settings)


def _preset_update(self, context):
    if materials.applying() or self.preset == "CUSTOM":
        return
    materials.apply_preset(self, self.preset)


def _enabled_update(self, context):
    # A material enabled for the first time gets the chosen preset's film.
    if self.enabled and len(self.layers) == 0 and self.preset != "CUSTOM":
        materials.apply_preset(self, self.preset)


# ----------------------------------------------------------------------------------------------
# Property groups
# ----------------------------------------------------------------------------------------------
class ThinFilmLayer(PropertyGroup):
    """One film layer: its index and thickness."""

    index_mode: EnumProperty(
        name="Index", items=INDEX_MODE_ITEMS, default="CONSTANT", update=_settings_changed
    )
    n: FloatProperty(
        name="n",
        description="Refractive index",
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
        description="Cauchy A",
        default=1.5,
        min=0.01,
        soft_min=1.0,
        soft_max=3.0,
        precision=4,
        update=_settings_changed,
    )
    cauchy_b: FloatProperty(
        name="B",
        description="Cauchy B (µm²)",
        default=0.004,
        soft_min=0.0,
        soft_max=0.1,
        precision=5,
        update=_settings_changed,
    )
    cauchy_c: FloatProperty(
        name="C",
        description="Cauchy C (µm⁴)",
        default=0.0,
        soft_min=0.0,
        soft_max=0.01,
        precision=6,
        update=_settings_changed,
    )
    metal: EnumProperty(name="Metal", items=METAL_ITEMS, update=_settings_changed)
    thickness_nm: FloatProperty(
        name="Thickness",
        description="Physical thickness of the layer in nanometres",
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
    layers: CollectionProperty(type=ThinFilmLayer, name="Film Layers")
    active_layer_index: IntProperty(name="Active Layer", default=0, min=0)

    # Top-layer thickness over the surface.
    vary_thickness: BoolProperty(
        name="Vary Thickness",
        description="Vary the top layer's thickness over the surface between Min and Max",
        default=True,
        update=_settings_changed,
    )
    thickness_min_nm: FloatProperty(
        name="Min",
        description="Thickness at value 0 (nm)",
        default=0.0,
        min=0.0,
        soft_max=2000.0,
        precision=1,
        update=_settings_changed,
    )
    thickness_max_nm: FloatProperty(
        name="Max",
        description="Thickness at value 1 (nm)",
        default=1000.0,
        min=0.0,
        soft_max=2000.0,
        precision=1,
        update=_settings_changed,
    )
    thickness_source: EnumProperty(
        name="Source",
        items=THICKNESS_SOURCE_ITEMS,
        default="NOISE",
        description="Where the thickness comes from",
    )
    thickness_attribute: StringProperty(
        name="Attribute", description="Float mesh attribute with values in [0, 1]", default="thickness"
    )
    noise_scale: FloatProperty(
        name="Scale",
        description="Noise frequency in object space (1 / size)",
        default=2.0,
        min=0.0,
        soft_max=50.0,
    )
    noise_seed: IntProperty(name="Seed", description="Noise pattern", default=0, min=0)
    thickness_image: PointerProperty(
        type=bpy.types.Image, name="Image", description="Thickness image (first channel, use Non-Color)"
    )
    thickness_uv_map: StringProperty(
        name="UV Map", description="UV map for the image (empty: the active render UV map)", default=""
    )

    # Substrate and ambient.
    substrate_mode: EnumProperty(
        name="Substrate", items=SUBSTRATE_MODE_ITEMS, default="DIELECTRIC", update=_settings_changed
    )
    substrate_ior: FloatProperty(
        name="IOR",
        description="Substrate refractive index",
        default=1.0,
        min=0.01,
        soft_min=1.0,
        soft_max=4.0,
        precision=4,
        update=_settings_changed,
    )
    substrate_metal: EnumProperty(name="Metal", items=METAL_ITEMS, update=_settings_changed)
    substrate_n: FloatProperty(
        name="n",
        description="Substrate refractive index",
        default=1.5,
        min=0.01,
        soft_max=4.0,
        precision=4,
        update=_settings_changed,
    )
    substrate_k: FloatProperty(
        name="k",
        description="Substrate extinction coefficient",
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
        description="A diffuse colour under the film",
        default=False,
        update=_settings_changed,
    )
    diffuse_color: FloatVectorProperty(
        name="Diffuse Color",
        subtype="COLOR",
        size=3,
        min=0.0,
        max=1.0,
        default=(0.05, 0.05, 0.05),
        update=_settings_changed,
    )
    model: EnumProperty(name="Model", items=MODEL_ITEMS, default="EXACT", update=_settings_changed)

    # Viewing.
    world_lamps: BoolProperty(
        name="World Lamps",
        description=(
            "Shade the World's small, very bright lamps (HDRI lamps, suns) per light direction, "
            "with the film's colour at each lamp's angle, instead of through the prefiltered "
            "World and SH. Off: cheaper, but glossy films under lamp-lit HDRIs lose colour"
        ),
        default=True,
    )
    colour_mode: EnumProperty(name="Colour", items=COLOUR_MODE_ITEMS, default="SPECTRAL")
    illuminant: EnumProperty(
        name="Illuminant",
        items=ILLUMINANT_ITEMS,
        default="E",
        description="Spectrum assumed for white light in the world lighting",
    )

    # Quality (0 = auto).
    sh_order: EnumProperty(name="SH Order", items=SH_ORDER_ITEMS, default="AUTO")
    view_samples: IntProperty(
        name="View Angles", description="View-angle samples (0 = auto)", default=0, min=0, max=512
    )
    thickness_samples: IntProperty(
        name="Thickness Samples",
        description="Samples across the thickness range (0 = auto)",
        default=0,
        min=0,
        max=512,
    )
    wavelength_count: IntProperty(
        name="Wavelengths",
        description="Wavelength samples over 360–830 nm (0 = auto)",
        default=0,
        min=0,
        max=8192,
    )

    # Filled by the bake operator.
    last_bake_ms: FloatProperty(name="Last Bake (ms)", default=0.0)
    last_plan: StringProperty(name="Last Plan", default="")
    last_error: StringProperty(name="Last Error", default="")


classes = (ThinFilmLayer, ThinFilmMaterialSettings)
