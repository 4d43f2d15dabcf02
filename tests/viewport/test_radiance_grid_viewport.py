"""The outgoing-radiance grid in the add-on (addon/bakes/radiance_grids.py through scene_draw.collect).

- the viewport's collect never builds a grid: it asks the worker and draws the per-pixel SH
  meanwhile; once built, the next frame reads the grid (and a timer asks for that redraw);
- a headless frame (allow_bake) builds it in place, so it draws what the viewport will;
- only constant-thickness films at l_max ≥ policy.GRID_MIN_L get one;
- a drag queues at most QUEUE_SIZE grids, newest first.
"""

from __future__ import annotations

import threading

import pytest
from _waits import EVENT_TIMEOUT_S, CueRecorder, HeldCall, wait_for
from test_viewport_state import collect, film
from test_viewport_state import grid as quad_grid

pytestmark = pytest.mark.blender


def rough_film(bpy, tf, name, roughness=0.6, vary=False, order="3"):
    mat = film(bpy, tf, name, roughness=roughness, vary=vary)
    mat.thinfilm_sh.sh_order = order
    return mat


def grids_module(tf):
    import importlib

    return importlib.import_module(f"{tf.package.__name__}.addon.bakes.radiance_grids")


def wait_idle(module):
    wait_for(lambda: not module.busy(), "the radiance grid worker to finish")


def record_builds(rg, monkeypatch) -> list:
    """The threads ``radiance_grid.build`` runs on, from now on (a list that grows)."""
    built_on = []
    real_build = rg.radiance_grid.build

    def build(*args, **kwargs):
        built_on.append(threading.current_thread())
        return real_build(*args, **kwargs)

    monkeypatch.setattr(rg.radiance_grid, "build", build)
    return built_on


def test_viewport_asks_the_worker_and_draws_the_grid_when_built(bpy, tf, scene, monkeypatch):
    rg = grids_module(tf)
    rg.GRIDS.clear()
    built_on = record_builds(rg, monkeypatch)
    quad_grid(bpy, scene, "Quad", rough_film(bpy, tf, "Rough"))
    collect(bpy, tf)  # bakes the table (allow_bake) and builds its grid in place
    assert built_on == [threading.main_thread()]
    rg.GRIDS.clear()
    built_on.clear()
    # the worker holds here until the "still building" state is checked; patched before
    # collect, which binds the build
    gate = HeldCall(rg.radiance_grid, "build", monkeypatch)
    # the viewport: no build on this thread, the per-pixel SH meanwhile
    cue = CueRecorder(rg.busy)  # what _poll reads beside the cue (GRIDS.lock is reentrant)
    monkeypatch.setattr(rg.GRIDS.work, "_finished", cue)
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)
    assert item.grid is None and item.grid_pending and rg.busy() and "tabulating" in rg.activity()
    assert bpy.app.timers.is_registered(rg._poll)
    gate.open()
    wait_idle(rg)
    assert built_on and all(t is not threading.main_thread() for t in built_on)
    assert rg.GRIDS.work.finished(), "the worker ended without the timer's cue for a redraw"
    assert cue.seen == [True], (
        f"the grid worker set its cue with busy()={cue.seen}: set after it stopped looking busy, a "
        "timer tick in between sees neither and stops, and the redraw with the grid never comes"
    )
    rg._poll()
    assert not rg.GRIDS.work.finished()
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)
    assert item.grid is not None and not item.grid_pending
    prepared = tf.package.addon.gpu.draw.prepare_draw([item], _eye(), _eye(), display_srgb=True)
    assert prepared.groups[0].variant.grid
    # the same frame again: the uploaded grid is reused, nothing is built
    built_on.clear()
    (again,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)
    assert again.grid is item.grid and not built_on and not rg.busy()


def _eye():
    import numpy as np

    return np.eye(4)


@pytest.mark.parametrize("vary, order", [(True, "3"), (False, "2")])
def test_no_grid_for_varying_thickness_or_low_orders(bpy, tf, scene, vary, order):
    rg = grids_module(tf)
    rg.GRIDS.clear()
    quad_grid(bpy, scene, "Quad", rough_film(bpy, tf, "Film", vary=vary, order=order))
    (item,), _ = collect(bpy, tf)
    assert item.grid is None and not item.grid_pending and not rg.busy()


def test_a_drag_queues_few_grids_newest_first(bpy, tf, scene, monkeypatch):
    rg = grids_module(tf)
    rg.GRIDS.clear()
    gate = threading.Event()
    order = []
    real_build = rg.radiance_grid.build

    def slow_build(result, coeffs, *args, **kwargs):
        gate.wait(EVENT_TIMEOUT_S)
        order.append(round(float(result.material.roughness), 3))
        return real_build(result, coeffs, *args, **kwargs)

    mat = rough_film(bpy, tf, "Dragged", roughness=0.5)
    quad_grid(bpy, scene, "Quad", mat)
    steps = [0.5 + 0.02 * k for k in range(8)]
    for r in steps:  # bake every step first (not what is measured here)
        mat.thinfilm_sh.roughness = r
        collect(bpy, tf)
    monkeypatch.setattr(rg.radiance_grid, "build", slow_build)
    rg.GRIDS.clear()
    for k, r in enumerate(steps):  # the drag: one frame per step, the worker held on the first grid
        mat.thinfilm_sh.roughness = r
        items, messages = collect(bpy, tf, allow_bake=False, allow_world=False)
        assert len(items) == 1 and items[0].grid is None, messages
        if k == 0:  # the worker took the first step's grid
            wait_for(lambda: rg.GRIDS.running is not None, "the grid worker to start")
    with rg.GRIDS.lock:
        queued = len(rg.GRIDS.queue)
    assert queued == rg.QUEUE_SIZE, (queued, rg.GRIDS.running)
    gate.set()
    wait_idle(rg)
    assert len(order) <= rg.QUEUE_SIZE + 1, order
    assert order[1] == round(steps[-1], 3), order  # after the one running, the newest


def test_the_idle_step_compiles_one_wanted_variant_and_says_so(bpy, tf):
    import importlib

    from precompute.shading.variant import Variant

    warmup = importlib.import_module(f"{tf.package.__name__}.addon.drawing.shader_warmup")
    shaders = importlib.import_module(f"{tf.package.__name__}.addon.gpu.shaders").SHADERS
    first, second = Variant(0, False, False, True), Variant(1, False, False, True)
    for v in (first, second):
        if shaders.compiled(v):
            shaders._shaders.pop(v)
        shaders.want(v)
    assert "compiling shaders (2 left)" in warmup.activity()
    assert "compiling shaders" in tf.viewport.activity()
    warmup.schedule()
    assert bpy.app.timers.is_registered(warmup.step)
    assert warmup.step() == 0.05 and shaders.compiled(first) and not shaders.compiled(second)
    assert warmup.step() is None and shaders.compiled(second) and warmup.activity() == ""
    warmup.unregister()
    assert not bpy.app.timers.is_registered(warmup.step)


def grey_world_and_cheap_builds(bpy, tf, scene, monkeypatch, name: str, roughness_arg: int):
    """(the grids module, the roughness of each ``lobe_grid.<name>`` call from now on): the
    grids emptied, a grey World, and the integrated builds at 4 × 4 nodes (cheap: what is drawn
    is tested, not the quadrature)."""
    rg = grids_module(tf)
    rg.GRIDS.clear()
    world = bpy.data.worlds.new("Grey")  # a node tree from Blender 5 on
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.5, 0.4, 0.3, 1.0)
    scene.world = world
    calls = []
    real_build = getattr(rg.lobe_grid, name)

    def build(*args, **kwargs):
        calls.append(args[roughness_arg])
        return real_build(*args, **{**kwargs, "samples": (4, 4)})

    monkeypatch.setattr(rg.lobe_grid, name, build)
    return rg, calls


@pytest.mark.parametrize(
    "preset, roughness, integrated",
    [("ANODISED_TITANIUM", 0.3, True), ("ANODISED_TITANIUM", 0.6, False), ("SOAP_FILM", 0.3, False)],
)
def test_a_film_in_the_hand_over_integrates_its_grid(
    bpy,
    tf,
    scene,
    monkeypatch,
    preset,
    roughness,
    integrated,
):
    """Roughness 0.2–0.45 (policy.uses_lobe_grid): the grid is the exact lobe against the World's
    panorama (precompute.shading.lobe_grid), weighted policy.LOBE_GRID_WEIGHT against the split
    sum; rougher films keep the SH grid at weight 1, and so does a transparent film (a soap
    film's wall), whose table holds more than the lobe."""
    from precompute.shading import policy

    rg, calls = grey_world_and_cheap_builds(bpy, tf, scene, monkeypatch, "build", 1)
    mat = rough_film(bpy, tf, "Film")
    mat.thinfilm_sh.preset = preset
    mat.thinfilm_sh.vary_thickness = False
    mat.thinfilm_sh.roughness = roughness
    mat.thinfilm_sh.sh_order = "3"
    quad_grid(bpy, scene, "Quad", mat)
    (item,), messages = collect(bpy, tf)
    assert item.grid is not None, messages
    assert bool(calls) == integrated
    assert item.sh_weight == pytest.approx(policy.grid_weight(roughness, integrated))
    expected = policy.LOBE_GRID_WEIGHT if integrated else policy.sh_weight(roughness)
    assert item.sh_weight == pytest.approx(expected)


def test_the_sh_grid_stands_in_while_the_lobe_grid_is_built(bpy, tf, scene, monkeypatch):
    """In the viewport an integrated grid takes 15–100 s of numpy: the SH grid (under a second,
    asked for after it, so built first) is drawn meanwhile at the SH weight, then the lobe grid
    at its own weight once the worker is done."""
    from precompute.shading import policy

    rg = grids_module(tf)
    rg.GRIDS.clear()
    world = bpy.data.worlds.new("Grey")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.5, 0.4, 0.3, 1.0)
    scene.world = world
    gate = threading.Event()
    real_build = rg.lobe_grid.build

    def held(*args, **kwargs):
        gate.wait(EVENT_TIMEOUT_S)
        return real_build(*args, **{**kwargs, "samples": (4, 4)})

    mat = rough_film(bpy, tf, "Film", roughness=0.3)
    mat.thinfilm_sh.preset = "ANODISED_TITANIUM"
    mat.thinfilm_sh.vary_thickness = False
    mat.thinfilm_sh.roughness = 0.3
    mat.thinfilm_sh.sh_order = "3"
    quad_grid(bpy, scene, "Quad", mat)
    monkeypatch.setattr(rg.lobe_grid, "build", lambda *a, **k: real_build(*a, **{**k, "samples": (4, 4)}))
    collect(bpy, tf)  # the table and film baked here (not what is tested)
    rg.GRIDS.clear()
    monkeypatch.setattr(rg.lobe_grid, "build", held)
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)
    assert item.grid is None and item.grid_pending
    wait_for(lambda: rg.GRIDS.built, "the SH grid, built first")
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)
    assert item.grid is not None and item.sh_weight == pytest.approx(policy.sh_weight(0.3))
    assert rg.busy()  # the lobe grid is still being built
    gate.set()
    wait_idle(rg)
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)
    assert item.grid is not None and item.sh_weight == pytest.approx(policy.grid_weight(0.3, True))


def test_a_varying_film_in_the_hand_over_reads_the_basis_grid(bpy, tf, scene, monkeypatch):
    """A varying thickness at roughness 0.3: no grid per thickness row, but the film-free basis
    grid of its roughness and World (precompute.shading.lobe_grid.build_basis), built in place
    for a headless frame and on the worker for the viewport (the per-pixel SH meanwhile), read
    with the film table at the integrated grid's weight; a second varying film of that roughness
    reads the same basis, built once."""
    from precompute.shading import policy

    rg, calls = grey_world_and_cheap_builds(bpy, tf, scene, monkeypatch, "build_basis", 0)
    mats = []
    for name in ("Film", "Other film"):
        mat = rough_film(bpy, tf, name, roughness=0.3, vary=True)
        mat.thinfilm_sh.preset = "ANODISED_TITANIUM"
        mat.thinfilm_sh.vary_thickness = True
        mat.thinfilm_sh.roughness = 0.3
        mat.thinfilm_sh.sh_order = "3"
        mats.append(mat)
    quad_grid(bpy, scene, "Quad", mats[0])
    (item,), messages = collect(bpy, tf)
    assert item.grid is not None and item.film is not None, messages
    assert calls == [pytest.approx(0.3)]
    layers = (policy.GRID_BASIS_VIEWS + 1) * policy.GRID_AZIMUTHS
    assert item.grid.shape == (
        policy.GRID_HATS * (policy.GRID_MIRROR[0] + 2),
        policy.GRID_MIRROR[1],
        layers // policy.GRID_AZIMUTHS,
        policy.GRID_AZIMUTHS,
    )
    assert item.sh_weight == pytest.approx(policy.grid_weight(0.3, True))
    bpy.data.objects["Quad"].data.materials[0] = mats[1]
    (item,), _ = collect(bpy, tf)
    assert item.grid is not None and len(calls) == 1  # the same basis
    rg.GRIDS.clear()
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)  # the viewport: the worker
    assert item.grid is None and item.grid_pending
    wait_idle(rg)
    rg._poll()
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False)
    assert item.grid is not None and not item.grid_pending and len(calls) == 2
