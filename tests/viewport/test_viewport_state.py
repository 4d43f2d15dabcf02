"""What the viewport remembers between frames, through the draw's own code path (issue 24).

- A material whose bake fails is baked once per change of its description, not once per redraw
  (``bake_jobs.want`` / ``viewport._service`` / ``scene_draw.collect`` as the draw callback
  calls them), and its error is in every frame's messages and in the material panel's error line.
- The GPU caches of ``scene_draw`` (batches, table and film textures, lightings) stay within
  their bounds over a long session, and what they drop is freed.
- The thickness a batch uploads follows its inputs: the noise scale and seed, the attribute's
  values, the image's pixels; an unchanged frame rebuilds nothing.
- NaN thickness values are counted and named in the messages and drawn mid-range.
- A cache disk that is full keeps the baked table in memory, draws it and says why.
"""

from __future__ import annotations

import errno
import gc
import weakref

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _waits import wait_for  # noqa: E402

#: Redraws simulated per case; a bake per redraw would show as REDRAWS bakes.
REDRAWS = 6


def film(bpy, tf, name: str, roughness: float = 0.5, vary: bool = False):
    mat = bpy.data.materials.new(name)
    settings = mat.thinfilm_sh
    settings.preset = "SOAP_FILM"
    settings.enabled = True
    settings.vary_thickness = vary
    settings.roughness = roughness
    settings.sh_order = "2"
    settings.view_samples = 4
    settings.thickness_samples = 4
    settings.wavelength_count = 32
    return mat


def grid(bpy, scene, name: str, material, n: int = 8):
    """An n × n grid of quads in the xz-plane, linked to the scene."""
    mesh = bpy.data.meshes.new(name)
    xs = np.linspace(-1.0, 1.0, n + 1)
    verts = [(x, 0.0, z) for z in xs for x in xs]
    faces = [
        (j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
        for j in range(n)
        for i in range(n)
    ]
    mesh.from_pydata(verts, [], faces)
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def collect(bpy, tf, **kwargs):
    bpy.context.view_layer.update()
    return tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get(), **kwargs)


# ----------------------------------------------------------------------------------------------
# A failing bake backs off
# ----------------------------------------------------------------------------------------------
def redraw(bpy, tf):
    """One viewport redraw as draw_callback does it (collect without baking, the bakes asked for),
    then the timer (_service: starts the queued bakes on threads), waiting for the threads."""
    vp = tf.viewport
    items, messages = collect(bpy, tf, allow_bake=False, allow_world=False, bake_later=True)
    vp._service()
    wait_for(lambda: not tf.bake_jobs.BAKES.running, "the viewport's bake threads to finish")
    return items, messages


def test_a_failing_material_is_baked_once_per_change_not_per_redraw(bpy, tf, scene, monkeypatch):
    """Issue 24: 6 failing bakes in 6 frames before; now one per change of the description."""
    calls = []

    def failing_bake(material, progress=None):
        calls.append(material)
        raise ValueError(f"planted failure #{len(calls)}")

    monkeypatch.setattr(tf.bake, "bake", failing_bake)
    mat = film(bpy, tf, "Failing")
    grid(bpy, scene, "Sheet", mat, n=2)
    tf.world_state.world_lighting(scene, allow_compute=True)

    frames = [redraw(bpy, tf) for _ in range(REDRAWS)]
    assert len(calls) == 1
    assert all(items == [] for items, _ in frames)
    for _, messages in frames[1:]:  # every frame after the failure says so
        assert any("'Failing'" in m and "planted failure #1" in m for m in messages), messages
    errors = tf.ui.material_errors(mat)
    assert any("planted failure #1" in line for line in errors), errors

    mat.thinfilm_sh.roughness = 0.6  # a new description: one new try, then backing off again
    for _ in range(REDRAWS):
        _, messages = redraw(bpy, tf)
    assert len(calls) == 2 and any("planted failure #2" in m for m in messages)

    monkeypatch.undo()  # the material's settings back: still remembered as failed, no retry
    mat.thinfilm_sh.roughness = 0.5
    redraw(bpy, tf)
    assert tf.tables.peek_table(tf.ui.description(mat)) is None
    assert bpy.ops.thinfilm.bake(material=mat.name) == {"FINISHED"}  # the Bake button retries
    items, messages = redraw(bpy, tf)
    assert len(items) == 1 and not any("planted" in m for m in messages)
    assert not any("planted" in line for line in tf.ui.material_errors(mat))


def test_a_full_cache_disk_still_draws_the_baked_table(bpy, tf, scene, monkeypatch):
    """Issue 24: the finished table is not lost when the cache disk is full (simulated ENOSPC)."""

    def full(self, key, *args, **kwargs):
        path = self.path_for(key)
        raise tf.atomic_write.TableWriteError(
            path, f"could not write {str(path)!r}: No space left on device", errno.ENOSPC
        )

    monkeypatch.setattr(tf.table_cache.TableCache, "store", full)
    grid(bpy, scene, "Sheet", film(bpy, tf, "Full"), n=2)
    items, messages = collect(bpy, tf)  # the headless path: bakes in place
    assert [item.name for item in items] == ["Sheet/Full"]
    assert any("'Full'" in m and "No space left on device" in m for m in messages), messages


# ----------------------------------------------------------------------------------------------
# GPU caches are bounded
# ----------------------------------------------------------------------------------------------
def test_gpu_caches_stay_within_their_bounds_and_free_what_they_drop(bpy, tf, scene, monkeypatch):
    """Four objects with four materials, shown two at a time round and round, with every bound
    set to 2: the caches never hold more than 2 entries, a frame showing all four still draws
    them (its own entries are kept), and a dropped table texture is freed."""
    sd = tf.scene_draw
    for name in ("BATCH_CACHE_SIZE", "TABLE_CACHE_SIZE", "FILM_CACHE_SIZE", "LIGHTING_CACHE_SIZE"):
        monkeypatch.setattr(sd, name, 2)
    sd.CACHES.clear()  # takes the bounds above
    objects = [
        grid(bpy, scene, f"Obj{k}", film(bpy, tf, f"Mat{k}", roughness=0.3 + 0.1 * k), n=2) for k in range(4)
    ]
    maps = {"batches": sd.CACHES.batches, "tables": sd.CACHES.tables, "lightings": sd.CACHES.lightings}

    def show(indices):
        for k, obj in enumerate(objects):
            linked = obj.name in scene.collection.objects
            if (k in indices) != linked:
                (scene.collection.objects.link if k in indices else scene.collection.objects.unlink)(obj)
        return collect(bpy, tf)[0]

    first = weakref.ref(show([0, 1])[0].table)
    for frame in range(1, 9):
        shown = [frame % 4, (frame + 1) % 4]
        items = show(shown)
        assert sorted(item.name for item in items) == sorted(f"Obj{k}/Mat{k}" for k in shown)
        assert {name: len(m) for name, m in maps.items()} == {"batches": 2, "tables": 2, "lightings": 2}
    del items
    gc.collect()
    assert first() is None, "a dropped table texture is still referenced"

    items = show([0, 1, 2, 3])
    assert len(items) == 4 and all(len(m) == 4 for m in maps.values())
    builds = sd.CACHES.stats["batch_builds"]
    assert len(show([0, 1, 2, 3])) == 4 and sd.CACHES.stats["batch_builds"] == builds  # kept
    show([0, 1])
    assert all(len(m) == 2 for m in maps.values())


# ----------------------------------------------------------------------------------------------
# The thickness follows its inputs
# ----------------------------------------------------------------------------------------------
def uploaded(tf, name: str) -> np.ndarray:
    entry = tf.scene_draw.batch_entry(name)
    assert entry is not None and entry.batch is not None and entry.batch.has_thickness
    return entry.thickness


def test_changing_the_noise_scale_or_seed_changes_the_preview(bpy, tf, scene, monkeypatch):
    sd = tf.scene_draw
    mat = film(bpy, tf, "Noisy", vary=True)
    settings = mat.thinfilm_sh
    settings.thickness_source = "NOISE"
    settings.noise_scale, settings.noise_seed = 2.0, 1
    obj = grid(bpy, scene, "Sheet", mat)
    collect(bpy, tf)
    first = uploaded(tf, "Sheet").copy()
    expected = tf.thickness.thickness_per_vertex(obj, obj.data, settings)
    np.testing.assert_array_equal(first, expected.astype(np.float32))  # what the draw uploads
    entry, builds = sd.batch_entry("Sheet"), sd.CACHES.stats["batch_builds"]
    assert sd.batch_entry("Sheet").batch.noise == (2.0, 1)  # and per pixel (TF_THICKNESS_NOISE)

    collect(bpy, tf)  # nothing changed: nothing rebuilt
    assert sd.CACHES.stats["batch_builds"] == builds and sd.batch_entry("Sheet") is entry

    settings.noise_scale = 5.0
    items, _ = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())  # no view-layer update
    scaled = uploaded(tf, "Sheet")
    assert sd.CACHES.stats["batch_builds"] == builds + 1 and items[0].batch is sd.batch_entry("Sheet").batch
    assert np.abs(scaled - first).max() > 0.05
    np.testing.assert_array_equal(
        scaled, tf.thickness.thickness_per_vertex(obj, obj.data, settings).astype(np.float32)
    )
    collect(bpy, tf)
    assert sd.CACHES.stats["batch_builds"] == builds + 1

    settings.noise_seed = 2
    collect(bpy, tf)
    assert sd.CACHES.stats["batch_builds"] == builds + 2
    assert sd.batch_entry("Sheet").batch.noise == (5.0, 2)
    assert np.abs(uploaded(tf, "Sheet") - scaled).max() > 0.05

    # Blender's Noise Texture: computed the same way, per pixel (kind 1) and at the corners, with
    # no bake queued (a dragged scale shows at once)
    settings.thickness_source = "BLENDER_NOISE"
    collect(bpy, tf)
    assert sd.CACHES.stats["batch_builds"] == builds + 3 and not tf.linked.has_pending()
    blender_noise = sd.batch_entry("Sheet").batch.noise  # Blender's 4-D Noise Texture, W = the seed
    assert (blender_noise.dimensions, blender_noise.scale, blender_noise.w) == (4, 5.0, 2.0)
    blender = uploaded(tf, "Sheet")
    np.testing.assert_array_equal(
        blender, tf.thickness.thickness_per_vertex(obj, obj.data, settings).astype(np.float32)
    )
    assert np.ptp(blender) > 0.1  # it varies over the sheet

    # on a mesh past linked_nodes.INLINE_VERTICES the draw computes no corner: per pixel at once,
    # the corners at the middle of the range until the viewport's timer has computed them
    monkeypatch.setattr(tf.linked.linked_nodes, "INLINE_VERTICES", 10)
    settings.noise_seed = 3
    with tf.linked.deferring():
        collect(bpy, tf)
    assert sd.batch_entry("Sheet").batch.noise.w == 3.0
    np.testing.assert_array_equal(uploaded(tf, "Sheet"), tf.thickness.NAN_PARAMETER)
    assert tf.linked.has_pending() and tf.linked.run_pending() == []
    with tf.linked.deferring():
        collect(bpy, tf)
    np.testing.assert_array_equal(
        uploaded(tf, "Sheet"), tf.thickness.thickness_per_vertex(obj, obj.data, settings).astype(np.float32)
    )


def test_editing_the_thickness_attribute_or_image_changes_the_preview(bpy, tf, scene):
    sd = tf.scene_draw
    mat = film(bpy, tf, "Mapped", vary=True)
    settings = mat.thinfilm_sh
    settings.thickness_source = "ATTRIBUTE"
    settings.thickness_attribute = "film"
    obj = grid(bpy, scene, "Sheet", mat, n=1)
    mesh = obj.data
    attribute = mesh.attributes.new("film", "FLOAT", "POINT")
    attribute.data.foreach_set("value", [0.1, 0.2, 0.3, 0.4])
    collect(bpy, tf)
    corner_vertices = [loop.vertex_index for loop in mesh.loops]
    np.testing.assert_allclose(
        uploaded(tf, "Sheet"), np.array([0.1, 0.2, 0.3, 0.4])[corner_vertices], rtol=1e-6
    )

    mesh.attributes["film"].data.foreach_set("value", [0.9, 0.8, 0.7, 0.6])
    mesh.update()  # a depsgraph geometry update, as an edit in Blender sends
    collect(bpy, tf)
    np.testing.assert_allclose(
        uploaded(tf, "Sheet"), np.array([0.9, 0.8, 0.7, 0.6])[corner_vertices], rtol=1e-6
    )

    # An image: drawn per pixel from Blender's own texture of it, which follows an edit of its
    # pixels with no rebuild; the corners are read again when the image's identity changes.
    uv = mesh.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.full(2 * len(mesh.loops), 0.5, dtype=np.float32))
    image = bpy.data.images.new("Thickness", 2, 2, float_buffer=True)
    image.pixels.foreach_set(np.full(16, 0.25, dtype=np.float32))
    settings.thickness_source = "IMAGE"
    settings.thickness_image = image
    collect(bpy, tf)
    np.testing.assert_allclose(uploaded(tf, "Sheet"), 0.25)

    def drawn_texel():
        texture = sd.batch_entry("Sheet").batch.map_texture()
        return np.asarray(texture.read().to_list(), dtype=np.float64)[0, 0, 0]

    assert drawn_texel() == 0.25
    builds = sd.CACHES.stats["batch_builds"]
    image.pixels.foreach_set(np.full(16, 0.75, dtype=np.float32))  # as a paint stroke does
    collect(bpy, tf)
    assert sd.CACHES.stats["batch_builds"] == builds  # nothing read or rebuilt in the draw
    assert drawn_texel() == 0.75
    image.scale(4, 4)  # the image's identity changed: the corners are read again
    collect(bpy, tf)
    assert sd.CACHES.stats["batch_builds"] == builds + 1
    np.testing.assert_allclose(uploaded(tf, "Sheet"), 0.75)
    assert drawn_texel() == 0.75


def test_an_image_thickness_is_drawn_per_pixel_while_the_timer_reads_its_corners(bpy, tf, scene):
    """In the viewport's draw (``linked.deferring``) the Image source reads no pixels: the film is
    drawn from Blender's texture of the image at once, the corners at the middle of the range,
    and the timer (``linked.run_pending``) reads the corners. An image holding NaN is drawn from a
    map of its pixels instead (Blender's texture turns NaN into 0), those pixels mid-range."""
    sd, nan_parameter = tf.scene_draw, tf.thickness.NAN_PARAMETER
    mat = film(bpy, tf, "Painted", vary=True)
    settings = mat.thinfilm_sh
    obj = grid(bpy, scene, "Canvas", mat, n=2)
    corners = np.array([obj.data.vertices[loop.vertex_index].co[0] for loop in obj.data.loops])
    uv = obj.data.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.stack([0.5 + 0.4 * corners, np.full_like(corners, 0.5)], 1).ravel())
    image = bpy.data.images.new("Ramp", 8, 1, float_buffer=True)
    ramp = np.zeros((1, 8, 4), dtype=np.float32)
    ramp[..., 0] = np.linspace(0.1, 0.8, 8)
    image.pixels.foreach_set(ramp.ravel())
    settings.thickness_source, settings.thickness_image = "IMAGE", image
    with tf.linked.deferring():
        collect(bpy, tf)
    entry = sd.batch_entry("Canvas")
    assert type(entry.batch.thickness_map).__name__ == "ImageTexture"
    assert entry.batch.map_texture() is not None  # Blender's own texture, drawn per pixel now
    np.testing.assert_array_equal(entry.thickness, nan_parameter)  # the corners: queued
    assert tf.linked.has_pending()
    assert tf.linked.run_pending() == []  # the viewport's timer
    with tf.linked.deferring():
        collect(bpy, tf)
    expected = tf.thickness.thickness_per_vertex(obj, obj.data, settings)
    assert np.ptp(expected) > 0.3
    np.testing.assert_allclose(uploaded(tf, "Canvas"), expected, rtol=1e-6)
    assert type(sd.batch_entry("Canvas").batch.thickness_map).__name__ == "ImageTexture"

    ramp[0, 0, 0] = np.nan
    holed = bpy.data.images.new("Holed", 8, 1, float_buffer=True)
    holed.pixels.foreach_set(ramp.ravel())
    settings.thickness_image = holed
    with tf.linked.deferring():
        collect(bpy, tf)
    assert tf.linked.run_pending() == []
    with tf.linked.deferring():
        _, messages = collect(bpy, tf)
    texture = sd.batch_entry("Canvas").batch.map_texture()
    assert texture.format == "R32F"  # the pixels' map, NaN at the middle of the range
    texels = np.asarray(texture.read().to_list(), dtype=np.float64).reshape(-1)
    np.testing.assert_allclose(texels, [nan_parameter, *np.linspace(0.1, 0.8, 8)[1:]], rtol=1e-6)
    assert any("'Canvas'" in m and "NaN" in m for m in messages), messages

    tiled = bpy.data.images.new("Tiles", 8, 1, float_buffer=True, tiled=True)  # UDIM: its 1001 tile
    ramp[0, 0, 0] = 0.1
    tiled.pixels.foreach_set(ramp.ravel())
    settings.thickness_image = tiled
    with tf.linked.deferring():
        collect(bpy, tf)
    assert sd.batch_entry("Canvas").batch.map_texture() is None  # per corner until the timer
    assert tf.linked.run_pending() == []
    with tf.linked.deferring():
        collect(bpy, tf)
    texture = sd.batch_entry("Canvas").batch.map_texture()
    assert texture.format == "R32F"  # the first tile's pixels, not Blender's array of tiles
    texels = np.asarray(texture.read().to_list(), dtype=np.float64).reshape(-1)
    np.testing.assert_allclose(texels, np.linspace(0.1, 0.8, 8), rtol=1e-6)


def test_nan_thickness_values_are_reported_and_drawn_mid_range(bpy, tf, scene):
    mat = film(bpy, tf, "Holes", vary=True)
    mat.thinfilm_sh.thickness_source = "ATTRIBUTE"
    mat.thinfilm_sh.thickness_attribute = "film"
    obj = grid(bpy, scene, "Torn", mat, n=1)
    obj.data.attributes.new("film", "FLOAT", "POINT").data.foreach_set("value", [0.2, float("nan"), 0.0, 1.0])
    for _ in range(2):  # built, then from the cache: reported on every frame
        items, messages = collect(bpy, tf)
        assert len(items) == 1
        named = [m for m in messages if "'Torn'" in m]
        assert named and "1 of 4 thickness values are NaN" in named[0], messages
    values = uploaded(tf, "Torn")
    corner_vertices = np.array([loop.vertex_index for loop in obj.data.loops])
    assert np.isfinite(values).all()
    np.testing.assert_array_equal(values[corner_vertices == 1], tf.thickness.NAN_PARAMETER)
    np.testing.assert_allclose(values[corner_vertices == 0], 0.2, rtol=1e-6)
    assert tf.scene_draw.object_notes("Torn") == named


def test_a_material_edit_that_leaves_the_thickness_alone_rebuilds_no_batch(bpy, tf, scene):
    """The thickness inputs are in the batch's signature, so other material edits (a roughness
    drag: a new table each step) need not rebuild the mesh batches of its users."""
    sd = tf.scene_draw
    mat = film(bpy, tf, "Dragged", vary=True)
    mat.thinfilm_sh.thickness_source = "NOISE"
    grid(bpy, scene, "Sheet", mat, n=2)
    collect(bpy, tf)
    batch, builds = sd.batch_entry("Sheet").batch, sd.CACHES.stats["batch_builds"]
    mat.thinfilm_sh.roughness = 0.55
    items, _ = collect(bpy, tf)
    assert items[0].roughness == pytest.approx(0.55) and items[0].batch is batch
    assert sd.CACHES.stats["batch_builds"] == builds
