"""Procedural Worlds in the viewport: their Cycles panorama rendered by the helper process (issue 16).

The viewport's World step (``world_job.service``, the timer) hands a procedural World to
:mod:`addon.world.panorama_helper`, whose process renders it with the add-on's own
``panorama.render_world_panorama``; a worker waits and analyses it. With the real bpy:

- no Cycles render runs in this process (counted), and the helper's panorama equals the one
  rendered here, bit for bit (same camera, samples and seed; Cycles on the CPU is deterministic);
- a helper that cannot start, exits, is killed mid-render or does not answer is given up once,
  logged, and the World is rendered here instead: the frame is still lit;
- closing the helper's stdin ends it (as its parent's death does), and ``unregister`` leaves no
  helper process.
"""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import sys

import numpy as np
import pytest
from _extension import assert_helper_ends_with_stdin_and_unregister, registered_extension

pytestmark = pytest.mark.blender

MODULES = (
    "addon.world.panorama",
    "addon.world.panorama_helper",
    "addon.world.panorama_process",
    "addon.ui.prefs",
    "addon.drawing.scene_draw",
    "addon.world.world",
    "addon.world.world_job",
    "addon.world.world_state",
    "addon.world.world_params",
)


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    root = tmp_path_factory.mktemp("extension")
    with registered_extension(bpy, root, MODULES, gpu=True) as ns:
        yield ns


@pytest.fixture
def sky(bpy, tf, monkeypatch):
    """An empty scene under a Sky Texture World, nothing analysed, no helper running; ``renders``
    counts the panoramas rendered in this process."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.panorama_helper.unregister()  # no helper, none given up
    tf.scene_draw.CACHES.clear()
    tf.world_job._render_here.clear()
    scene = bpy.context.scene
    world = bpy.data.worlds.new("Sky")
    tree = world.node_tree
    node = tree.nodes.new("ShaderNodeTexSky")
    node.sun_elevation = math.radians(30.0)
    tree.links.new(node.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    scene.world = world
    renders = []
    real = tf.panorama.render_world_panorama

    def counting(*args, **kwargs):
        renders.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(tf.panorama, "render_world_panorama", counting)
    monkeypatch.setattr(tf.world, "render_world_panorama", counting)
    yield scene, renders, real
    tf.panorama_helper.unregister()


def ask_and_settle(tf, scene, between=None):
    """The draw asks for the World, the timer reads it (``between`` runs right after that first
    timer step), workers analyse it; then the lighting the next draw gets."""
    assert tf.world_state.world_lighting(scene, allow_compute=False) is None  # nothing drawn yet
    assert tf.world_state.STATE.wanted
    tf.world_job.service(scene)
    if between is not None:
        between()
    for _ in range(10):
        tf.world_job.wait()
        tf.world_job.service(scene)
        if not tf.world_job.busy():
            break
    return tf.world_state.world_lighting(scene, allow_compute=False)


def assert_lit(tf, scene, lighting):
    """The frame is lit by the Sky Texture's panorama: a daylight sky, brighter above."""
    assert lighting is not None
    content_key, _ = tf.world_params.world_parts(scene)
    content = tf.world_state.STATE.contents[content_key].content
    assert content.read.source == "panorama render (Sky Texture)"
    assert content.read.rgb is not None and content.read.pending is None
    coeffs = content.coeffs
    assert np.all(np.isfinite(coeffs)) and np.all(coeffs[0] > 0.0) and np.all(coeffs[2] > 0.0)
    return content


def test_procedural_world_is_rendered_by_the_helper_as_in_process(tf, sky):
    scene, renders, real = sky
    rendered = tf.panorama_helper.STATS["rendered"]
    lighting = ask_and_settle(tf, scene)
    content = assert_lit(tf, scene, lighting)
    assert renders == []  # no Cycles render in this process
    assert (
        tf.panorama_helper.STATS["rendered"] == rendered + 1 and tf.panorama_helper.process_id() is not None
    )
    here = real(scene.world)  # the same function, the same samples and seed, in this process
    assert content.read.rgb.dtype == np.float32 and content.read.rgb.shape == here.shape
    # Cycles on the CPU in another process: per pixel the same samples and seed, so equal up to
    # float32 rounding of another thread count; a wrong image, orientation or scale is ≫ 1e-6.
    np.testing.assert_allclose(
        content.read.rgb,
        here,
        rtol=1e-6,
        atol=1e-6 * float(np.abs(here).max()),
        err_msg="the helper's panorama against the same render in this process",
    )
    figures = tf.panorama_helper.info()
    assert figures["write_ms"] > 0.0 and figures["start_s"] > 0.0 and figures["rss_bytes"] > 0
    assert os.listdir(tf.panorama_helper.SLOT.process.folder) == ["helper.log"]  # no .blend or .npy left


def crashing_command():
    return [sys.executable, "-c", "import sys; sys.exit(3)"]


def silent_command(mark: str):
    """A helper that says it is ready, then never answers (reads until its stdin closes)."""
    ready = mark + json.dumps({"ready": True, "working_space": "Linear Rec.709"})
    return lambda: [sys.executable, "-c", f"import sys; print({ready!r}, flush=True); sys.stdin.read()"]


@pytest.mark.parametrize("how", ["unstartable", "exits", "killed", "silent"])
def test_a_failing_helper_falls_back_to_an_in_process_render(tf, sky, monkeypatch, caplog, how):
    scene, renders, _real = sky
    helper = tf.panorama_helper
    given_up = helper.STATS["given_up"]
    between = None
    if how == "unstartable":
        monkeypatch.setattr(helper, "command", lambda: [os.path.join(os.sep, "nonexistent", "blender")])
    elif how == "exits":
        monkeypatch.setattr(helper, "command", crashing_command)
    elif how == "silent":
        monkeypatch.setattr(helper, "command", silent_command(tf.panorama_process.MARK))
        monkeypatch.setattr(helper, "RENDER_TIMEOUT_S", 1.0)
    else:  # killed while it renders

        def between():
            assert helper.SLOT.process.ready.wait(helper.START_TIMEOUT_S)
            os.kill(helper.process_id(), signal.SIGKILL)

    with caplog.at_level(logging.ERROR, logger=helper.__name__):
        lighting = ask_and_settle(tf, scene, between)
    assert_lit(tf, scene, lighting)  # the frame still gets lit
    assert renders == [1]  # once, in this process
    assert helper.STATS["given_up"] == given_up + 1 and not helper.enabled()
    assert helper.process_id() is None
    given_up = [r for r in caplog.records if "panorama helper process" in r.getMessage()]
    assert len(given_up) == 1 and "rendered in Blender itself" in given_up[0].getMessage()


def test_the_preference_turns_the_helper_off(tf, sky):
    scene, renders, _real = sky
    tf.prefs.preferences().use_render_helper = False
    try:
        assert_lit(tf, scene, ask_and_settle(tf, scene))
    finally:
        tf.prefs.preferences().use_render_helper = True
    assert renders == [1] and tf.panorama_helper.process_id() is None


def test_the_helper_ends_with_its_stdin_and_with_unregister(tf, sky):
    helper = tf.panorama_helper
    assert_helper_ends_with_stdin_and_unregister(tf.package, helper, helper.START_TIMEOUT_S)


def test_unregister_during_a_render_does_not_give_the_helper_up(tf, sky, caplog):
    scene, _renders, _real = sky
    helper = tf.panorama_helper
    given_up = helper.STATS["given_up"]
    tf.world_state.world_lighting(scene, allow_compute=False)
    with caplog.at_level(logging.ERROR, logger=helper.__name__):
        tf.world_job.service(scene)  # handed over: a worker waits for the helper
        pid = helper.process_id()
        tf.package.unregister()
        tf.world_job.wait()
        tf.package.register()
    assert pid is not None and not os.path.exists(f"/proc/{pid}")
    assert helper.STATS["given_up"] == given_up and helper.enabled()
    assert not [r for r in caplog.records if "panorama helper process" in r.getMessage()]


def test_a_helper_that_exited_while_idle_is_started_again(tf, sky, caplog):
    scene, renders, _real = sky
    helper = tf.panorama_helper
    helper.warm()
    first = helper.process_id()
    assert helper.SLOT.process.ready.wait(helper.START_TIMEOUT_S)
    os.kill(first, signal.SIGKILL)
    helper.SLOT.process.proc.wait()
    with caplog.at_level(logging.WARNING, logger=helper.__name__):
        assert_lit(tf, scene, ask_and_settle(tf, scene))
    assert renders == [] and helper.process_id() not in (None, first)
    assert any("had exited" in r.getMessage() for r in caplog.records)


def test_blenders_command_line_reaches_the_script(tf, sky, monkeypatch, tmp_path):
    """Blender's binary gets ``--background --factory-startup --python SCRIPT -- ROOT``; a stand-in
    binary runs the script with Blender's arguments in front, as Blender leaves them in sys.argv."""
    scene, renders, _real = sky
    helper = tf.panorama_helper
    blender = tmp_path / "blender"
    blender.write_text(f'#!/bin/sh\nexec {sys.executable} "$4" "$@"\n')
    blender.chmod(0o755)
    argv = helper.command_for(str(blender), sys.executable)
    assert argv == [
        str(blender),
        "--background",
        "--factory-startup",
        "--python",
        helper.SCRIPT,
        "--",
        helper.helper_process.PACKAGE_ROOT,
    ]
    assert helper.command_for("", sys.executable) == [
        sys.executable,
        helper.SCRIPT,
        helper.helper_process.PACKAGE_ROOT,
    ]
    monkeypatch.setattr(helper, "command", lambda: argv)
    assert_lit(tf, scene, ask_and_settle(tf, scene))
    assert renders == [] and helper.process_id() is not None


@pytest.mark.parametrize("stored", ["relative", "packed"])
def test_images_relative_to_the_file_or_packed_reach_the_helper(bpy, tf, sky, tmp_path, stored):
    """An image behind a node the panorama route renders (Environment Texture → Gamma), saved
    beside the .blend with a ``//`` path or packed into it: the helper renders what this process
    renders, not the fallback colour."""
    scene, renders, real = sky
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    img = bpy.data.images.new("studio", 64, 32, float_buffer=True, alpha=False)
    ramp = np.linspace(0.1, 2.0, 64 * 32 * 4, dtype=np.float32)
    img.pixels.foreach_set(ramp)
    img.filepath_raw = str(tmp_path / "studio.exr")
    img.file_format = "OPEN_EXR"
    img.save()
    img.filepath = "//studio.exr"
    img.reload()
    if stored == "packed":
        img.pack()
        os.remove(tmp_path / "studio.exr")
    tree = scene.world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    gamma = tree.nodes.new("ShaderNodeGamma")
    tree.links.new(env.outputs["Color"], gamma.inputs["Color"])
    tree.links.new(gamma.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    lighting = ask_and_settle(tf, scene)
    assert lighting is not None and renders == []
    content_key, _ = tf.world_params.world_parts(scene)
    read = tf.world_state.STATE.contents[content_key].content.read
    assert read.source == "panorama render (Gamma)"
    here = real(scene.world)
    np.testing.assert_allclose(  # another process: float32 rounding only (see above)
        read.rgb,
        here,
        rtol=1e-6,
        atol=1e-6 * float(np.abs(here).max()),
        err_msg="the helper's Gamma-corrected panorama against the same render in this process",
    )
    assert read.rgb.max() > 1.0  # the image's ramp, not a fallback colour
