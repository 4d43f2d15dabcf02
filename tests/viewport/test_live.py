"""The viewport stays live while it works (issue 16), through the add-on's own draw and timer.

- The film table is computed vectorised over the thickness rows and equals the per-row
  computation it replaces (``film_rgb_matrices`` + ``brdf.directional_albedo`` per row).
- A finished bake, and a finished World update, ask for a redraw.
- While a material's new table bakes, the draw shows its previous table: the object is never
  blank mid-bake (pixels of an off-screen draw of the draw callback's items).
- A 10-step slider drag leaves one bake: one queued per material, the newest value winning, and
  a running bake that is no longer wanted is cancelled, never completed.
- No bake and no film table runs on the draw's thread: the real draw callback and timer are run
  with ``bake.bake`` and ``film_colour.film_table`` instrumented to record their threads.

Nothing here is timed: the latency figures are in benchmarks/latency.py → docs/latency.md.
"""

from __future__ import annotations

import dataclasses
import importlib
import threading
import types

import numpy as np
import pytest
from _extension import EXTENSION_ID, registered_extension
from _waits import EVENT_TIMEOUT_S, CueRecorder, RedrawLog, viewport_lanes_idle, wait_for

#: The camera of the off-screen draws: at −y, looking at the sheet in the xz-plane.
VIEW = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, -4.0], [0, 0, 0, 1]], dtype=float)
PROJ = np.array([[2.0, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]], dtype=float)
SIZE = 24


# ----------------------------------------------------------------------------------------------
# The film table, vectorised
# ----------------------------------------------------------------------------------------------
def _film_table_per_row(precompute, result, samples):
    """The film table as it was computed before issue 16: one row at a time."""
    bake, brdf, constants, film_colour = (
        precompute.bakes.bake,
        precompute.brdf,
        precompute.constants,
        precompute.colour.film_colour,
    )
    m = result.material
    u = np.linspace(0.0, 1.0, samples)
    rows = []
    for t in np.atleast_1d(result.thicknesses_nm):
        rows.append(film_colour.film_rgb_matrices(m, float(t) if m.thicknesses() else None, samples)[1])
    rg = np.stack(rows)
    reflectance = rg if np.asarray(result.data).ndim == 5 else np.einsum("tukk->tuk", rg)

    def multiscatter(rg_t):
        if m.multiscatter == "none" or m.roughness <= 0.0:
            return np.ones((u.size, 3))
        if m.multiscatter == "cycles":
            return bake.apply_multiscatter(np.ones((1, u.size, 1, 3, 1)), m, u)[0, :, 0, :, 0]
        white = rg_t.sum(axis=-1)
        mu, wmu = np.polynomial.legendre.leggauss(32)
        mu, wmu = 0.5 * (mu + 1.0), 0.5 * wmu

        def film_reflectance(x):
            return np.stack([np.interp(x, u, white[:, c]) for c in range(3)], axis=-1)

        e_film = brdf.directional_albedo(mu, m.roughness, film_reflectance, 128, 64)
        e = brdf.ggx_E(float(m.roughness), tuple(np.clip(mu, constants.MIN_COS, 1.0).tolist()))
        f_avg = np.clip(np.sum(e_film / e[:, None] * (2.0 * mu * wmu)[:, None], axis=0), 0.0, 1.0)
        return np.stack([brdf.multiscatter_scale(u, m.roughness, f) for f in f_avg], axis=-1)

    return reflectance, np.stack([multiscatter(r) for r in rg])


@pytest.fixture(scope="module")
def precompute():
    """The precompute package's modules the film-table check needs (no Blender)."""
    names = ("bakes.bake", "bakes.planner", "brdf", "constants", "colour.film_colour", "materials.material")
    for name in names:
        importlib.import_module(f"precompute.{name}")
    return importlib.import_module("precompute")


@pytest.mark.parametrize(
    "preset, changes",
    [
        ("soap_film", {}),  # spectral, a 0 nm row (the bare interface), film multiple scattering
        ("heat_tinted_steel", {"colour_mode": "per_channel"}),  # a metal, per channel (Cycles' film)
        ("coated_car_window", {"multiscatter": "cycles"}),  # the substrate's F_avg, every row alike
    ],
)
def test_the_vectorised_film_table_equals_the_per_row_one(precompute, preset, changes):
    """Every row, every u, both arrays: equal to float rounding (1e-12 of values ≤ ~1)."""
    material = dataclasses.replace(precompute.materials.material.preset(preset), **changes)
    _, axis = precompute.bakes.planner.thickness_sets(material, 5)
    ndim = 4 if material.colour_mode == "per_channel" else 5
    result = types.SimpleNamespace(material=material, thicknesses_nm=axis, data=np.zeros((1,) * ndim))
    table = precompute.colour.film_colour.film_table(result, samples=64)
    reflectance, multiscatter = _film_table_per_row(precompute, result, 64)
    assert table.reflectance.shape == reflectance.shape and table.multiscatter.shape == multiscatter.shape
    assert np.all(np.isfinite(table.reflectance)) and np.all(np.isfinite(table.multiscatter))
    np.testing.assert_allclose(table.reflectance, reflectance, rtol=0, atol=1e-12)
    np.testing.assert_allclose(table.multiscatter, multiscatter, rtol=0, atol=1e-12)
    if material.multiscatter == "film":  # the rows differ: each row has its own factor
        assert np.ptp(table.multiscatter[:, -1, :], axis=0).max() > 0.0


@pytest.mark.parametrize("preset, mode", [("soap_film", "spectral"), ("heat_tinted_steel", "per_channel")])
def test_the_film_table_of_a_material_is_its_bakes(precompute, preset, mode):
    """film_table_of(material) equals film_table of its bake: exactly when the table has no
    reflectance at its u nodes (read from a file: swept), and within the bake's own
    interpolation tolerance when a fresh spectral bake's nodes are interpolated instead of a
    second sweep (1e-6 relative above u = 0.0125, where the bake checks it)."""
    quality = precompute.materials.material.Quality(sh_order=2, view_samples=4, wavelength_count=32)
    material = dataclasses.replace(
        precompute.materials.material.preset(preset), colour_mode=mode, quality=quality
    )
    exact = precompute.colour.film_colour.film_table_of(material, samples=81)
    result = precompute.bakes.bake.bake(material)
    assert (result.node_reflectance is not None) == (mode == "spectral")
    swept = precompute.colour.film_colour.film_table(
        dataclasses.replace(result, node_reflectance=None), samples=81
    )
    assert exact.thicknesses_nm.size > 1 and exact.spectral == (mode == "spectral")
    np.testing.assert_array_equal(exact.thicknesses_nm, swept.thicknesses_nm)
    np.testing.assert_allclose(exact.reflectance, swept.reflectance, rtol=0, atol=1e-12)
    np.testing.assert_allclose(exact.multiscatter, swept.multiscatter, rtol=0, atol=1e-12)
    fresh = precompute.colour.film_colour.film_table(result, samples=81)
    above = np.linspace(0.0, 1.0, 81) >= precompute.bakes.planner.U_TEST_MIN
    np.testing.assert_allclose(fresh.reflectance[:, above], exact.reflectance[:, above], rtol=0, atol=2e-6)
    np.testing.assert_allclose(fresh.multiscatter, exact.multiscatter, rtol=0, atol=1e-5)
    assert np.abs(fresh.reflectance - exact.reflectance).max() < 0.05  # the grazing end: extrapolated


# ----------------------------------------------------------------------------------------------
# The viewport, through the add-on
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    modules = [
        "addon.drawing.scene_draw",
        "addon.ui.prefs",
        "addon.bakes.tables",
        "addon.drawing.viewport",
        "addon.materials.description",
        "addon.world.world_job",
        "addon.world.world_state",
        "addon.bakes.bake_jobs",
        "addon.thickness.linked",
        "addon.thickness.maps",
    ]
    modules += ["precompute.bakes.bake", "precompute.colour.film_colour", "addon.gpu.draw"]
    root = tmp_path_factory.mktemp("extension")
    with registered_extension(bpy, root, modules, cache_preference=False, gpu=True) as ns:
        yield ns


@pytest.fixture
def scene(bpy, tf):
    """The factory start-up file (a window with a 3D viewport) without objects or World (nothing
    for Cycles to render), a point light, the caches and the bake queue emptied."""
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    tf.package.register()
    prefs = tf.prefs.preferences()
    prefs.cache_dir = tf.cache_dir
    prefs.show_overlay = True
    tf.tables.clear_caches()
    tf.scene_draw.CACHES.clear()
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    scene = bpy.context.scene
    scene.world = None
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    light.data.energy = 800.0
    light.location = (1.0, -3.0, 1.0)
    scene.collection.objects.link(light)
    tf.world_state.world_lighting(scene, allow_compute=True)  # no World: a constant, no render
    yield scene
    _settle(tf)


def _settle(tf):
    """Wait until no viewport bake runs; empty the queue."""
    bj = tf.bake_jobs
    bj.cancel_all()
    wait_for(lambda: not bj.BAKES.running, "the cancelled viewport bakes to end")
    bj._pending.clear()
    bj._wanted.clear()
    bj.BAKES.take_finished()


def film(bpy, scene, thickness: float = 500.0):
    """A tiny-quality soap film on a 2 × 2 sheet facing −y at the origin."""
    mat = bpy.data.materials.new("Film")
    s = mat.thinfilm_sh
    s.preset = "SOAP_FILM"
    s.enabled = True
    s.transparency = "OPAQUE"  # the pixel checks read the film's own colour and coverage
    s.vary_thickness = False
    s.roughness = 0.4
    s.sh_order = "2"
    s.view_samples = 4
    s.thickness_samples = 4
    s.wavelength_count = 32
    s.layers[0].thickness_nm = thickness
    mesh = bpy.data.meshes.new("Sheet")
    mesh.from_pydata([(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], [], [(0, 1, 2, 3)])
    mesh.materials.append(mat)
    scene.collection.objects.link(bpy.data.objects.new("Sheet", mesh))
    return mat


def frame(bpy, tf):
    """One draw as the draw callback does it (collect without baking; the bakes asked for), drawn
    off-screen: (RGBA image, items)."""
    bpy.context.view_layer.update()
    items, _ = tf.scene_draw.collect(
        bpy.context.evaluated_depsgraph_get(),
        allow_bake=False,
        allow_world=False,
        bake_later=True,
    )
    return tf.draw.render_offscreen(items, VIEW, PROJ, SIZE, SIZE), items


def settled_frame(bpy, tf):
    """Draw, run the timer, wait for its bakes, until a frame queues nothing: the final frame."""
    vp = tf.viewport
    bj = tf.bake_jobs
    for _ in range(6):
        image, items = frame(bpy, tf)
        if not bj._pending and not bj.BAKES.running:
            return image, items
        vp._service()
        wait_for(lambda: not bj.BAKES.running, "the viewport's bakes")
    raise AssertionError("the viewport never settled: every frame of 6 queued another bake")


class Gate:
    """``bake.bake`` held at its start until :meth:`open` (so a test can draw mid-bake), counting
    the bakes that started and those that completed."""

    def __init__(self, tf, monkeypatch):
        self.real = tf.bake.bake
        self.opened = threading.Event()
        self.started: list[str] = []
        self.completed: list[float] = []
        monkeypatch.setattr(tf.bake, "bake", self)

    def __call__(self, material, progress=None):
        self.started.append(threading.current_thread().name)
        assert self.opened.wait(EVENT_TIMEOUT_S), "the gate was never opened"
        result = self.real(material, progress)
        self.completed.append(float(material.layers[0].thickness_nm))
        return result

    def open(self):
        self.opened.set()


@pytest.mark.blender
def test_a_baked_table_is_drawn_before_it_is_written_to_disk(bpy, tf, scene, monkeypatch):
    """The worker cues the redraw once the table (and its film) is in memory; the disk copy,
    which only serves a later session (0.4–2 s for the soap preset's 61 rows), is written after
    that, and still written."""
    vp = tf.viewport
    bj = tf.bake_jobs
    held = threading.Event()
    stored = []
    cache = tf.tables.open_cache()
    real = type(cache).store

    def held_store(self, key, *args, **kwargs):
        assert held.wait(EVENT_TIMEOUT_S), "the disk write was never released"
        path = real(self, key, *args, **kwargs)
        stored.append(path)
        return path

    monkeypatch.setattr(type(cache), "store", held_store)
    cue = CueRecorder(lambda: not stored)  # at the cue: is the disk copy still unwritten?
    monkeypatch.setattr(bj.BAKES, "_finished", cue)
    film(bpy, scene)
    frame(bpy, tf)  # queues the bake
    vp._service()
    wait_for(lambda: not bj.BAKES.running, "the bake")
    # the redraw's cue came while the write is held, whichever tick took it (the one that
    # started a quick bake may have)
    assert cue.seen == [True] and not stored, f"cue set with the disk copy unwritten: {cue.seen}"
    image, items = frame(bpy, tf)
    assert len(items) == 1 and image[..., 3].max() > 0 and not bj._pending  # drawn, not re-queued
    held.set()
    wait_for(lambda: stored, "the disk write")
    assert stored[0].exists()


@pytest.mark.blender
def test_a_finished_bake_and_a_finished_world_update_ask_for_a_redraw(bpy, tf, scene, monkeypatch):
    """The timer tags the 3D views after a bake's worker ended and after it updated the World,
    even when nothing else runs any more (no stalled edit waiting for an unrelated redraw)."""
    vp = tf.viewport
    bj = tf.bake_jobs
    bake_cue = CueRecorder(lambda: bj.BAKES.running)
    monkeypatch.setattr(bj.BAKES, "_finished", bake_cue)
    redraws = RedrawLog(bake_cue)
    monkeypatch.setattr(vp, "_tag_redraw", redraws)
    film(bpy, scene)
    frame(bpy, tf)  # queues the bake
    redraws.clear()
    vp._service()
    wait_for(lambda: viewport_lanes_idle(vp), "the bake (and any World or display job it started beside)")
    assert bake_cue.seen == [True], (
        f"the bake's worker set its redraw cue with running={bake_cue.seen}: it must set it before "
        "it leaves the running list, or a timer tick in between stops the timer and the redraw is lost"
    )
    assert vp._service() is None and redraws.after_cue(), (
        f"cues set at each redraw since the bake started: {redraws} (the last must follow the cue)"
    )

    img = bpy.data.images.new("Sky", 32, 16, float_buffer=True, alpha=False)
    img.pixels.foreach_set(np.full(32 * 16 * 4, 0.5, dtype=np.float32))
    world = bpy.data.worlds.new("Sky")  # an image World: read here, analysed on a worker
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    scene.world = world
    bpy.context.view_layer.update()
    tf.world_state.world_lighting(scene, allow_compute=False)  # the old lighting, and an ask
    assert tf.world_job.busy()
    world_cue = CueRecorder(lambda: tf.world_job.WORK.running)
    monkeypatch.setattr(tf.world_job.WORK, "_finished", world_cue)
    redraws.cue = world_cue
    redraws.clear()
    vp._service()  # reads it here, analyses it on a worker
    wait_for(lambda: not tf.world_job.busy(), "the World's analysis")
    assert world_cue.seen == [True], (
        f"the World's worker set its redraw cue with running={world_cue.seen}: it must set it "
        "before it leaves the running list (the same lost redraw as the bake's)"
    )
    # the job ended: this tick redraws, unless the tick that started it already took its cue
    assert vp._service() is None and redraws.after_cue(), (
        f"cues set at each redraw since the World's analysis started: {redraws}"
    )
    assert vp.activity() == ""


@pytest.mark.blender
def test_the_previous_table_is_drawn_while_the_new_one_bakes(bpy, tf, scene, monkeypatch):
    """Pixels: mid-bake the sheet shows the 500 nm film it showed before (not blank), and once
    the 300 nm table is there, the 300 nm film (a different colour)."""
    vp = tf.viewport
    bj = tf.bake_jobs
    mat = film(bpy, scene, 500.0)
    before, items = settled_frame(bpy, tf)
    covered = before[..., 3] > 0.5
    assert covered.mean() > 0.2 and before[covered, :3].max() > 1e-3, "the lit sheet is not drawn"
    assert items[0].film is not None  # the point light reads the film table

    gate = Gate(tf, monkeypatch)
    mat.thinfilm_sh.layers[0].thickness_nm = 300.0
    mid, items = frame(bpy, tf)  # the table is missing: the bake is queued
    assert len(bj._pending) == 1
    vp._service()
    wait_for(lambda: gate.started, "the bake to start")
    mid, items = frame(bpy, tf)  # drawn while the worker bakes
    assert bj.BAKES.running and "baking 1 film" in vp.activity()
    assert len(items) == 1, "the object disappeared while its new table bakes"
    np.testing.assert_array_equal(mid, before)  # the previous table, film and lighting

    gate.open()
    after, _ = settled_frame(bpy, tf)
    assert gate.completed == [300.0]
    np.testing.assert_array_equal(after[..., 3], before[..., 3])
    assert np.abs(after[covered, :3] - before[covered, :3]).max() > 1e-3, "the new film is not shown"


@pytest.mark.blender
def test_a_ten_step_drag_leaves_one_bake(bpy, tf, scene, monkeypatch):
    """Ten thickness values, each drawn and ticked by the timer while the previous bakes run:
    one bake queued at a time per material, every superseded bake cancelled, one completed
    (the last value), and the frame after it shows that value's table."""
    vp = tf.viewport
    bj = tf.bake_jobs
    mat = film(bpy, scene, 500.0)
    settled_frame(bpy, tf)
    gate = Gate(tf, monkeypatch)
    bakes = tf.tables.bake_count
    values = [400.0 + 10.0 * i for i in range(10)]
    for value in values:
        mat.thinfilm_sh.layers[0].thickness_nm = value
        frame(bpy, tf)
        assert len(bj._pending) <= 1  # one per material, the newest value
        vp._service()
        assert sum(not job.cancelled for job in bj.BAKES.running.values()) <= 1
    gate.open()
    _, items = settled_frame(bpy, tf)
    assert gate.completed == [values[-1]], gate.completed
    assert tf.tables.bake_count == bakes + 1
    key = tf.description.description_key(tf.description.description(mat))
    assert items[0].table is tf.scene_draw.CACHES.tables.get(key)
    for value in values[:-1]:
        mat.thinfilm_sh.layers[0].thickness_nm = value
        assert tf.tables.peek_table(tf.description.description(mat)) is None


@pytest.mark.blender
def test_no_bake_and_no_film_table_runs_in_the_draw_callback(bpy, tf, scene, monkeypatch):
    """The real draw callback in the start-up file's 3D viewport and the real timer, from a cold
    material to its settled frame: every bake and film table ran on a worker thread. The film's
    thickness is this test's own, and the workers are idle first: in a fresh clone's run on a
    loaded machine (2026-12-07) the earlier tests' 500 nm table came without a call to the
    patched bake."""
    vp = tf.viewport
    bj = tf.bake_jobs
    wait_for(lambda: not bj.BAKES.running, "the earlier tests' bakes")
    calls = []
    real_bake, real_film = tf.bake.bake, tf.film_colour.film_table

    def bake(*args, **kwargs):
        calls.append(("bake", threading.current_thread() is threading.main_thread()))
        return real_bake(*args, **kwargs)

    def film_table(*args, **kwargs):
        calls.append(("film", threading.current_thread() is threading.main_thread()))
        return real_film(*args, **kwargs)

    monkeypatch.setattr(tf.bake, "bake", bake)
    monkeypatch.setattr(tf.film_colour, "film_table", film_table)
    drawn = []
    monkeypatch.setattr(
        vp,
        "draw_items",
        lambda items, *a, **k: drawn.append(tf.draw.render_offscreen(items, VIEW, PROJ, 8, 8)),
    )
    film(bpy, scene, 437.0)  # no other test's: its table is baked here or nowhere
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")
    bpy.context.view_layer.update()
    for _ in range(8):
        with bpy.context.temp_override(window=window, area=area, region=region):
            vp.draw_callback()
        vp._service()
        wait_for(lambda: not bj.BAKES.running, "the viewport's bakes")
        if drawn and (drawn[-1][..., 3] > 0.5).any() and not bj._pending:
            break
    assert ("bake", False) in calls and ("film", False) in calls, calls
    assert not any(on_main for _, on_main in calls), calls
    assert (drawn[-1][..., 3] > 0.5).any(), "the film was never drawn"


@pytest.mark.blender
def test_a_prefilter_the_draw_asks_for_starts_the_timer(bpy, tf, scene, monkeypatch):
    """A glossy film's draw asks a worker for the World's prefilter from inside ``collect``; the
    draw callback must start the timer that serves the ask, or the frame with the prefilter waits
    for an unrelated redraw (the stalled first open of benchmarks/latency.py)."""
    vp = tf.viewport
    bj = tf.bake_jobs
    monkeypatch.setattr(vp, "draw_items", lambda *a, **k: None)
    mat = film(bpy, scene)
    mat.thinfilm_sh.roughness = 0.1  # the split sum alone: it reads the prefiltered World
    mat.thinfilm_sh.world_lamps = False  # no film table to queue: only the prefilter is asked for
    img = bpy.data.images.new("Sky", 32, 16, float_buffer=True, alpha=False)
    img.pixels.foreach_set(np.linspace(0.1, 2.0, 32 * 16 * 4, dtype=np.float32))
    world = bpy.data.worlds.new("Sky")
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    scene.world = world
    bpy.context.view_layer.update()
    tf.world_state.world_lighting(scene, allow_compute=True)  # the World analysed, no prefilter yet
    items, _ = tf.scene_draw.collect(
        bpy.context.evaluated_depsgraph_get(), allow_bake=True, allow_world=False
    )
    assert items and items[0].prefiltered is None  # the table is baked; the prefilter not computed
    tf.world_job.wait()  # an earlier test's World work, if any, ends first
    tf.world_state.STATE.prefilters_wanted.clear()  # as if no draw had asked yet
    tf.world_state.STATE.wanted = False
    display = importlib.import_module(f"{EXTENSION_ID}.addon.drawing.display")
    settings = display.settings_of(scene)  # the view's LUT baked first: its bake starts the timer too
    wait_for(lambda: display.viewport_lut(settings) is not None and not display.baking(), "the LUT")
    display.take_finished()
    if bpy.app.timers.is_registered(vp._service):
        bpy.app.timers.unregister(vp._service)
    assert not tf.world_job.busy()
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=area, region=region):
        vp.draw_callback()
    assert tf.world_job.busy() and not bj._pending  # the draw asked for the prefilter alone …
    assert bpy.app.timers.is_registered(vp._service)  # … and started the timer that serves it


@pytest.mark.blender
def test_a_noise_thickness_map_is_made_by_the_timer_once_edits_settle(bpy, tf, scene, monkeypatch):
    """The real draw callback and timer, a (distorted) Noise Texture linked into a Principled
    BSDF's Thin Film Thickness on a UV sphere: the draw bakes
    nothing (the corners' bake, then the map, are queued); the timer bakes the corners at once and
    keeps the map queued, asking to be called again, until the edits have settled
    (``maps.SETTLE_S``: a dragged slider bakes no map per step); then it bakes the map and
    redraws, and the next frame's batch reads the thickness per pixel."""
    vp, linked, maps = tf.viewport, tf.linked, tf.maps
    mat = bpy.data.materials.new("Noise film")  # an opaque Principled film, its thickness linked
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = next(n for n in nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 0.4
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 4.0
    noise.texture_mapping.translation = (0.25, 0.0, 0.0)  # mapped: not mirrored, Cycles bakes it
    ranged = nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = 200.0, 700.0
    links.new(noise.outputs["Fac"], ranged.inputs["Value"])
    links.new(ranged.outputs["Result"], bsdf.inputs["Thin Film Thickness"])
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    sphere = bpy.context.active_object
    sphere.data.materials.append(mat)
    monkeypatch.setattr(vp, "draw_items", lambda *args, **kwargs: None)
    redraws = []
    monkeypatch.setattr(vp, "_tag_redraw", lambda: redraws.append(1))
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")

    def draw():
        bpy.context.view_layer.update()
        with bpy.context.temp_override(window=window, area=area, region=region):
            vp.draw_callback()

    corners, images = linked.STATS["bakes"], linked.STATS["image_bakes"]
    monkeypatch.setattr(maps, "SETTLE_S", 3600.0)
    for _ in range(8):  # the film's table first: no batch until it is there
        draw()
        if linked.baking():
            break
        vp._service()
        wait_for(lambda: not tf.bake_jobs.BAKES.running, "the film's table bake")
    assert linked.STATS["bakes"] == corners and linked.baking(), "the draw queues the corners' bake"
    vp._service()
    assert linked.STATS["bakes"] == corners + 1 and not linked.baking()
    for _ in range(8):  # the corners are drawn (once the film's table is there); the map is queued
        draw()
        if tf.scene_draw.batch_entry(sphere.name) is not None:
            break
        vp._service()
        wait_for(lambda: not tf.bake_jobs.BAKES.running, "the film's table bake")
    entry = tf.scene_draw.batch_entry(sphere.name)
    assert entry is not None and entry.batch is not None and entry.batch.thickness_map is None
    assert linked.has_pending() and linked.STATS["image_bakes"] == images
    wait_for(lambda: not tf.bake_jobs.BAKES.running, "the film's table bake")
    vp._service()
    assert vp._service() is not None, "the timer stopped while a map waits for the edits to settle"
    assert linked.STATS["image_bakes"] == images and linked.has_pending()
    monkeypatch.setattr(maps, "SETTLE_S", 0.0)
    redraws.clear()
    vp._service()
    assert linked.STATS["image_bakes"] == images + 1 and not linked.has_pending()
    assert redraws, "the map was made, but no redraw was asked for"
    draw()
    assert tf.scene_draw.batch_entry(sphere.name).batch.thickness_map is not None
