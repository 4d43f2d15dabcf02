"""Viewport bakes in the bake helper process (issue 16, addon/bakes/bake_helper.py and
addon/bakes/bake_process.py).

A bake on a thread of Blender's process waits for Python's lock whenever the main thread draws;
the helper bakes in a process of its own. With the real bpy and the viewport's own path
(``collect`` asks, the timer ``_service`` starts the worker, the worker hands the bake over):

- the table and film table the helper bakes equal the in-process ones bit for bit, and no bake
  runs in this process;
- a bake's own error comes back as its exception; a superseded bake is cancelled in the helper,
  which goes on serving;
- a helper that cannot start, exits, is killed mid-bake or stays silent is given up once,
  logged, and the table is baked in process: the film is still drawn;
- the preference and ``THINFILM_SH_BAKE_HELPER=0`` turn it off; closing its stdin ends it, and
  ``unregister`` leaves no process.

The conftest turns the helper off for every other test module (they replace ``bake.bake``);
this module turns it on. Nothing here is timed (docs/latency.md has the figures).
"""

from __future__ import annotations

import importlib
import io
import logging
import os
import signal
import sys
import threading
import types

import numpy as np
import pytest
from _extension import assert_helper_ends_with_stdin_and_unregister
from _waits import EVENT_TIMEOUT_S, wait_for
from test_viewport_state import collect, film, grid, redraw

pytestmark = pytest.mark.blender


def same_bake(got, expected, what: str) -> None:
    """A table from the helper process against the same bake here: the same code in another
    process (its BLAS single-threaded), so equal up to float64 rounding; another material's
    table, a mixed-up answer or a lost row differs by far more than 1e-12."""
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15, err_msg=what)


@pytest.fixture
def helper(tf, monkeypatch):
    """The bake helper module, turned on, no process running and none given up; ``tf.in_process``
    counts the bakes run in this process."""
    monkeypatch.setenv("THINFILM_SH_BAKE_HELPER", "1")
    module = importlib.import_module(f"{tf.package.__name__}.addon.bakes.bake_helper")
    module.unregister()
    tf.in_process = []
    real = tf.bake.bake

    def counting(material, progress=None):
        tf.in_process.append(material)
        return real(material, progress)

    monkeypatch.setattr(tf.bake, "bake", counting)
    tf.film_colour = importlib.import_module(f"{tf.package.__name__}.precompute.colour.film_colour")
    tf.Material = importlib.import_module(f"{tf.package.__name__}.precompute.materials.material").Material
    tf.real_bake = real
    yield module
    module.unregister()


_FILMS = iter(range(1000))


def soap(bpy, tf):
    """A glossy soap film with a thickness range of its own: a table no other test baked (a
    viewport worker writes its table's disk copy up to 1 s after its bake, so an earlier test's
    table can arrive in the disk cache after this test's fixture emptied it)."""
    mat = film(bpy, tf, "Soap", roughness=0.05, vary=True)
    mat.thinfilm_sh.thickness_max_nm = 900.0 + next(_FILMS)
    return mat


def description(tf, mat):
    return tf.scene_draw.description.description(mat)


def drawn(bpy, tf, scene, mat):
    """One viewport redraw that asks for ``mat``'s table (and film table), then the next frame's
    items once the worker is done."""
    grid(bpy, scene, "Quad", mat, n=2)
    tf.world_state.world_lighting(scene, allow_compute=True)
    redraw(bpy, tf)
    items, _messages = redraw(bpy, tf)
    return items


def test_the_viewports_bake_runs_in_the_helper_equal_to_in_process(bpy, tf, scene, helper):
    baked = helper.STATS["baked"]
    mat = soap(bpy, tf)
    items = drawn(bpy, tf, scene, mat)
    assert len(items) == 1  # the film is drawn
    assert helper.STATS["baked"] == baked + 1 and helper.process_id() is not None
    assert tf.in_process == []  # no bake in this process
    desc = description(tf, mat)
    key = tf.scene_draw.description.description_key(desc)
    table = tf.tables.MEMORY.get(key)
    here = tf.real_bake(desc)  # the same function in this process
    same_bake(table.data, here.data, "the table baked by the helper process")
    assert table.material == here.material and table.u_nodes == here.u_nodes
    assert table.sh_order == here.sh_order and table.reasons == here.reasons
    for name in ("view_angles_rad", "thicknesses_nm", "wavelengths_nm"):
        same_bake(getattr(table, name), getattr(here, name), f"the helper's {name}")
    info = helper.info()
    assert info["bake_ms"] > 0.0 and info["start_s"] > 0.0 and info["rss_bytes"] > 0


def test_the_film_table_comes_back_with_the_table(tf, helper):
    desc = tf.planner.table_material(tf.Material.from_dict(soap_dict(tf)))
    table, film_table = helper.bake(desc, True)
    here = tf.real_bake(desc)
    expected = tf.film_colour.film_table(here)  # from the bake's reflectance at its nodes
    same_bake(table.data, here.data, "the table baked by the helper process")
    same_bake(film_table.reflectance, expected.reflectance, "the helper's film table (reflectance)")
    same_bake(film_table.multiscatter, expected.multiscatter, "the helper's film table (multiscatter)")
    same_bake(film_table.thicknesses_nm, expected.thicknesses_nm, "the helper's film table (thicknesses)")
    assert helper.bake(desc, False)[1] is None


def soap_dict(ns, thickness: float = 500.0) -> dict:
    data = ns.Material.from_dict(
        {"layers": [{"index": 1.33, "thickness_nm": thickness}], "roughness": 0.05}
    ).to_dict()
    data["quality"] = {"sh_order": 0, "view_samples": 8, "thickness_samples": 4, "wavelength_count": 16}
    return data


class Broken:
    """A description the helper cannot read back (its own error, not the helper's)."""

    def to_dict(self):
        return {"layers": [], "no_such_parameter": 1}


def test_a_bakes_own_error_comes_back_as_its_exception(tf, helper):
    with pytest.raises(ValueError, match="unknown material parameters: \\['no_such_parameter'\\]"):
        helper.bake(Broken(), False)
    assert helper.enabled() and helper.process_id() is not None  # the helper stays
    assert helper._failure("KeyError", "x").__class__ is KeyError
    assert isinstance(helper._failure("TableWriteError", "disk full"), RuntimeError)


def test_a_superseded_bake_is_cancelled_in_the_helper_which_goes_on(tf, helper):
    material = tf.Material
    helper.warm()
    slow = material.from_dict(soap_dict(tf))
    slow = slow.with_(quality=slow.quality.__class__(sh_order=8, view_samples=24))  # ≈ 1 s cold
    calls = []

    class Superseded(Exception):
        pass

    def progress(fraction, text):
        calls.append(fraction)
        if len(calls) >= 3:
            raise Superseded

    cancelled = helper.STATS["cancelled"]
    pid = helper.process_id()
    with pytest.raises(Superseded):
        helper.bake(slow, False, progress)
    assert helper.STATS["cancelled"] == cancelled + 1
    quick = material.from_dict(soap_dict(tf, 640.0))
    table, _ = helper.bake(quick, False)  # the next answer is this bake's, not the cancelled one's
    same_bake(table.data, tf.real_bake(quick).data, "the answer after a cancel (must be this bake's)")
    assert helper.process_id() == pid and helper.enabled()


def test_frames_round_trip_and_a_broken_frame_is_an_error(tf):
    frames = importlib.import_module(f"{tf.package.__name__}.addon.bakes.bake_process")
    stream = io.BytesIO()
    big = np.arange(300_000, dtype=np.float32).reshape(1000, 300)  # sent out of band
    message = ("done", 7, {"data": np.arange(6.0).reshape(2, 3), "big": big}, None, 1.5)
    frames.send(stream, message)
    stream.seek(0)
    got = frames.receive(stream)
    assert got[:2] == ("done", 7) and got[3:] == (None, 1.5)
    np.testing.assert_array_equal(got[2]["data"], message[2]["data"])
    np.testing.assert_array_equal(got[2]["big"], big)
    assert got[2]["big"].dtype == np.float32 and got[2]["big"].flags.writeable
    assert frames.receive(stream) is None  # the end
    whole = stream.getvalue()
    with pytest.raises(frames.FrameError, match="closed"):
        frames.receive(io.BytesIO(whole[:-3]))
    with pytest.raises(frames.FrameError, match="not one of ours"):
        frames.receive(io.BytesIO(frames.HEADER.pack(frames.MAX_FRAME + 1, 0)))


def silent_command(tf):
    """A helper that says it is ready, then never answers (reads until its stdin closes)."""
    addon = os.path.dirname(
        importlib.import_module(f"{tf.package.__name__}.addon.bakes.bake_process").__file__
    )
    code = (
        f"import sys; sys.path.insert(0, {addon!r}); import bake_process as b; "
        "b.send(sys.stdout.buffer, ('ready', 0)); sys.stdin.buffer.read()"
    )
    return lambda: [sys.executable, "-c", code]


@pytest.mark.parametrize("how", ["unstartable", "exits", "dies as sent", "killed", "silent"])
def test_a_failing_helper_falls_back_to_an_in_process_bake(bpy, tf, scene, helper, monkeypatch, caplog, how):
    given_up = helper.STATS["given_up"]
    real_send = helper._Process.send
    if how == "unstartable":
        monkeypatch.setattr(helper, "command", lambda: [os.path.join(os.sep, "nonexistent", "python")])
    elif how == "exits":
        monkeypatch.setattr(helper, "command", lambda: [sys.executable, "-c", "import sys; sys.exit(3)"])
    elif how == "silent":
        monkeypatch.setattr(helper, "command", silent_command(tf))
        monkeypatch.setattr(helper, "SILENCE_S", 1.0)
    elif how == "dies as sent":  # its pipe breaks under the bake (CI: an exiting helper)

        def die_then_send(self, message):
            if message[0] == "bake":
                self.proc.kill()
                self.proc.wait()
            real_send(self, message)

        monkeypatch.setattr(helper._Process, "send", die_then_send)
    else:  # killed as soon as the bake is handed over

        def send_then_kill(self, message):
            real_send(self, message)
            if message[0] == "bake":
                os.kill(self.proc.pid, signal.SIGKILL)

        monkeypatch.setattr(helper._Process, "send", send_then_kill)
    mat = soap(bpy, tf)
    with caplog.at_level(logging.ERROR, logger=helper.__name__):
        items = drawn(bpy, tf, scene, mat)
    assert len(items) == 1  # still drawn: baked here
    assert len(tf.in_process) == 1
    assert helper.STATS["given_up"] == given_up + 1 and not helper.enabled()
    assert helper.process_id() is None
    logged = [r for r in caplog.records if "bake helper process" in r.getMessage()]
    assert len(logged) == 1 and "baked in Blender itself" in logged[0].getMessage()


@pytest.mark.parametrize("switch", ["preference", "environment"])
def test_the_helper_can_be_turned_off(bpy, tf, scene, helper, monkeypatch, switch):
    if switch == "preference":
        tf.prefs.preferences().use_bake_helper = False
    else:
        monkeypatch.setenv("THINFILM_SH_BAKE_HELPER", "0")
    try:
        mat = soap(bpy, tf)
        tf.viewport._drawn.set()
        assert len(drawn(bpy, tf, scene, mat)) == 1
    finally:
        tf.prefs.preferences().use_bake_helper = True
    assert len(tf.in_process) == 1 and helper.process_id() is None


def test_the_helper_ends_with_its_stdin_and_with_unregister(tf, helper):
    assert_helper_ends_with_stdin_and_unregister(tf.package, helper, EVENT_TIMEOUT_S)


def test_a_helper_that_exited_while_idle_is_started_again(tf, helper, caplog):
    helper.warm()
    first = helper.process_id()
    assert helper.SLOT.process.ready.wait(EVENT_TIMEOUT_S)
    os.kill(first, signal.SIGKILL)
    helper.SLOT.process.proc.wait()
    wait_for(lambda: helper.SLOT.process.ended, "the helper's reader to see the end of its pipe")
    desc = tf.Material.from_dict(soap_dict(tf))
    with caplog.at_level(logging.WARNING, logger=helper.__name__):
        table, _ = helper.bake(desc, False)
    assert helper.process_id() not in (None, first) and table.data.shape[0] == 1
    assert any("had exited" in r.getMessage() for r in caplog.records)


def test_two_workers_get_their_own_answers(tf, helper):
    material = tf.Material
    descs = [material.from_dict(soap_dict(tf, t)) for t in (300.0, 700.0)]
    results: dict = {}

    def run(i):
        results[i] = helper.bake(descs[i], True)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(EVENT_TIMEOUT_S)
        assert not t.is_alive(), f"a bake through the helper did not return in {EVENT_TIMEOUT_S:.0f} s"
    for i, desc in enumerate(descs):
        same_bake(results[i][0].data, tf.real_bake(desc).data, f"worker {i}'s answer (must be its own bake)")


def test_a_grid_films_grid_is_built_by_the_helper_with_its_table(bpy, tf, scene, helper, monkeypatch):
    """A rough constant film read through its radiance grid: the edit's bake brings the grid's
    texels from the helper, equal to the grid built here, and no grid is built in this process."""
    from test_live_ahead import drawn_once
    from test_radiance_grid_viewport import record_builds

    bj = tf.bake_jobs
    rg = importlib.import_module(f"{tf.package.__name__}.addon.bakes.radiance_grids")
    mat = film(bpy, tf, "Rough", roughness=0.6)
    mat.thinfilm_sh.sh_order = "3"  # l ≥ policy.GRID_MIN_L: the SH half is read from a grid
    item = drawn_once(bpy, tf, scene, mat)  # the headless path: baked here
    assert item.grid is not None
    tf.in_process.clear()
    built_on = record_builds(rg, monkeypatch)
    baked = helper.STATS["baked"]
    mat.thinfilm_sh.layers[0].thickness_nm = 610.0
    bpy.context.view_layer.update()  # handed to the helper with the grid's spec
    wait_for(lambda: not bj.BAKES.running, "the bake and its grid")
    assert helper.STATS["baked"] == baked + 1 and tf.in_process == []
    assert built_on == []  # the grid came with the table
    (item,), _ = collect(bpy, tf, allow_bake=False, allow_world=False, bake_later=True)
    assert item.grid is not None and not item.grid_pending and not rg.busy() and built_on == []

    # the same grid under a World with something in it (this scene has none): equal to here's
    desc = tf.scene_draw.description.description(mat)
    result = tf.real_bake(desc)
    coeffs = np.random.default_rng(7).normal(size=(25, 3))
    policy = importlib.import_module(f"{tf.package.__name__}.precompute.shading.policy")
    chain = rg.Chain("a World", coeffs, False)
    ticket = helper.submit(desc, False, chain.helper_spec())
    ticket.wait()
    windowed = policy.windowed_lighting(coeffs, result.sh_order, desc.roughness)
    here, shape = rg.radiance_grid.texels(rg.radiance_grid.build(result, windowed))
    assert ticket.grid.shape == shape and ticket.grid.rgba.dtype == np.float32
    assert np.abs(here).max() > 0.0
    # float32 sums in another order (the helper's BLAS is single-threaded): ~1e-7 of the peak,
    # far below the RGBA16F texture's own rounding (5e-4)
    np.testing.assert_allclose(ticket.grid.rgba, here, rtol=1e-5, atol=1e-6 * float(np.abs(here).max()))


def test_no_grid_comes_back_for_a_film_that_reads_none(tf, helper):
    desc = tf.Material.from_dict(soap_dict(tf))  # glossy, order 0: split sum only
    ticket = helper.submit(desc, False, {"coeffs": np.ones((9, 3)), "prefiltered": True})
    table, _ = ticket.wait()
    assert ticket.grid is None and table.sh_order == 0


def test_the_helper_warms_the_kernels_of_the_neighbouring_rungs(tf):
    """Between requests the helper computes the kernels an edit that needs one more (or one
    fewer) node per interval would wait for; a request that arrives stops it."""
    frames = importlib.import_module(f"{tf.package.__name__}.addon.bakes.bake_process")
    progress = importlib.import_module(f"{tf.package.__name__}.precompute.bakes.progress")
    modules = types.SimpleNamespace(planner=tf.planner, kernel=tf.kernel, progress=progress)
    desc = tf.Material.from_dict(soap_dict(tf))
    result = tf.real_bake(desc)
    read, write = os.pipe()
    try:
        with os.fdopen(read, "rb") as stream:
            requests = frames._Requests(stream)
            tf.kernel.microfacet_kernel.cache_clear()
            ladder = list(tf.planner.U_DEGREE_LADDER)
            i = ladder.index(result.u_nodes)
            assert frames.warm_neighbours(modules, result, requests) == [ladder[i + 1], ladder[i - 1]]
            info = tf.kernel.microfacet_kernel.cache_info()
            tf.kernel.microfacet_kernel(
                float(result.material.roughness), 0, result.view_angles_rad.size, ladder[i + 1]
            )
            assert tf.kernel.microfacet_kernel.cache_info().hits == info.hits + 1  # warm
            requests.queue.put(("bake", 1, {}, False, None))  # a request waits: nothing is warmed
            tf.kernel.microfacet_kernel.cache_clear()
            assert frames.warm_neighbours(modules, result, requests) == []
            assert tf.kernel.microfacet_kernel.cache_info().currsize == 0
            os.close(write)
            write = None
    finally:
        if write is not None:
            os.close(write)


def test_a_bake_superseded_in_the_helper_does_not_hold_the_next_one_back(tf):
    """In process, no bake starts while a superseded one stops (tests/viewport/test_live_ahead.py); one
    handed to the helper was cancelled there at once, so the newest value starts now."""
    bj = tf.bake_jobs
    desc = tf.Material.from_dict(soap_dict(tf))
    handed_over = types.SimpleNamespace(cancel=lambda: None)  # its cancel went to the helper
    stopping = bj.BakeJob(desc, key="an older value", viewport=True)
    stopping.ticket = handed_over
    stopping.cancel()
    saved = (dict(bj.BAKES.running), dict(bj._pending), dict(bj._wanted))
    try:
        bj.BAKES.running.clear()
        bj._pending.clear()
        bj._wanted.clear()
        bj.BAKES.running[stopping.key] = stopping
        bj.want(desc, owner="material")
        (started,) = bj.start_ready()
        assert started.desc is desc and not bj._pending
    finally:
        for live, old in zip((bj.BAKES.running, bj._pending, bj._wanted), saved, strict=True):
            live.clear()
            live.update(old)


def test_a_table_on_disk_is_read_not_handed_to_the_helper(bpy, tf, scene, helper):
    """A reopened file's tables are in the disk cache: the worker reads them; the helper gets no
    request to bake them."""
    mat = soap(bpy, tf)
    desc = tf.scene_draw.description.description(mat)
    tf.tables.get_table(desc)  # baked here and stored on disk, as in an earlier session
    tf.tables.clear_memory_cache()
    tf.in_process.clear()
    submitted, baked = helper.STATS["submitted"], helper.STATS["baked"]
    assert len(drawn(bpy, tf, scene, mat)) == 1
    assert helper.STATS["submitted"] == submitted and helper.STATS["baked"] == baked
    assert tf.in_process == []  # read from the disk cache
    key = tf.scene_draw.description.description_key(desc)
    assert tf.tables.MEMORY.get(key) is not None
