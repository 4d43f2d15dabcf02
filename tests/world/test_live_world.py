"""World edits in the viewport (issue 16): analysed off the main thread, parameters without work.

Replays what the viewport does (``scene_draw.collect`` as the draw callback calls it, the timer's
World step ``world_job.service``, ``viewport._service``) with the real bpy and real GPU drawing
(Mesa), on a synthetic HDRI with one bright lamp:

- a Background Strength or Mapping rotation edit recomputes nothing (no World read, panorama,
  analysis or prefilter: counted), yet the pixels follow: Strength × 2 → pixels × 2 (linear),
  a rotation about z → the pixels of a World whose image was turned by the same angle (its
  content analysed from scratch);
- a new World content is analysed on a worker while the old lighting is drawn, and the timer
  asks for a redraw when it is ready;
- no prefilter is computed inside the draw callback, or on the main thread at all.
"""

from __future__ import annotations

import math
import threading
import types

import numpy as np
import pytest
from _extension import registered_extension

pytestmark = pytest.mark.blender

VIEW = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, -4.0], [0, 0, 0, 1]], dtype=float)  # camera at −y
PROJ = np.array([[3.5, 0, 0, 0], [0, 3.5, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]], dtype=float)
SIZE = 24
#: The synthetic HDRI: 256 × 128, a sky gradient and one lamp (5000 × the mean) off-axis.
WIDTH, HEIGHT = 256, 128


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    modules = [
        "addon.drawing.scene_draw",
        "addon.ui.prefs",
        "addon.bakes.tables",
        "addon.world.panorama",
        "addon.world.world",
        "addon.world.world_job",
        "addon.world.world_state",
        "addon.world.world_analysis",
        "addon.drawing.viewport",
        "precompute.world.prefilter",
        "addon.gpu.draw",
    ]
    root = tmp_path_factory.mktemp("extension")
    with registered_extension(bpy, root, modules, cache_preference=False, gpu=True) as ns:
        yield ns


def hdri_pixels(shift: int = 0) -> np.ndarray:
    """(H, W, 4) top row first: a gradient sky and a bright lamp, turned by ``shift`` columns."""
    rows = np.linspace(0.0, 1.0, HEIGHT)[:, None]
    cols = np.linspace(0.0, 2.0 * math.pi, WIDTH, endpoint=False)[None, :]
    img = np.ones((HEIGHT, WIDTH, 4), dtype=np.float32)
    img[..., 0] = 0.2 + 0.3 * (1.0 - rows) + 0.1 * np.cos(cols)
    img[..., 1] = 0.25 + 0.2 * (1.0 - rows) + 0.1 * np.sin(cols)
    img[..., 2] = 0.3 + 0.1 * rows + 0.05 * np.cos(2.0 * cols)
    img[40:43, 150:153, :3] = 2000.0  # the lamp
    return np.roll(img, shift, axis=1)


def image(bpy, name: str, shift: int = 0):
    """A float image datablock holding :func:`hdri_pixels` (Blender stores the bottom row first)."""
    img = bpy.data.images.new(name, WIDTH, HEIGHT, float_buffer=True, alpha=False)
    img.pixels.foreach_set(np.ascontiguousarray(hdri_pixels(shift)[::-1]).reshape(-1))
    return img


def hdri_world(bpy, scene, img, mapping: bool = True):
    """World Output ← Background ← Environment Texture (← Mapping ← Texture Coordinate)."""
    world = bpy.data.worlds.new(img.name)
    tree = world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    if mapping:
        coords = tree.nodes.new("ShaderNodeTexCoord")
        node = tree.nodes.new("ShaderNodeMapping")
        node.name = "Mapping"
        tree.links.new(coords.outputs["Generated"], node.inputs["Vector"])
        tree.links.new(node.outputs["Vector"], env.inputs["Vector"])
    scene.world = world
    return world


@pytest.fixture
def live(bpy, tf, monkeypatch):
    """A glossy film sphere under the synthetic HDRI; its table baked, its World analysed through
    the viewport's own steps (the draw asks, the timer reads, a worker analyses)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    tf.scene_draw.CACHES.clear()
    scene = bpy.context.scene
    world = hdri_world(bpy, scene, image(bpy, "sky"))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0)
    sphere = bpy.context.active_object
    mat = bpy.data.materials.new("film")
    s = mat.thinfilm_sh
    s.preset = "SOAP_FILM"
    s.enabled = True
    s.roughness = 0.1  # the split sum alone: the prefilter is what is drawn
    s.sh_order = "2"
    s.view_samples = 4
    s.wavelength_count = 32
    sphere.data.materials.append(mat)
    calls = []  # (thread name, lamps lifted) of every prefilter computed
    real = tf.prefilter.prefilter

    def counting(img, *args, **kwargs):
        calls.append((threading.current_thread().name, kwargs.get("lamp_mask") is not None))
        return real(img, *args, **kwargs)

    monkeypatch.setattr(tf.prefilter, "prefilter", counting)
    redraws = []
    monkeypatch.setattr(tf.viewport, "_tag_redraw", lambda: redraws.append(1))
    ns = types.SimpleNamespace(scene=scene, world=world, sphere=sphere, calls=calls, redraws=redraws)
    assert frame(bpy, tf) == ([], ["World lighting is being updated"])  # nothing analysed yet
    settle(tf)
    items, messages = collect(bpy, tf, allow_bake=True)  # bakes the table: the draw asks for the prefilter
    assert len(items) == 1 and items[0].prefiltered is None, messages
    settle(tf)
    items, _ = frame(bpy, tf)
    assert items[0].prefiltered is not None and items[0].lighting.lamp_count > 0
    ns.items = items
    return ns


def collect(bpy, tf, allow_bake=False):
    """``collect`` as the draw callback calls it (``allow_bake``: the table baked here once)."""
    bpy.context.view_layer.update()
    return tf.scene_draw.collect(
        bpy.context.evaluated_depsgraph_get(), allow_bake=allow_bake, allow_world=False
    )


def frame(bpy, tf):
    """One draw callback's collection (no bakes, no World work)."""
    return collect(bpy, tf)


def settle(tf):
    """The viewport timer until the World's workers are done (their results in the caches)."""
    for _ in range(10):
        tf.viewport._service()
        tf.world_job.wait()
        if not tf.world_job.busy():
            break
    tf.viewport._service()


def pixels(tf, items) -> np.ndarray:
    return tf.draw.render_offscreen(items, VIEW, PROJ, SIZE, SIZE)


def forbid_world_work(tf, monkeypatch):
    def forbidden(*_a, **_k):
        raise AssertionError("a World parameter edit recomputed the World")

    monkeypatch.setattr(tf.panorama, "render_world_panorama", forbidden)
    monkeypatch.setattr(tf.world, "read_world", forbidden)
    monkeypatch.setattr(tf.world, "analyse_read", forbidden)
    monkeypatch.setattr(tf.world_analysis, "analyse_content", forbidden)
    monkeypatch.setattr(tf.world_analysis, "analyse_world", forbidden)


def test_strength_scales_the_drawn_pixels_without_recomputation(bpy, tf, live, monkeypatch):
    """Strength 1 → 2: no World read, analysis or prefilter; the film's pixels double (linear)."""
    before = pixels(tf, live.items)
    prefilters = len(live.calls)
    forbid_world_work(tf, monkeypatch)
    live.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 2.0
    items, _ = frame(bpy, tf)
    assert len(live.calls) == prefilters and not tf.world_job.busy()
    assert items[0].prefiltered is live.items[0].prefiltered  # the same texture, scaled in the lookup
    after = pixels(tf, items)
    covered = before[..., 3] > 0
    assert covered.sum() > 50
    np.testing.assert_allclose(after[covered, :3], 2.0 * before[covered, :3], rtol=1e-4, atol=1e-6)
    coeffs = tf.world_state.STATE.lighting.sh.coeffs
    assert tf.world_state.STATE.lighting.scale == 2.0 and np.all(np.isfinite(coeffs))


def test_rotation_matches_a_world_rebuilt_turned(bpy, tf, live, monkeypatch):
    """Mapping rotation 90° about z: no recomputation; the pixels equal those of a World whose
    image is turned by a quarter (its content read and analysed from scratch)."""
    prefilters = len(live.calls)
    with monkeypatch.context() as m:
        forbid_world_work(tf, m)
        live.world.node_tree.nodes["Mapping"].inputs["Rotation"].default_value = (0.0, 0.0, math.pi / 2.0)
        items, _ = frame(bpy, tf)
        assert len(live.calls) == prefilters and not tf.world_job.busy()
        turned = pixels(tf, items)
        sh_turned = np.array(tf.world_state.STATE.lighting.sh.coeffs)
    # the same World with the image itself turned by W/4 columns (u decreases as φ grows)
    hdri_world(bpy, live.scene, image(bpy, "sky turned", shift=WIDTH // 4), mapping=False)
    frame(bpy, tf)
    settle(tf)
    items, _ = frame(bpy, tf)
    assert len(live.calls) > prefilters  # this one was analysed and prefiltered
    rebuilt = pixels(tf, items)
    rebuilt_sh = np.array(tf.world_state.STATE.lighting.sh.coeffs)
    # exact rotation vs a projection of turned pixels: equal up to the quadrature's float32 rounding
    np.testing.assert_allclose(sh_turned, rebuilt_sh, rtol=0, atol=1e-5 * np.max(np.abs(rebuilt_sh)))
    covered = (turned[..., 3] > 0) & (rebuilt[..., 3] > 0)
    assert covered.sum() > 50
    # the lookup turns the direction; the rebuilt texture turns the texels: both bilinear on a
    # 512-wide level, so they differ by interpolation only (≈ 1e-3 of the brightest pixel)
    scale = float(np.max(rebuilt[covered, :3]))
    assert np.max(np.abs(turned[covered, :3] - rebuilt[covered, :3])) < 0.02 * scale
    assert np.mean(np.abs(turned[covered, :3] - rebuilt[covered, :3])) < 0.002 * scale
    unturned = pixels(tf, live.items)
    assert np.max(np.abs(unturned[covered, :3] - rebuilt[covered, :3])) > 0.05 * scale  # it did turn


def test_old_lighting_is_drawn_while_a_new_world_is_analysed(bpy, tf, live, monkeypatch):
    """A new HDRI: the draw keeps the old lighting and asks the timer, which reads the World and
    analyses it on a worker thread; when it ends the timer asks for a redraw, and the next draw
    shows the new World. Every prefilter ran on a worker."""
    release = threading.Event()
    real = tf.world_analysis.analyse_content

    def held(*args, **kwargs):
        assert threading.current_thread() is not threading.main_thread()
        release.wait(60.0)
        return real(*args, **kwargs)

    monkeypatch.setattr(tf.world_analysis, "analyse_content", held)
    old = tf.world_state.STATE.lighting
    hdri_world(bpy, live.scene, image(bpy, "other", shift=30))
    items, _ = frame(bpy, tf)
    assert tf.world_state.STATE.lighting is old and items[0].lighting is live.items[0].lighting
    assert tf.world_job.busy()
    live.redraws.clear()
    tf.viewport._service()  # reads the World, starts the worker
    items, _ = frame(bpy, tf)  # the worker is held: the old World is drawn
    assert items[0].lighting is live.items[0].lighting and items[0].prefiltered is live.items[0].prefiltered
    release.set()
    tf.world_job.wait()
    live.redraws.clear()
    tf.viewport._service()
    assert live.redraws  # a finished World job asks for a redraw
    items, _ = frame(bpy, tf)
    assert tf.world_state.STATE.lighting is not old and items[0].lighting is not live.items[0].lighting
    assert items[0].prefiltered is not None  # computed with the content: the films read it
    main = threading.main_thread().name
    assert live.calls and all(name != main for name, _ in live.calls)


def test_no_prefilter_inside_the_draw_callback(bpy, tf, live):
    """A glossy film under a diffuse base needs the whole World's prefilter: the draw asks a worker
    for it and draws the film from the SH meanwhile; the timer's worker computes it."""
    mat = live.sphere.data.materials[0]
    mat.thinfilm_sh.world_lamps = False  # the whole World's prefilter, not computed yet
    count = len(live.calls)
    items, messages = collect(bpy, tf, allow_bake=True)
    assert len(items) == 1, messages
    assert items[0].prefiltered is None and len(live.calls) == count  # nothing computed in the draw
    settle(tf)
    items, _ = frame(bpy, tf)
    assert items[0].prefiltered is not None and len(live.calls) == count + 1
    assert live.calls[-1] == (live.calls[-1][0], False) and live.calls[-1][0] != threading.main_thread().name


def rough_items(bpy, tf, live):
    """The sphere's film made rough (its SH half read from a radiance grid, policy.uses_grid),
    its table baked and its grid built here (allow_bake), then one viewport frame."""
    mat = live.sphere.data.materials[0]
    mat.thinfilm_sh.roughness = 0.6
    mat.thinfilm_sh.sh_order = "3"
    mat.thinfilm_sh.vary_thickness = False  # one grid per constant thickness
    mat.thinfilm_sh.transparency = "OPAQUE"
    items, messages = collect(bpy, tf, allow_bake=True)
    assert len(items) == 1 and items[0].grid is not None, messages
    items, _ = frame(bpy, tf)
    assert items[0].grid is not None
    return items


def forbid_grids(tf, monkeypatch):
    grids = tf.package.addon.bakes.radiance_grids

    def forbidden(*_a, **_k):
        raise AssertionError("a World parameter edit rebuilt a radiance grid")

    monkeypatch.setattr(grids.radiance_grid, "build", forbidden)
    return grids


def test_strength_and_rotation_keep_a_rough_films_grid(bpy, tf, live, monkeypatch):
    """A rough film reads its SH half from a grid of the World's content: Strength × 2 doubles
    its pixels and a 90° Mapping rotation turns them, with no grid built, queued or World work."""
    items = rough_items(bpy, tf, live)
    before = pixels(tf, items)
    grids = forbid_grids(tf, monkeypatch)
    forbid_world_work(tf, monkeypatch)
    live.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 2.0
    doubled, _ = frame(bpy, tf)
    assert doubled[0].grid is items[0].grid and not grids.busy()
    after = pixels(tf, doubled)
    covered = before[..., 3] > 0
    assert covered.sum() > 50
    np.testing.assert_allclose(after[covered, :3], 2.0 * before[covered, :3], rtol=1e-4, atol=1e-6)
    live.world.node_tree.nodes["Mapping"].inputs["Rotation"].default_value = (0.0, 0.0, math.pi / 2.0)
    turned, _ = frame(bpy, tf)
    assert turned[0].grid is items[0].grid and not grids.busy()
    got = pixels(tf, turned)
    # the per-pixel SH of the turned World (its coefficients rotated exactly) as the reference:
    # the grid's interpolation against it is ≈ 1 % of the peak (mean ΔE2000 0.1, tuning.md)
    turned[0].grid = None
    per_pixel = pixels(tf, turned)
    peak = float(np.max(per_pixel[covered, :3]))
    assert np.mean(np.abs(got[covered, :3] - per_pixel[covered, :3])) < 0.02 * peak
    assert np.mean(np.abs(after[covered, :3] - got[covered, :3])) > 0.05 * peak  # it did turn
