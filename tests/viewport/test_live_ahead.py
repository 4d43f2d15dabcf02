"""An edit's work starts before its first redraw and arrives whole (issue 16, addon/bakes/bake_asks.py).

- The depsgraph update that follows an edit (Blender runs ``depsgraph_update_post`` before it
  redraws) starts the edited material's bake, once a viewport has drawn films; before any
  viewport drew, it starts nothing.
- A film drawn from an outgoing-radiance grid gets its new grid built by the bake's worker right
  after the table: the redraw the bake's end asks for draws the grid, with no grid left to build.
- While a superseded bake is stopping no newer one starts (on two cores a drag's newest bake would
  share them with every older one).
- The table kept in memory drops the bake's reflectance at its u nodes (only the film table
  reads it, once).

Nothing here is timed: the latency figures are in benchmarks/latency.py → docs/latency.md.
"""

from __future__ import annotations

import importlib
import threading

import pytest
from _waits import EVENT_TIMEOUT_S, wait_for
from test_radiance_grid_viewport import record_builds
from test_viewport_state import collect, film
from test_viewport_state import grid as quad_grid

pytestmark = pytest.mark.blender


class Gate:
    """``bake.bake`` held at its start until :meth:`open`, recording which descriptions started."""

    def __init__(self, tf, monkeypatch):
        self.real = tf.bake.bake
        self.opened = threading.Event()
        self.started: list[float] = []
        monkeypatch.setattr(tf.bake, "bake", self)

    def __call__(self, material, progress=None):
        self.started.append(float(material.layers[0].thickness_nm))
        assert self.opened.wait(EVENT_TIMEOUT_S), "the gate was never opened"
        return self.real(material, progress)

    def open(self):
        self.opened.set()


def drawn_once(bpy, tf, scene, mat):
    """The material drawn as the viewport would after its first frames: lit, baked, its entry
    kept; and the viewport marked as drawing films (what ``draw_callback`` sets)."""
    quad_grid(bpy, scene, "Quad", mat, n=2)
    tf.world_state.world_lighting(scene, allow_compute=True)
    (item,), _ = collect(bpy, tf)  # headless path: bakes (and builds a grid) in place
    tf.viewport._drawn.set()
    return item


def test_the_edits_bake_starts_at_the_depsgraph_update(bpy, tf, scene, monkeypatch):
    bj = tf.bake_jobs
    mat = film(bpy, tf, "Edited")
    drawn_once(bpy, tf, scene, mat)
    gate = Gate(tf, monkeypatch)
    mat.thinfilm_sh.layers[0].thickness_nm = 420.0
    bpy.context.view_layer.update()  # Blender's depsgraph update: our handler runs, no draw yet
    wait_for(lambda: gate.started, "the bake to start")
    assert gate.started == [420.0] and len(bj.BAKES.running) == 1
    gate.open()
    wait_for(lambda: not bj.BAKES.running, "the bake")
    key = tf.scene_draw.description.description_key(tf.scene_draw.description.description(mat))
    assert tf.tables.MEMORY.get(key) is not None
    assert bj.BAKES.finished()  # the timer's cue: the redraw that shows it


def test_before_any_viewport_drew_an_edit_starts_nothing(bpy, tf, scene, monkeypatch):
    vp = tf.viewport
    bj = tf.bake_jobs
    mat = film(bpy, tf, "Headless")
    drawn_once(bpy, tf, scene, mat)
    vp._drawn.clear()  # e.g. a headless render: no viewport draws films
    gate = Gate(tf, monkeypatch)
    gate.open()
    mat.thinfilm_sh.layers[0].thickness_nm = 430.0
    bpy.context.view_layer.update()
    assert not gate.started and not bj.BAKES.running and not bj._pending


def test_a_grid_films_bake_brings_its_grid(bpy, tf, scene, monkeypatch):
    bj = tf.bake_jobs
    rg = importlib.import_module(f"{tf.package.__name__}.addon.bakes.radiance_grids")
    mat = film(bpy, tf, "Rough", roughness=0.6)
    mat.thinfilm_sh.sh_order = "3"  # l ≥ policy.GRID_MIN_L: the SH half is read from a grid
    item = drawn_once(bpy, tf, scene, mat)
    assert item.grid is not None
    built_on = record_builds(rg, monkeypatch)
    mat.thinfilm_sh.layers[0].thickness_nm = 610.0
    bpy.context.view_layer.update()  # the bake starts, with the grid chained to it
    wait_for(lambda: not bj.BAKES.running, "the bake and its grid")
    assert len(built_on) == 1 and built_on[0] is not threading.main_thread()
    assert not rg.busy()
    # the one redraw the bake's end asks for: the new table and its grid, nothing left to build
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False, bake_later=True)
    assert item.grid is not None and not item.grid_pending
    assert not rg.busy() and not bj._pending and len(built_on) == 1
    key = tf.scene_draw.description.description_key(tf.scene_draw.description.description(mat))
    assert item.table is tf.scene_draw.CACHES.tables.get(key)


def test_no_bake_starts_while_a_superseded_one_stops(bpy, tf, scene, monkeypatch):
    bj = tf.bake_jobs
    mat = film(bpy, tf, "Dragged")
    desc = tf.scene_draw.description.description(mat)
    stopping = bj.BakeJob(desc, key="an older value", viewport=True)
    stopping.cancel()  # superseded: it stops at its next checkpoint
    monkeypatch.setattr(bj.BAKES, "running", {stopping.key: stopping})
    monkeypatch.setattr(bj, "_pending", {})
    monkeypatch.setattr(bj, "_wanted", {})
    bj.want(desc, owner="material")
    assert bj.start_ready() == [] and "material" in bj._pending
    del bj.BAKES.running[stopping.key]  # it stopped
    (started,) = bj.start_ready()
    assert started.desc is desc and not bj._pending
    bj.BAKES.running.clear()


def test_the_table_in_memory_drops_the_reflectance_at_its_nodes(bpy, tf, scene):
    """A fresh bake's reflectance at its u nodes (up to 4.5 MiB) is kept only for the film table
    the viewport's worker computes next (keep_nodes), then dropped; by default it is not kept."""
    first = tf.scene_draw.description.description(film(bpy, tf, "Plain"))
    result, source = tf.tables.get_table_with_source(first, store=False)
    assert source == "bake" and result.node_reflectance is None
    desc = tf.scene_draw.description.description(film(bpy, tf, "Kept", roughness=0.45))
    result, source = tf.tables.get_table_with_source(desc, store=False, keep_nodes=True)
    key = tf.scene_draw.description.description_key(desc)
    assert source == "bake" and result.node_reflectance is not None
    assert tf.tables.MEMORY.get(key) is result  # one object: the caller's and the cache's
    film_table = tf.tables.get_film(desc, result)
    assert film_table.reflectance.shape[0] == result.data.shape[0]
    assert result.node_reflectance is None


def test_a_superseded_jobs_grid_stops_at_its_next_step(bpy, tf, scene):
    """The grid a bake's worker builds after the table runs its steps under the job's cancel:
    superseded mid-build (a drag moved on) it stops at the next step instead of finishing a
    grid nobody wants, and the worker treats it as a cancelled bake."""
    progress = importlib.import_module(f"{tf.package.__name__}.precompute.bakes.progress")
    steps = []
    job = tf.bake_jobs.BakeJob(None, key="superseded", viewport=True)

    def then(key, desc, result):
        for step in range(4):
            steps.append(step)
            if step == 1:
                job.cancel()  # a newer value arrived
            progress.checkpoint()

    job.then = then
    with pytest.raises(tf.workers.Cancelled):
        job._then(None)
    assert steps == [0, 1]


def test_the_grid_build_has_steps_to_stop_at():
    """radiance_grid.build reports between its steps (the World part, then each colour channel)."""
    import numpy as np

    from precompute.bakes import bake, progress
    from precompute.materials.material import Layer, Material, Quality
    from precompute.shading import radiance_grid

    film = Layer(1.33, 400.0)
    result = bake.bake(Material(layers=(film,), substrate=1.5, roughness=0.6, quality=Quality(sh_order=3)))
    coeffs = np.ones((16, 3))
    calls = []
    with progress.reporting(lambda: calls.append(1)):
        radiance_grid.build(result, coeffs, (8, 4, result.data.shape[1], 4))
    assert len(calls) >= 4


@pytest.mark.parametrize("how", ["superseded", "cancel button"])
def test_a_cancelled_bake_asks_for_a_redraw_only_when_the_user_cancelled(bpy, tf, scene, monkeypatch, how):
    """A bake superseded by a newer value has nothing to show (its redraw would only delay the
    one that shows the newest table); one the Cancel button stopped asks for a redraw, so the
    header stops saying it bakes."""
    bj = tf.bake_jobs
    mat = film(bpy, tf, "Cancelled")
    drawn_once(bpy, tf, scene, mat)
    gate = Gate(tf, monkeypatch)
    mat.thinfilm_sh.layers[0].thickness_nm = 440.0
    bpy.context.view_layer.update()
    wait_for(lambda: gate.started, "the bake to start")
    (job,) = bj.BAKES.running.values()
    bj.BAKES.take_finished()
    if how == "superseded":
        mat.thinfilm_sh.layers[0].thickness_nm = 450.0
        bpy.context.view_layer.update()  # the newer value's bake waits for this one to stop
        assert job.superseded and job.cancelled
    else:
        assert bj.cancel_all() == 1 and not job.superseded
    gate.open()
    wait_for(lambda: job.key not in bj.BAKES.running, "the cancelled bake to stop")
    assert bj.BAKES.finished() == (how == "cancel button")
    bj.cancel_all()
    wait_for(lambda: not bj.BAKES.running, "the bakes")
