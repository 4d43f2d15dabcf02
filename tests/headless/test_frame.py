"""The headless render as a final frame (issue 19): the rest of the scene by EEVEE, the films
over it, depth-tested.

A film sphere, a non-film Principled cube in front of part of it, a floor, a point light and a
coloured World: outside the film sphere (its projected bounding box, widened by the pixel
filters' reach) the headless frame equals EEVEE's own render of the same scene with the same
samples to ≤ 1/255 mean; the cube in front hides the film (depth test); the film is drawn.
"""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _extension import empty_file, registered_extension  # noqa: E402

SIZE = (64, 48)
SAMPLES = 4


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    with registered_extension(
        bpy,
        tmp_path_factory.mktemp("extension"),
        (
            "addon.headless.headless",
            "addon.headless.render",
            "addon.ui.prefs",
            "addon.headless.background",
        ),
    ) as ns:
        yield ns


def _scene(bpy, tf):
    scene = empty_file(bpy, tf, SIZE)
    scene.view_settings.view_transform = "Standard"
    scene.eevee.taa_render_samples = SAMPLES
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(-0.7, 0.0, 0.0), segments=32, ring_count=16)
    ball = bpy.context.object
    mat = bpy.data.materials.new("Film")
    mat.thinfilm_sh.preset = "SOAP_FILM"
    mat.thinfilm_sh.enabled = True
    ball.data.materials.append(mat)
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(-0.3, -1.5, -0.25))
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 0.0, -0.8))
    bpy.ops.object.light_add(type="POINT", location=(1.5, -2.5, 2.5))
    bpy.context.object.data.energy = 300.0
    bpy.ops.object.camera_add(location=(0.0, -6.0, 0.6), rotation=(np.radians(84.0), 0.0, 0.0))
    scene.camera = bpy.context.object
    scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.15, 0.2, 0.3)
    return scene, ball


def _box(bpy, scene, obj, margin: int) -> tuple[slice, slice]:
    """The rows and columns (top row first) of ``obj``'s projected bounding box, widened."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    corners = [world_to_camera_view(scene, scene.camera, obj.matrix_world @ Vector(c)) for c in obj.bound_box]
    xs = [c.x * SIZE[0] for c in corners]
    ys = [(1.0 - c.y) * SIZE[1] for c in corners]
    rows = slice(max(int(min(ys)) - margin, 0), int(max(ys)) + margin + 1)
    cols = slice(max(int(min(xs)) - margin, 0), int(max(xs)) + margin + 1)
    return rows, cols


def _png(path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGBA"), dtype=np.float64) / 255.0


def test_outside_the_films_the_frame_is_eevees_render(bpy, tf, tmp_path):
    scene, ball = _scene(bpy, tf)
    ball.active_material.thinfilm_sh.transparency = "OPAQUE"  # its pixels are the film's own
    result = tf.render.render_scene(scene, str(tmp_path / "frame.png"), *SIZE, supersample=2, engine="EEVEE")
    assert result["engine"] == "EEVEE" and result["objects"] == ["Sphere/Film"], result
    ours = _png(result["png"])
    # EEVEE's own render of the whole scene, the film sphere included (as Blender renders it)
    scene.render.engine = "BLENDER_EEVEE"
    scene.render.filepath = str(tmp_path / "eevee.png")
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    bpy.ops.render.render(write_still=True)
    theirs = _png(tmp_path / "eevee.png")
    outside = np.ones(ours.shape[:2], dtype=bool)
    outside[_box(bpy, scene, ball, margin=3)] = False
    diff = np.abs(ours - theirs)[outside]
    mean, worst = float(diff.mean() * 255), float(diff.max() * 255)
    print(f"\noutside the film ({outside.sum()} px): mean |Δ| {mean:.3f}/255, max {worst:.1f}/255")
    assert outside.sum() > 0.5 * outside.size, outside.sum()
    assert mean <= 1.0, (mean, worst)
    # the film is drawn where it is in front: against EEVEE's frame without the ball (EEVEE
    # renders the film itself since issue 33, so its frame with the ball is close to ours)
    ball.hide_render = True
    bpy.ops.render.render(write_still=True)
    ball.hide_render = False
    without = _png(tmp_path / "eevee.png")
    rows, cols = _box(bpy, scene, ball, margin=0)
    inside = np.abs(ours - without)[rows, cols].max(axis=-1)
    assert inside.max() > 0.05, f"no film drawn where the sphere is: max |Δ| {inside.max():.3f}"
    assert np.all(ours[..., 3] > 0.99)  # the World behind everything: opaque


def _exr(path) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        return np.array(f.channels()["RGBA"].pixels, dtype=np.float64)


def test_a_transparent_film_shows_the_eevee_frame_behind_it(bpy, tf, tmp_path):
    """The soap film is a wall (issue 17): over the EEVEE pass its pixels are what is behind times
    T plus the reflection, so they stay near that background (a soap film transmits ≥ 80 % per
    wall at these angles), where the same film drawn opaque replaces it."""
    scene, ball = _scene(bpy, tf)
    behind = tf.background.render_background(scene, *SIZE, engine="EEVEE", hidden={ball.name})
    seen = tf.render.render_scene(scene, str(tmp_path / "wall.png"), *SIZE, supersample=1, engine="EEVEE")
    ball.active_material.thinfilm_sh.transparency = "OPAQUE"
    solid = tf.render.render_scene(scene, str(tmp_path / "solid.png"), *SIZE, supersample=1, engine="EEVEE")
    rows, cols = _box(bpy, scene, ball, margin=0)
    centre = (slice(rows.start + 4, rows.stop - 4), slice(cols.start + 4, cols.stop - 4))
    bg = behind.rgba[centre][..., :3]
    wall = _exr(seen["exr"])[centre][..., :3]
    opaque = _exr(solid["exr"])[centre][..., :3]
    assert np.all(wall >= 0.6 * bg - 1e-3), float((wall - 0.6 * bg).min())  # both walls' T ≥ 0.64
    assert np.abs(wall - bg).mean() < 0.5 * np.abs(opaque - bg).mean()


def test_a_holdout_film_cuts_a_transparent_hole(bpy, tf, tmp_path):
    """A film object set to *Holdout* renders as Blender renders a holdout: transparent black
    where it is in front (C = 0, α = 0), the rest of the frame unchanged."""
    scene, ball = _scene(bpy, tf)
    kept = tf.render.render_scene(scene, str(tmp_path / "kept.png"), *SIZE, supersample=1, engine="EEVEE")
    ball.is_holdout = True
    cut = tf.render.render_scene(scene, str(tmp_path / "cut.png"), *SIZE, supersample=1, engine="EEVEE")
    rows, cols = _box(bpy, scene, ball, margin=0)
    centre = (slice(rows.start + 4, rows.stop - 4), slice(cols.start + 4, cols.stop - 4))
    hole, before = _exr(cut["exr"]), _exr(kept["exr"])
    cut_out = np.all(hole[centre] == 0.0, axis=-1)
    assert cut_out.mean() > 0.5, cut_out.mean()  # the sphere's disc, less the cube in front of it
    same = np.all(np.abs(hole[centre] - before[centre]) < 1e-6, axis=-1)
    assert np.all(cut_out | same)  # elsewhere (the cube in front) as before
    assert before[centre][..., 3].min() > 0.99  # drawn there without the holdout
    outside = np.ones(hole.shape[:2], dtype=bool)
    outside[_box(bpy, scene, ball, margin=3)] = False
    assert np.abs(hole - before)[outside].max() < 1e-6


@pytest.mark.parametrize("camera", ["PERSP", "ORTHO"])
def test_an_overscanned_background_pass_holds_the_frame_in_its_middle(bpy, tf, camera):
    """Solid glass refracts the background pass beyond the frame's edges: rendered ``margin``
    pixels wider on each side (the camera widened, its pixels unchanged, shifted as set), its middle
    is the frame's own render, and the camera's settings are restored."""
    scene, ball = _scene(bpy, tf)
    cam = scene.camera.data
    cam.type = camera
    cam.shift_x, cam.shift_y = 0.05, -0.03
    before = (cam.sensor_width, cam.sensor_height, cam.ortho_scale, cam.shift_x, cam.shift_y)
    plain = tf.background.render_background(scene, *SIZE, engine="WORKBENCH", hidden={ball.name})
    wide = tf.background.render_background(scene, *SIZE, engine="WORKBENCH", hidden={ball.name}, margin=8)
    assert (cam.sensor_width, cam.sensor_height, cam.ortho_scale, cam.shift_x, cam.shift_y) == before
    assert wide.margin == 8 and wide.wide[0].shape == (SIZE[1] + 16, SIZE[0] + 16, 4)
    assert wide.rgba.shape == plain.rgba.shape
    diff = np.abs(wide.rgba - plain.rgba)
    print(f"\n{camera}: overscan middle vs frame: mean |Δ| {diff.mean():.2e}, max {diff.max():.2e}")
    assert diff.mean() < 2e-3 and np.percentile(diff, 99) < 0.05
    finite = np.isfinite(plain.depth)
    assert np.array_equal(finite, np.isfinite(wide.depth))
    assert np.allclose(wide.depth[finite], plain.depth[finite], rtol=1e-3)


def test_the_overscan_is_asked_for_solid_glass_only_and_bounded(tf):
    """REFRACT_OVERSCAN of the longer side on each side for a frame with solid glass, none without, and the
    pass's longer side never over policy.REFRACT_MAX_SIDE."""
    from types import SimpleNamespace

    from precompute.shading import policy, transmit

    glass = SimpleNamespace(wall=(transmit.WALL_SOLID, 1.5), film=object())
    bubble = SimpleNamespace(wall=(transmit.WALL_SHEET, 1.0), film=object())
    margin = tf.background.refraction_margin
    assert margin([bubble], 256, 128) == 0
    assert margin([bubble, glass], 256, 128) == round(policy.REFRACT_OVERSCAN * 256)
    assert margin([glass], 3840, 2160) * 2 + 3840 <= policy.REFRACT_MAX_SIDE
    assert margin([glass], 5000, 100) == 0
