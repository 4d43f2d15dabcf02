"""Outgoing-radiance grids of constant-thickness films: built on a worker, uploaded when ready.

A film whose SH half policy.uses_grid reads from a grid (precompute.shading.radiance_grid)
gets one per (description key, World content key, roughness): the table and the windowed SH of
the World's *content* it is built from (:meth:`.world_analysis.WorldLighting.grid_source`), or,
in the split-sum/SH hand-over (policy.uses_lobe_grid), the exact lobe integrated against the
content's panorama (precompute.shading.lobe_grid). The World's Strength and Mapping rotation
are applied at the lookup (the lighting buffer's ``world`` block), so editing them rebuilds no
grid. :func:`grid_for` returns the uploaded grid, or None while it is being built, and the draw
then reads the per-pixel SH as before (the same picture to mean ΔE2000 < 0.6). Building takes
0.3–0.8 s of numpy at l = 12 (an integrated grid, :func:`lobe_build`, 15–100 s) on a worker
thread (never the main thread or the draw callback); the newest request is built first and at
most :data:`QUEUE_SIZE` wait, so a roughness drag builds the value it stops on, not every
step. When one finishes a timer asks the 3D viewports for a redraw. ``wait=True`` (headless
frames) builds it in the caller.

:data:`GRIDS` (registered in :mod:`.caches` as ``radiance_grids``, FILE scope) holds the
uploaded textures by key, an LRU of :data:`GRID_CACHE_SIZE` (4.5–9 MiB of GPU memory each).
"""

from __future__ import annotations

import dataclasses
import functools
import logging

import bpy
import numpy as np

from ...precompute.shading import lobe_grid, policy, radiance_grid
from ...precompute.world import lamps as lamp_extraction
from .. import caches, workers
from ..gpu import resources
from ..workers import tag_view3d as _tag_redraw

log = logging.getLogger(__name__)

#: Uploaded grids kept (4.5–9 MiB each on the GPU).
GRID_CACHE_SIZE = 8
#: Uploaded basis grids kept (varying films, one per World content and roughness: 80 MiB each).
BASIS_CACHE_SIZE = 2
#: Requests waiting for the worker; older ones are dropped (the newest is built first).
QUEUE_SIZE = 4
#: The end of an integrated grid's key (:func:`lobe_build`): 15–100 s, so built after SH grids.
LOBE_SUFFIX = "|lobe"
#: The end of a varying film's basis grid's key (:func:`basis_build`): integrated as well.
BASIS_SUFFIX = "|basis" + LOBE_SUFFIX
#: Seconds between the timer's looks while grids are built: a grid takes 0.05–0.3 s, so a
#: 0.1 s poll added up to a third to the edit's wait; a look that finds nothing costs µs.
POLL_S = 0.01


class _Grids:
    """The uploaded grids (an LRU) and the worker's queue and results: the worker is the one job
    of its lane (:attr:`work`, :mod:`..workers`), whose lock guards the queue too."""

    def __init__(self):
        self.textures = caches.LRU(GRID_CACHE_SIZE)
        self.bases = caches.LRU(BASIS_CACHE_SIZE)  # varying films' basis grids: 80 MiB each
        self.work = workers.Lane("radiance grid")
        self.lock = self.work.lock
        self.queue: dict = {}  # key → a call that builds the grid, oldest first
        self.built: dict = {}  # key → grid array, waiting for its upload
        self.running: str | None = None
        self.inline: set = set()  # keys a bake's worker is building (:func:`prebuild`)

    def clear(self) -> None:
        """Forget the uploaded grids, the queue and the built-but-not-uploaded ones."""
        with self.lock:
            self.textures.clear()
            self.bases.clear()
            self.queue.clear()
            self.built.clear()


GRIDS = caches.register("radiance_grids", _Grids(), scope=caches.FILE)


def busy() -> bool:
    """Whether grids are being built or wait for the worker."""
    with GRIDS.lock:
        return bool(GRIDS.queue) or GRIDS.running is not None or bool(GRIDS.inline)


def activity() -> str:
    """A few words for the viewport header while grids are built, else ""."""
    with GRIDS.lock:
        count = len(GRIDS.queue) + (GRIDS.running is not None)
    return f"tabulating {count} rough film{'s' if count > 1 else ''}" if count else ""


class _Worker(workers.Job):
    """The worker: builds the queued grids one after the other until none is left. Each grid
    asks for a redraw as it is built; the worker's own end shows nothing new."""

    def __init__(self):
        super().__init__(_WORKER)

    def run(self) -> None:
        """Build the queued grids."""
        _work(self)

    def shows_something(self) -> bool:
        """Nothing: every grid asked for its redraw when it was built."""
        return False


_WORKER = "worker"


def _work(job: _Worker) -> None:
    while True:
        with GRIDS.lock:
            if not GRIDS.queue:  # off the running jobs now, in the step that finds the queue empty
                if GRIDS.work.running.get(_WORKER) is job:
                    del GRIDS.work.running[_WORKER]
                return
            keys = list(GRIDS.queue)  # the newest request first; SH grids before integrated ones
            key = ([k for k in keys if not k.endswith(LOBE_SUFFIX)] or keys)[-1]
            build = GRIDS.queue.pop(key)
            GRIDS.running = key
        try:
            grid = resources.grid_texels(build())  # padded here: the main thread only uploads
        except Exception as exc:  # the per-pixel SH keeps drawing the film
            log.error("Thin Film SH: radiance grid failed: %s", exc)
            grid = None
        with GRIDS.lock:
            GRIDS.work.mark_finished()  # the cue before it stops looking busy: _poll never sees neither
            GRIDS.running = None
            if grid is not None:
                _keep_built(key, grid)


def _poll() -> float | None:
    """Timer: ask for a redraw when a grid is built; stops when nothing is left to build."""
    if GRIDS.work.take_finished():
        _tag_redraw()
    return POLL_S if busy() or GRIDS.work.finished() else None


def _request(key: str, build) -> None:
    with GRIDS.lock:
        if _known(key):
            return
        GRIDS.queue[key] = build
        while len(GRIDS.queue) > QUEUE_SIZE:
            GRIDS.queue.pop(next(iter(GRIDS.queue)))
        if _WORKER not in GRIDS.work.running:
            GRIDS.work.start(_Worker())
    if not bpy.app.timers.is_registered(_poll):
        bpy.app.timers.register(_poll, first_interval=POLL_S)


def prebuild(key: str, build) -> bool:
    """Build the grid of ``key`` here, on the calling worker thread (a bake's, :func:`chain`),
    and leave it for the next draw's upload, unless it is uploaded, built, queued or being built
    already. True when it was built here."""
    with GRIDS.lock:
        if _known(key) or key in GRIDS.textures:
            return False
        GRIDS.inline.add(key)
    grid = None
    try:
        grid = resources.grid_texels(build())
    finally:
        with GRIDS.lock:  # one step: never neither building nor built
            GRIDS.inline.discard(key)
            if grid is not None:
                _keep_built(key, grid)
    return True


def _known(key: str) -> bool:
    """Whether the grid of ``key`` is queued, being built or built (call with the lock held)."""
    return key in GRIDS.queue or key == GRIDS.running or key in GRIDS.built or key in GRIDS.inline


def _keep_built(key: str, grid) -> None:
    """Leave a built grid for the next draw's upload (call with the lock held); the oldest beyond
    QUEUE_SIZE is dropped (never fetched: a drag's intermediate value)."""
    GRIDS.built[key] = grid
    while len(GRIDS.built) > QUEUE_SIZE:
        GRIDS.built.pop(next(iter(GRIDS.built)))


@dataclasses.dataclass(frozen=True, eq=False)
class Chain:
    """A bake's follow-up (:func:`chain`): ``chain(desc_key, desc, result, built=None)`` builds
    the new table's SH grid (:func:`prebuild`) when the film still reads one, or keeps ``built``,
    the grid the bake helper built right after the table (:meth:`helper_spec` is what it needs:
    the World's content SH, unwindowed, and whether the World is prefiltered)."""

    source: str
    coeffs: np.ndarray
    prefiltered: bool

    def helper_spec(self) -> dict:
        """What the bake helper needs to build the grid (:mod:`.bake_process`)."""
        return {"coeffs": self.coeffs, "prefiltered": self.prefiltered}

    def __call__(self, desc_key: str, desc, result, built=None) -> None:
        """Build (or keep ``built``) the SH grid of ``desc``'s new table ``result``."""
        if not policy.table_uses_grid(desc, result, self.prefiltered):
            return
        l_max, roughness = int(result.sh_order), float(desc.roughness)
        if built is None:
            build = sh_build(result, policy.windowed_lighting(self.coeffs, l_max, roughness))
        else:

            def build():
                return built

        prebuild(sh_key(desc_key, self.source, l_max, roughness), build)


def chain(previous, lighting) -> Chain | None:
    """The call a bake's worker makes after the table of a material that was last drawn as
    ``previous`` (a ``scene_draw`` entry, or None) under ``lighting`` (a ``WorldLighting``):
    a :class:`Chain` that builds the new table's SH grid (:func:`prebuild`) when the material
    read a grid and its new table still does; None when it read none. The SH grid is also the
    stand-in an integrated grid is drawn with while it builds."""
    if previous is None or not previous.grid_wanted or lighting is None:
        return None
    source, coeffs = lighting.grid_source(previous.lamps)
    return Chain(source, np.array(coeffs, dtype=np.float64), lighting.textures is not None)


def sh_key(desc_key: str, source: str, l_max: int, roughness: float) -> str:
    """The key of a film's SH grid: its description, the World content it is built from, its
    order and roughness (the window)."""
    return f"{desc_key}|{source}|{l_max}|{round(roughness, 6)}"


def sh_build(result, coeffs):
    """The call that builds an SH grid: ``result`` (a constant-thickness table) under ``coeffs``
    (the lighting buffer's windowed SH, copied now)."""
    coeffs = np.array(coeffs, dtype=np.float64)
    return functools.partial(radiance_grid.build, result, coeffs)


def lobe_build(film, roughness: float, panorama, view_count: int, lamp_mask=None):
    """The call that builds an integrated grid (precompute.shading.lobe_grid): ``film`` (its
    FilmTable) under the content's ``panorama`` in its frame and strength (the lighting buffer's
    ``world`` block turns and scales the lookup), ``view_count`` view angles. ``lamp_mask``: the
    lamp pixels to lift out (shaded per direction), removed by the call, on the worker: a
    float64 copy of the panorama that a frame which finds the grid built never makes."""
    shape = policy.grid_shape(view_count)

    def build():
        image = panorama if lamp_mask is None else lamp_extraction.remove(np.asarray(panorama), lamp_mask)
        return lobe_grid.build(film, float(roughness), image, shape)

    return build


def basis_build(roughness: float, panorama, view_count: int, lamp_mask=None):
    """The call that builds a varying film's film-free basis grid
    (precompute.shading.lobe_grid.build_basis), as :func:`lobe_build` builds a film's grid."""
    shape = (*policy.GRID_BASIS_MIRROR, int(view_count), policy.GRID_AZIMUTHS)

    def build():
        image = panorama if lamp_mask is None else lamp_extraction.remove(np.asarray(panorama), lamp_mask)
        return lobe_grid.build_basis(float(roughness), image, shape)

    return build


def grid_for(key: str, build, *, wait: bool = False) -> resources.RadianceGridTexture | None:
    """The uploaded grid of ``key`` (description and lighting keys), built by ``build()``
    (:func:`sh_build`, :func:`lobe_build`), or None while the worker builds it (``wait``: build it
    here).

    Only the upload runs on the calling thread (4.5–9 MiB; a basis grid's 80 MiB took 117 ms on
    llvmpipe, once per World content and roughness); a failed build leaves the film on the
    per-pixel SH.
    """
    cache = GRIDS.bases if key.endswith(BASIS_SUFFIX) else GRIDS.textures
    found = cache.get(key)
    if found is not None:
        return found
    with GRIDS.lock:
        grid = GRIDS.built.pop(key, None)
    if grid is None and wait:
        grid = build()
    if grid is None:
        _request(key, build)
        return None
    found = resources.RadianceGridTexture.from_grid(grid)
    cache[key] = found
    return found


def film_grid(desc_key: str, desc, result, lighting, lamps: bool, film=None, *, wait: bool):
    """(grid, integrated) of a film: its grid where policy.uses_grid reads one (a constant
    thickness, an SH half at l_max ≥ GRID_MIN_L), else None; None too while the worker builds it
    (:func:`grid_for`; ``wait``: built here, for headless frames).

    ``lighting``: the scene's ``WorldLighting``; ``lamps``: the film is shaded with the World's
    lamps (its grid then holds the content without them). ``film``: the film table in memory,
    given where policy.uses_lobe_grid says so: the grid then integrates the exact lobe against
    the content's panorama (``integrated`` True; the SH grid is drawn while it is built), else
    it holds the SH sum. Both are built in the
    content's frame and strength: the lighting buffer's ``world`` block turns and scales the
    lookup.
    """
    if policy.table_uses_basis_grid(desc, result, lighting.textures is not None):
        return _basis_grid(desc, lighting, lamps, film, wait=wait)
    if not applies(desc, result, lighting):
        return None, False
    source, coeffs = lighting.grid_source(lamps)
    l_max, roughness = int(result.sh_order), float(desc.roughness)
    env = lighting.environment
    key = sh_key(desc_key, source, l_max, roughness)
    if film is not None and env is not None:
        mask = env.lamp_mask if lamps and env.lamps is not None else None
        build = lobe_build(film, roughness, env.panorama, policy.LOBE_GRID_VIEWS, mask)
        lobe_key = f"{desc_key}|{source}|{round(roughness, 6)}{LOBE_SUFFIX}"
        if wait or _ready(lobe_key):
            return grid_for(lobe_key, build, wait=wait), True
        # it takes 15–100 s: meanwhile the SH grid (under a second, asked for first, and the
        # worker builds SH grids first) stands in, better than the per-pixel variant's stand-in
        stand_in = _sh_grid(key, result, coeffs, roughness, wait=False)
        _request(lobe_key, build)
        return stand_in, False
    return _sh_grid(key, result, coeffs, roughness, wait=wait), False


def _basis_grid(desc, lighting, lamps: bool, film, *, wait: bool):
    """(grid, integrated) of a varying film in the hand-over: the film-free basis grid of its
    roughness under the World's content (without the lamps where they are shaded per direction),
    shared by every varying film of that roughness; (None, False) where the film is not drawn
    from the exact lobe (``film`` None: a diffuse base, a wall) or while the worker builds it
    (the per-pixel SH meanwhile)."""
    env = lighting.environment
    if film is None or env is None:
        return None, False
    source = lighting.grid_source(lamps)[0]
    roughness = float(desc.roughness)
    mask = env.lamp_mask if lamps and env.lamps is not None else None
    key = f"{source}|{round(roughness, 6)}{BASIS_SUFFIX}"
    build = basis_build(roughness, env.panorama, policy.GRID_BASIS_VIEWS, mask)
    if wait or _ready(key):
        found = grid_for(key, build, wait=wait)
        return found, found is not None
    _request(key, build)
    return None, False


def _sh_grid(key: str, result, coeffs, roughness: float, *, wait: bool):
    """:func:`grid_for` of a film's SH grid; its windowed lighting is made only when it is built."""
    found = GRIDS.textures.get(key)
    if found is not None:  # the frame's usual case: no windowing, no copy
        return found
    windowed = policy.windowed_lighting(coeffs, int(result.sh_order), roughness)
    return grid_for(key, sh_build(result, windowed), wait=wait)


def _ready(key: str) -> bool:
    """Whether the grid of ``key`` is uploaded or built (waiting for its upload)."""
    with GRIDS.lock:
        return key in GRIDS.textures or key in GRIDS.bases or key in GRIDS.built


def applies(desc, result, lighting, integrated: bool = False) -> bool:
    """Whether the film draws its SH half from a grid (policy.uses_grid): a constant thickness,
    an SH half at l_max ≥ GRID_MIN_L; a varying one in the hand-over where its film table is
    there to read the basis grid with (``integrated``: policy.uses_lobe_grid)."""
    prefiltered = lighting.textures is not None
    if integrated and policy.table_uses_basis_grid(desc, result, prefiltered):
        return True
    return policy.table_uses_grid(desc, result, prefiltered)
