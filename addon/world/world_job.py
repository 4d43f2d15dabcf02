"""The World's analysis as background work: the viewport's timer reads, a worker thread analyses.

The draw never analyses a World: when it meets a content that is not analysed
(:func:`.world_state.world_lighting` with ``allow_compute`` False) it sets
``world_state.STATE.wanted`` and keeps drawing the lighting it has; when a glossy film reads a
prefilter that is not computed it adds it to ``STATE.prefilters_wanted``
(:func:`.world_state.prefilter`) and draws that film from the SH meanwhile. :func:`service`,
called by the viewport's timer (``viewport._service``), then

1. reads the World with bpy on the main thread (:func:`.world.read_world`: an Environment
   Texture's pixels, ≈ 0.1–0.3 s for a 4k HDRI); a procedural World is only handed to the
   panorama helper process (:func:`.panorama_helper.submit`: a .blend of the World written,
   ≈ 1–2 ms), which renders its small Cycles panorama;
2. starts a worker thread that waits for the helper's panorama (:func:`.panorama_helper.resolve`)
   and analyses the World (:func:`.world_analysis.analyse_content`: the SH projection, the
   lamps, and the prefilters the last frames' glossy films read) and stores the result in
   ``STATE.contents``; a prefilter asked for later gets a worker of its own. When the helper
   fails the World is read again at the next step, its panorama rendered on the main thread as
   before (:mod:`.panorama_helper`: the helper is then given up, logged once);
3. reports when a worker finished, so the timer asks for a redraw: the next draw builds the new
   lighting from the analysed content (milliseconds) and uploads the prefilter textures.

The workers are jobs of one lane (:data:`WORK`, :mod:`..workers`). One content analysis runs at
a time; the newest World wins (a World edited while one is analysed is read when that one
ends). Strength and rotation edits never come here: they keep the content key
(:func:`.world_params.world_parts`).
"""

from __future__ import annotations

import collections
import logging
import threading

import numpy as np

from .. import workers
from . import panorama_helper, world, world_analysis, world_params
from .world_state import STATE

log = logging.getLogger(__name__)

__all__ = ["STATS", "WORK", "busy", "service", "wait"]

#: The World's workers: ("content", key) or ("prefilter", key, kind) → its job.
WORK = workers.Lane("World analysis")
_render_here = threading.Event()  # the helper failed: read the next World's panorama in process
#: How often each step ran (tests and benchmarks count them): "read", "analyse", "prefilter".
STATS: collections.Counter = collections.Counter()


def busy() -> bool:
    """Whether World work is running or asked for (for the viewport's header and timer)."""
    return WORK.busy() or STATE.wanted or bool(STATE.prefilters_wanted)


def _start(label: tuple, target, *args) -> None:
    WORK.start(workers.Job(label, target, *args))


def _rendered(read):
    """``read`` with the helper's panorama, or None when the helper failed (the World is then
    read again on the main thread: the timer's next step)."""
    try:
        return panorama_helper.resolve(read)
    except (panorama_helper.HelperError, panorama_helper.RenderFailed) as exc:
        log.warning("Thin Film SH: the World's panorama is rendered in Blender instead: %s", exc)
        _render_here.set()
        STATE.wanted = True
        return None


def _analyse(content_key: str, read, fallback, kinds, generation: int) -> None:
    read = _rendered(read)
    if read is None:
        return
    STATS["analyse"] += 1
    try:
        found = world_analysis.analyse_content(content_key, read, fallback, kinds)
    except Exception as exc:  # kept as the fallback colour, so the timer does not retry it forever
        log.error("Thin Film SH: World analysis failed: %s", exc)
        coeffs = world.constant_sh(0, fallback)
        why = f"The World could not be analysed ({exc}): lit by its fallback colour"
        plain = world.WorldRead("fallback", coeffs=coeffs, warnings=(why,))
        found = world_analysis.Analysed(content_key, world.analyse_read(plain, 0), None)
    if STATE.generation == generation:  # not for a file loaded since
        STATE.contents[content_key] = found


def _prefilter(analysed, kind: str) -> None:
    STATS["prefilter"] += 1
    analysed.compute(kind)


def _start_content(scene) -> None:
    """Read the scene's World (main thread) and start its analysis on a worker, unless it is
    analysed already or another analysis runs (it is then read when that one ends)."""
    with WORK.lock:
        if any(label[0] == "content" for label in WORK.running):
            return
    STATE.wanted = False
    panorama_helper.warm()  # at the first World read: warm by the first procedural World
    content_key, params = world_params.world_parts(scene)
    if content_key in STATE.contents:
        WORK.mark_finished()  # analysed meanwhile: the next draw shows it
        return
    STATS["read"] += 1
    render = None if _render_here.is_set() else panorama_helper.submit
    _render_here.clear()
    read = world.read_world(scene, params=params, render=render)  # bpy: pixels, or a Cycles panorama
    fallback = np.asarray(world.fallback_colour(scene.world)[0], dtype=np.float64)
    kinds = tuple(sorted(STATE.prefilters_used))  # what the glossy films read so far
    _start(("content", content_key), _analyse, content_key, read, fallback, kinds, STATE.generation)


def _start_prefilters() -> None:
    for content_key, asked in list(STATE.prefilters_wanted):
        analysed = STATE.contents.get(content_key)
        if analysed is None:  # a World no longer analysed: its lighting is not drawn any more
            STATE.prefilters_wanted.discard((content_key, asked))
            continue
        kind = analysed.kind(asked)
        label = ("prefilter", content_key, kind)
        with WORK.lock:
            if label in WORK.running:
                continue
        STATE.prefilters_wanted.discard((content_key, asked))
        if kind in analysed.arrays:
            WORK.mark_finished()
            continue
        _start(label, _prefilter, analysed, kind)


def service(scene) -> bool:
    """The viewport timer's World step (main thread); True when a worker finished since the last
    call (ask for a redraw: the next draw shows its result)."""
    if scene is not None and STATE.wanted:
        _start_content(scene)
    _start_prefilters()
    return WORK.take_finished()


def wait(timeout: float = 120.0) -> None:
    """Wait for the running World workers (tests, benchmarks, unregister)."""
    WORK.wait(timeout)
