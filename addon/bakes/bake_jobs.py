"""The one bake-job type, and the viewport's bake queue that owns the viewport's bakes.

:class:`BakeJob` bakes a description's table off the main thread (numpy releases the GIL while it
works), with its film table and its grid when asked. Two lanes run it (:mod:`..workers`):

- :data:`BUTTON`: the Bake button (``ui.ops.THINFILM_OT_bake``, modal: progress in the status
  bar, Esc cancels): a table from memory, disk or a bake, stored to the disk cache at once;
- :data:`BAKES`: the viewport's bakes, asked for by the draw and the depsgraph handler
  (:func:`want`, through :mod:`.bake_asks`) and started by the viewport's timer
  (:func:`start_queued`).

The viewport's queue holds one bake per material (:func:`.bake_asks.material_identity`), the
newest value winning: dragging a slider over ten values leaves one bake, and a running bake whose
description no material wants any more is cancelled at its next progress checkpoint (the job's
own cancel, not :func:`cancel_all`'s). Nothing new starts while a superseded in-process bake is
still stopping. A viewport bake runs in the bake helper process (:mod:`.bake_helper`) when it is
on, its thread waiting on the pipe; its film table (:func:`.tables.get_film`) and its grid
(``then``, :func:`.radiance_grids.chain`) are made on the same worker, so the bake's one redraw
shows them all. A bake that fails is remembered with its error by description key
(:func:`.tables.failure`) and not queued again until the description changes. When a bake ends
the lane's *finished* flag asks the viewport's timer for a redraw, and only after the frame that
shows it is the table's disk copy written (it only serves the next session).
"""

from __future__ import annotations

import logging

from ...precompute.bakes.progress import reporting
from .. import workers
from ..materials.description import description_key
from . import bake_helper, tables

log = logging.getLogger(__name__)

__all__ = [
    "BAKES",
    "BUTTON",
    "POLL_S",
    "STORE_WAIT_S",
    "BakeJob",
    "activity",
    "busy",
    "cancel_all",
    "pending",
    "start_queued",
    "start_ready",
    "want",
]

#: The Bake button's bakes.
BUTTON = workers.Lane("bake")
#: The viewport's bakes: running jobs by description key; :data:`_pending` and :data:`_wanted`
#: beside them, under the same lock.
BAKES = workers.Lane("viewport bake")
_pending: dict = {}  # material identity → the newest bake it wants (not started)
_wanted: dict = {}  # material identity → the description key it wants now
#: Seconds between the viewport timer's looks while bakes run: a warm bake takes 0.01–0.1 s, so
#: the 0.1 s poll it had added up to 0.1 s to an edit's wait (and 10 ms up to 10 ms); a look that
#: finds nothing costs µs.
POLL_S = 0.005
#: Longest a bake's worker waits for the frame that shows its table before writing the disk copy
#: (no viewport redraws, e.g. it is hidden): the copy only serves the next session.
STORE_WAIT_S = 1.0


class BakeJob(workers.Job):
    """One table bake: the description ``desc`` (its key is the job's), the disk ``cache`` (opened
    on the main thread: it reads the preferences), whether the film table is wanted too, and
    ``then``, run on the worker after the table: ``then(key, desc, result[, built])``, the
    material's grid (:func:`.radiance_grids.chain`), so the bake's one redraw shows both.

    ``viewport``: a viewport bake (:data:`BAKES`): the table's disk copy is written after the
    frame that shows it, its failure is remembered (:func:`.tables.record_failure`) and logged;
    else (the Bake button) the table is stored at once and the button reports the error.
    :attr:`ticket`: the bake handed to the helper process by the main thread when the job
    started (:func:`.bake_helper.submit`), or None. After it ends: :attr:`result` and
    :attr:`source` ("memory", "disk" or "bake"). ``key``: the job's key when it is not the
    description's (tests).
    """

    def __init__(self, desc, cache=None, *, film: bool = False, then=None, viewport: bool = False, key=None):
        super().__init__(description_key(desc) if key is None else key)
        self.desc, self.cache, self.film, self.then = desc, cache, film, then
        self.viewport = viewport
        self.text = "starting"  # the Bake button's status line until the first checkpoint
        self.ticket = None
        self.source = ""
        self.baked = None  # a fresh bake whose disk copy is still to be written (viewport)
        self.shown_after = 0  # the last frame started when it ended (viewport)

    @property
    def fraction(self) -> float:
        """Its progress, 0–1 (the Bake button's name for :attr:`progress`)."""
        return self.progress

    def start(self) -> BakeJob:
        """Run the Bake button's bake on its thread (:data:`BUTTON`)."""
        return BUTTON.start(self)

    def join(self, timeout=None) -> None:
        """Wait until it has ended, at most ``timeout`` seconds."""
        self.done.wait(timeout)

    def run(self):
        """The table (from memory, disk or a bake), then its film table and ``then``."""
        if not self.viewport:
            result, self.source = tables.get_table_with_source(self.desc, self.cache, self.report)
            return result
        result = None
        try:
            self.report(0.0, "")  # superseded before it started: stops here
            result, self.source = self._table()
            self.baked = result if self.source == "bake" else None
            if not self.film:
                tables.release_nodes(result)
            else:  # from the fresh bake's reflectance at its nodes: no second sweep
                self.report(1.0, "film table")  # superseded meanwhile: stops here
                tables.get_film(self.desc, result, self.report)
            self.report(1.0, "grid")
            self._then(result)
        except workers.Cancelled:  # a table baked before the cancel is still written to disk (after)
            tables.release_nodes(result)
            raise
        return result

    def _table(self):
        """(table, source): from memory or disk, else baked by the helper (the ticket handed
        over on the main thread) or in process. A ticket whose table was found after all, or
        whose job failed or was superseded, is cancelled."""
        ticket = self.ticket
        baker = bake_helper.baker(ticket, tables.keep_film) if ticket is not None else None
        try:
            result, source = tables.get_table_with_source(
                self.desc, self.cache, self.report, store=False, keep_nodes=True, baker=baker
            )
        except BaseException:
            if ticket is not None:
                ticket.cancel()
            raise
        if ticket is not None and source != "bake":
            ticket.cancel()  # in memory or on disk after all
        return result, source

    def _then(self, result) -> None:
        """Run the follow-up (its grid) unless it was superseded; its failure is logged and
        leaves the table (the draw asks for the grid again)."""
        if self.then is None or self.cancelled:
            return
        try:
            built = getattr(self.ticket, "grid", None)  # built by the bake helper with the table
            with reporting(self.check):  # the grid's steps: a superseded job stops
                if built is not None:
                    self.then(self.key, self.desc, result, built)
                else:
                    self.then(self.key, self.desc, result)
        except workers.Cancelled:
            raise
        except Exception as exc:  # the table is good; the draw asks for the grid the usual way
            log.error("Thin Film SH: radiance grid after the bake failed: %s", exc)

    def fail(self, exc: Exception, lane: workers.Lane) -> None:
        """A viewport bake's error is remembered before it leaves the lane (the draw must not
        ask for it again) and logged; the Bake button reports its own."""
        if self.viewport:
            text = tables.record_failure(self.desc, exc)
            log.error("Thin Film SH: bake failed: %s", text)

    def leave(self) -> None:
        """Forget the materials this bake served (or failed, or cancelled: the next draw asks
        again), under :data:`BAKES`' lock."""
        if not self.viewport:
            return
        for owner in [o for o, k in _wanted.items() if k == self.key and o not in _pending]:
            del _wanted[owner]
        self.shown_after = workers.FRAMES.started

    def after(self) -> None:
        """After the frame that shows it, the fresh table's disk copy (the write would compete
        with that frame)."""
        if self.baked is None:
            return
        workers.FRAMES.wait_past(self.shown_after, STORE_WAIT_S)
        if tables.MEMORY.get(self.key) is not None:  # not cleared meanwhile (Clear Cache, file load)
            tables.store_table(self.desc, self.baked, self.cache)
        if tables.CACHE_ERRORS.get(self.key) is not None:
            BAKES.mark_finished()  # a redraw shows why the table was not saved
        self.baked = None


# ----------------------------------------------------------------------------------------------
# The viewport's queue
# ----------------------------------------------------------------------------------------------
def want(desc, owner=None, film: bool = False, then=None) -> None:
    """Queue a bake of ``desc`` for the material ``owner`` (None: the description itself), with
    its film table if ``film`` and ``then`` run after it (:class:`BakeJob`), unless its last
    bake failed. One bake per owner: a newer description replaces the queued one, and a running
    bake that no owner wants any more is cancelled at its next progress checkpoint."""
    key = description_key(desc)
    if key in tables.FAILURES:
        return  # backs off until the description (so its key) changes
    owner = key if owner is None else owner
    with BAKES.lock:
        _wanted[owner] = key
        running = BAKES.running.get(key)
        if running is not None and (running.film or not film):
            _pending.pop(owner, None)  # the running bake makes what this owner wants
            running.then = running.then or then  # read by its worker after the table
        else:
            queued = _pending.get(owner)
            same = queued is not None and queued.key == key
            film = film or (same and queued.film)
            then = then or (queued.then if same else None)
            _pending[owner] = BakeJob(desc, film=film, then=then, viewport=True)
        wanted = set(_wanted.values())
        superseded = [job for job in BAKES.running.values() if job.key not in wanted]
    for job in superseded:
        job.superseded = True  # before the cancel: its worker reads it once it stops
        job.cancel()  # stops at its next checkpoint, caches nothing
        if job.ticket is not None:
            job.ticket.cancel()  # in the helper too, now: its worker may wait for the lock


def start_ready() -> list[BakeJob]:
    """Move the queued bakes that can start now to the running ones (not yet started: see
    :func:`start_queued`); a description already being baked waits (unless that bake makes
    what it wants: then it is dropped). Nothing starts while a superseded in-process bake is
    still stopping (it ends at its next checkpoint, tens of ms): on two cores a slider drag's
    newest bake would otherwise share them with every older one. A bake handed to the helper is
    no such obstacle: its cancel went to the helper with the superseding edit, and the helper
    bakes one request after the other."""
    jobs = []
    with BAKES.lock:
        if any(job.cancelled and job.ticket is None for job in BAKES.running.values()):
            return jobs
        for owner, job in list(_pending.items()):
            running = BAKES.running.get(job.key)
            if running is not None:
                if running.film or not job.film:
                    del _pending[owner]
                continue
            del _pending[owner]
            if _wanted.get(owner) != job.key:
                continue  # superseded since it was queued
            BAKES.running[job.key] = job  # started by start_queued, on its own thread
            jobs.append(job)
    return jobs


def _on_disk(cache, key: str) -> bool:
    """Whether the disk cache has a table file for ``key`` (one stat: a reopened file's tables
    are read by the worker, not baked by the helper)."""
    path_for = getattr(cache, "path_for", None)  # an UnusableCache has none
    try:
        return path_for is not None and path_for(key).is_file()
    except (OSError, ValueError):
        return False


def start_queued() -> list[BakeJob]:
    """Start the queued bakes that can start now, each on its thread (main thread: the cache
    folder comes from the preferences). A table not in memory is handed to the bake helper
    here, before the thread runs: that thread needs Python's lock, which the edit's first
    redraw holds for its whole draw (20–40 ms on the 2-core machine's llvmpipe)."""
    jobs = start_ready()
    cache = tables.open_cache() if jobs else None
    for job in jobs:
        job.cache = cache
        if bake_helper.enabled() and tables.peek_table(job.desc) is None and not _on_disk(cache, job.key):
            try:
                spec = getattr(job.then, "helper_spec", None)  # its grid, built there too
                job.ticket = bake_helper.submit(job.desc, job.film, spec() if spec is not None else None)
            except bake_helper.HelperError:
                pass  # the worker bakes in process (and gives the helper up, if it is broken)
        BAKES.start(job)
    return jobs


def pending() -> bool:
    """Whether bakes wait in the queue."""
    with BAKES.lock:
        return bool(_pending)


def busy() -> bool:
    """Whether viewport bakes run or wait."""
    with BAKES.lock:
        return bool(BAKES.running or _pending)


def activity() -> str:
    """The running bakes and their progress, for the viewport's header: "" when none runs."""
    with BAKES.lock:
        running = {key: job.progress for key, job in BAKES.running.items() if not job.cancelled}
    if not running:
        return ""
    done = sum(running.values()) / len(running)
    return f"baking {len(running)} film{'s' if len(running) > 1 else ''} ({100 * done:.0f} %)"


def cancel_all() -> int:
    """Stop the running viewport bakes at their next progress checkpoint (≤ one step of the
    bake, :mod:`precompute.bakes.progress`) and drop the queued ones; returns how many were running.
    Nothing half-made is cached, and a cancelled bake is not remembered as failed: the next
    draw queues it again unless the overlay is switched off."""
    with BAKES.lock:
        jobs = list(BAKES.running.values())
        _pending.clear()
    for job in jobs:
        job.cancel()
        if job.ticket is not None:
            job.ticket.cancel()  # the helper stops it now, whatever its worker waits for
    return len(jobs)
