"""Which Blender materials are drawn as transparent walls (addon/materials/transparency.py), in bpy.

The extension's *Transparency* setting (Automatic: a film on air; Thin Sheet; Opaque), a
Principled BSDF's *Transmission Weight* and *Thin Wall*, the write-back of Thin Wall for Cycles,
and the draw items :func:`scene_draw.collect` makes (a wall carries the film table it reads).
"""

import importlib

import pytest
from _extension import EXTENSION_ID

from precompute.shading import transmit

pytestmark = pytest.mark.blender


@pytest.fixture
def ext(bpy, package):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    package.register()
    try:
        yield {
            dotted.rpartition(".")[2]: importlib.import_module(f"{EXTENSION_ID}.{dotted}")
            for dotted in (
                "addon.materials.transparency",
                "addon.materials.description",
                "addon.materials.principled",
            )
        }
    finally:
        package.unregister()


def _film(bpy, preset: str, **settings):
    mat = bpy.data.materials.new(preset)
    tf = mat.thinfilm_sh
    tf.preset = preset
    tf.enabled = True
    for key, value in settings.items():
        setattr(tf, key, value)
    return mat


def _wall(ext, mat):
    return ext["transparency"].wall(mat, ext["description"].description(mat))


def test_extension_settings_choose_the_wall(bpy, ext):
    assert _wall(ext, _film(bpy, "SOAP_FILM")) == (transmit.WALL_SHEET, 1.0)  # a film on air
    assert _wall(ext, _film(bpy, "SOAP_FILM", transparency="OPAQUE")) is None
    assert _wall(ext, _film(bpy, "COATED_CAR_WINDOW")) is None  # on glass: opaque unless asked
    mode, eta = _wall(ext, _film(bpy, "COATED_CAR_WINDOW", transparency="SHEET"))
    assert mode == transmit.WALL_SHEET and eta == pytest.approx(1.52)
    assert _wall(ext, _film(bpy, "ANODISED_TITANIUM", transparency="SHEET")) is None  # a metal
    assert _wall(ext, _film(bpy, "SOAP_FILM", diffuse_base=True)) is None


def _principled(bpy, transmission: float, thin_wall: bool, ior: float = 1.0, base=(1.0, 1.0, 1.0)):
    mat = bpy.data.materials.new("principled")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["IOR"].default_value = ior
    bsdf.inputs["Transmission Weight"].default_value = transmission
    bsdf.inputs["Thin Wall"].default_value = thin_wall
    bsdf.inputs["Thin Film Thickness"].default_value = 500.0
    bsdf.inputs["Thin Film IOR"].default_value = 1.33
    return mat


def test_principled_thin_wall_is_cycles_slab_series(bpy, ext):
    assert _wall(ext, _principled(bpy, 1.0, True)) == (transmit.WALL_CYCLES, 1.0, 1.0, 1.0, 1.0)
    mode, eta, *tint = _wall(ext, _principled(bpy, 1.0, False, 1.5))  # solid glass of its IOR
    assert mode == transmit.WALL_SOLID and eta == pytest.approx(1.5) and tint == [1.0, 1.0, 1.0]
    assert _wall(ext, _principled(bpy, 1.0, False))[:2] == (transmit.WALL_SHEET, 1.0)  # the film alone
    assert _wall(ext, _principled(bpy, 0.2, True)) is None  # previewed as Transmission 0
    # Cycles tints the transmission by Base Color (Blender's default 0.8): the wall carries it
    mode, eta, *tint = _wall(ext, _principled(bpy, 1.0, True, 1.45, base=(0.8, 0.5, 0.2)))
    assert mode == transmit.WALL_CYCLES and eta == pytest.approx(1.45)
    assert tint == pytest.approx([0.8, 0.5, 0.2])


def test_write_back_sets_thin_wall_for_a_film_on_air(bpy, ext):
    write = ext["principled"].write_back_to_principled
    soap = _film(bpy, "SOAP_FILM")
    write(soap)
    bsdf = ext["principled"].principled_node(soap)
    assert bsdf.inputs["Thin Wall"].default_value and bsdf.inputs["Transmission Weight"].default_value == 1.0
    glass = _film(bpy, "COATED_CAR_WINDOW")
    write(glass)
    assert not ext["principled"].principled_node(glass).inputs["Thin Wall"].default_value
    glass.thinfilm_sh.transparency = "SHEET"
    write(glass)
    assert ext["principled"].principled_node(glass).inputs["Thin Wall"].default_value


def test_cycles_stops_shadow_rays_where_the_principled_bsdf_says(bpy, ext):
    """Read from the material's Principled BSDF (what Cycles renders): a thin wall of IOR 1 lets
    shadow rays through at any roughness, one of IOR 1.52 only while smooth; glass without Thin
    Wall never does, even of IOR 1 (measured, tests/eevee/test_wall_shadows.py and
    docs/eevee-native-results.md)."""
    stops = ext["transparency"].cycles_stops_shadow_rays
    for thin_wall, ior, roughness, expected in (
        (True, 1.0, 0.3, False),
        (True, 1.52, 0.0, False),
        (True, 1.52, 0.05, True),
        (False, 1.0, 0.0, True),
        (False, 1.5, 0.0, True),
    ):
        mat = _principled(bpy, 1.0, thin_wall, ior)
        mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = roughness
        assert stops(mat, _wall(ext, mat), 0.5) == expected, (thin_wall, ior, roughness)
    soap = _film(bpy, "SOAP_FILM")  # the extension's free film, written back as a thin wall
    ext["principled"].write_back_to_principled(soap)
    assert not stops(soap, _wall(ext, soap), 0.05)
