"""Background work: the one job type, the one way it runs, and the redraw when it ends.

Every piece of the add-on's background work is a :class:`Job` (what it works on, its progress,
its cancel, its result or error) run by a :class:`Lane` (one kind of work: its running jobs by
key, one lock, a daemon thread per job, a *finished* flag). What runs where:

=================================== ============================== ====================================
lane                                jobs                           its own scheduling rules
=================================== ============================== ====================================
``bakes.bake_jobs.BAKES``           the viewport's table bakes     one per material, the newest value
                                    (``bake_jobs.BakeJob``)        wins, a superseded one cancelled,
                                                                   nothing new while one stops
``bakes.bake_jobs.BUTTON``          the Bake button's bake (the    one per button press, Esc cancels
                                    same ``BakeJob``)
``world.world_job.WORK``            the World's analysis,          one content analysis at a time, the
                                    prefilters                     newest World read when it ends
``bakes.radiance_grids.GRIDS.work`` outgoing-radiance grids        one worker drains a queue of at most
                                                                   ``QUEUE_SIZE``, newest first
``drawing.display.LUT_WORK``        the viewport's display LUT     one per display settings
``eevee.sync.WORK``                 the EEVEE films' images        one worker drains a queue, the newest
                                    (tables and pixels)            edit per material
=================================== ============================== ====================================

Work that must run on Blender's main thread but not inside a draw is :class:`Deferred`: queued
(the newest per key wins) where it cannot run and run by a timer — the Cycles bakes of linked
thicknesses (``thickness.linked.PENDING``, run by the viewport's timer). The shader variants the
draw drew by their stand-in are compiled the same way, one per idle step
(``drawing.shader_warmup``; the queue is the shader cache's ``wanted`` list).

**Lock discipline.** A lane's lock (:attr:`Lane.lock`, reentrant) guards its running jobs and
whatever its room keeps beside them (a queue, what each material wants); it is held only for
those dictionary steps — never while a job works, never across a call into another room, and
never together with another lane's lock. A job's own fields (progress, text, cancel,
superseded) are each written by one thread and read without a lock.

**Redraw when done.** A job that ends sets its lane's *finished* flag unless it has nothing to
show (cancelled because a newer value superseded it); the viewport's timer, or the lane's own
poll, takes the flag (:meth:`Lane.take_finished`) and tags the 3D views (:func:`tag_view3d`).
:data:`FRAMES` numbers the draw callback's frames, so work can wait for the frame that shows its
result before it does what would compete with that frame (a bake's disk copy).
"""

from __future__ import annotations

import logging
import threading
import time

import bpy

__all__ = ["FRAMES", "Cancelled", "Deferred", "FrameCount", "Job", "Lane", "tag_view3d"]

log = logging.getLogger(__name__)


def tag_view3d() -> None:
    """Tag every 3D view of every window for a redraw (none in background mode).

    Shared by the viewport's timer (:mod:`.drawing.viewport`), the radiance-grid worker's timer
    (:mod:`.bakes.radiance_grids`), the idle shader compile (:mod:`.drawing.shader_warmup`) and
    the EEVEE sync's timer when it made a thickness map (:mod:`.eevee.sync`);
    each imports it as its own ``_tag_redraw``, so a test or benchmark can replace one module's.
    """
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


class Cancelled(Exception):
    """Raised by :meth:`Job.check` and :meth:`Job.report` once the job was cancelled: the work
    stops at its next checkpoint and nothing half-made is kept."""


class Job:
    """One piece of background work, run by a :class:`Lane` on a thread of its own.

    ``key``: what it works on (its lane keeps one running job per key); :attr:`progress` (0–1)
    and :attr:`text` follow its checkpoints (:meth:`report`); :meth:`cancel` makes the next
    checkpoint raise :class:`Cancelled`. Once :attr:`done` is set: :attr:`result` (what
    :meth:`run` returned) or :attr:`error`, and :attr:`elapsed_s`. :attr:`superseded`: a newer
    value replaced it, so, cancelled, it has nothing to show (no redraw).

    Subclasses write :meth:`run`, or pass ``target`` (called with ``args``).
    """

    def __init__(self, key=None, target=None, *args):
        self.key = key
        self.progress = 0.0
        self.text = ""
        self.result = None
        self.error: BaseException | None = None
        self.elapsed_s = 0.0
        self.superseded = False
        #: It ended at a checkpoint because it was cancelled (set by its lane).
        self.stopped = False
        self.done = threading.Event()
        self._cancel = threading.Event()
        self._target, self._args = target, args

    @property
    def cancelled(self) -> bool:
        """Whether :meth:`cancel` was called."""
        return self._cancel.is_set()

    def cancel(self) -> None:
        """Stop the job at its next checkpoint (:meth:`check`, :meth:`report`)."""
        self._cancel.set()

    def check(self) -> None:
        """A checkpoint: raise :class:`Cancelled` once the job was cancelled."""
        if self._cancel.is_set():
            raise Cancelled

    def report(self, fraction, text="") -> None:
        """A checkpoint with progress (a bake's ``progress(fraction, text)`` callback)."""
        self.check()
        self.progress, self.text = float(fraction), str(text)

    def run(self):
        """The work, on the lane's thread; its return value becomes :attr:`result`."""
        return self._target(*self._args)

    def fail(self, exc: Exception, lane: Lane) -> None:
        """:meth:`run` raised ``exc`` (still in the lane, before it leaves): logged here."""
        log.error("Thin Film SH: %s failed: %s", lane.what, exc)

    def leave(self) -> None:
        """The job leaves its lane's running jobs: the room's bookkeeping (under the lane's lock)."""

    def shows_something(self) -> bool:
        """Whether its end changes what the views show (else no redraw): all but a job stopped
        by its cancel because a newer value superseded it."""
        return not (self.stopped and self.superseded)

    def after(self) -> None:
        """Work after the job left its lane and its redraw was asked for (a bake's disk copy)."""


class Lane:
    """One kind of background work: its running jobs by key (:attr:`running`), one reentrant
    lock (:attr:`lock`), a daemon thread per job, and a *finished* flag for the redraw.

    ``what`` names the work in log lines ("World analysis").
    """

    def __init__(self, what: str):
        self.what = what
        self.lock = threading.RLock()
        self.running: dict = {}
        self._threads: dict = {}
        self._finished = threading.Event()

    def start(self, job: Job) -> Job:
        """Run ``job`` on a new daemon thread; it is in :attr:`running` under its key until it
        ends (replacing any entry of that key: the caller checks first, under :attr:`lock`)."""
        thread = threading.Thread(target=self._run, args=(job,), daemon=True, name=f"thinfilm_sh {self.what}")
        with self.lock:
            self.running[job.key] = job
            self._threads[job] = thread
        thread.start()
        return job

    def _run(self, job: Job) -> None:
        start = time.perf_counter()
        try:
            job.result = job.run()
        except Cancelled:
            job.stopped = True
        except Exception as exc:  # reported, never raised into Blender
            job.error = exc
            job.fail(exc, self)
        finally:
            job.elapsed_s = time.perf_counter() - start
            with self.lock:
                # the cue before leaving the running jobs: a timer tick that saw neither would stop
                if job.shows_something():  # for good and never show this job's result
                    self._finished.set()
                if self.running.get(job.key) is job:
                    del self.running[job.key]
                self._threads.pop(job, None)
                job.leave()
            job.done.set()
        job.after()

    def busy(self) -> bool:
        """Whether any job runs."""
        with self.lock:
            return bool(self.running)

    def jobs(self) -> list:
        """The running jobs (a copy)."""
        with self.lock:
            return list(self.running.values())

    def mark_finished(self) -> None:
        """Ask for a redraw without a job ending (a result that arrived another way)."""
        self._finished.set()

    def finished(self) -> bool:
        """Whether a redraw is asked for (the flag is left as it is)."""
        return self._finished.is_set()

    def take_finished(self) -> bool:
        """Whether work ended since the last call (then redraw); clears the flag."""
        done = self._finished.is_set()
        self._finished.clear()
        return done

    def wait(self, timeout: float = 120.0) -> None:
        """Wait for the running jobs' threads (tests, benchmarks, unregister)."""
        with self.lock:
            threads = list(self._threads.values())
        for thread in threads:
            thread.join(timeout)


class Deferred:
    """Main-thread work queued where it cannot run (inside a draw): one call per key, the newest
    winning, run later by a timer (:meth:`run`, main thread, outside drawing)."""

    def __init__(self, what: str):
        self.what = what
        self.lock = threading.RLock()
        self._calls: dict = {}

    def defer(self, key, call) -> None:
        """Queue ``call()`` under ``key`` (replacing a queued call of that key)."""
        with self.lock:
            self._calls[key] = call

    def __bool__(self) -> bool:
        with self.lock:
            return bool(self._calls)

    def __len__(self) -> int:
        with self.lock:
            return len(self._calls)

    def run(self, errors=(Exception,)) -> list:
        """Run the queued calls (main thread); returns ``(key, exception)`` of each that raised
        one of ``errors`` (others propagate)."""
        with self.lock:
            calls = list(self._calls.items())
            self._calls.clear()
        failed = []
        for key, call in calls:
            try:
                call()
            except errors as exc:
                failed.append((key, exc))
        return failed

    def clear(self) -> None:
        """Forget the queued calls."""
        with self.lock:
            self._calls.clear()


class FrameCount:
    """The draw callback's frames, numbered: work waits for the first frame started after its
    result arrived (:meth:`wait_past`) before it does what would compete with that frame."""

    def __init__(self):
        self.started = 0
        self.ended = 0
        self._cond = threading.Condition()

    def start(self) -> int:
        """A frame begins: its number."""
        with self._cond:
            self.started += 1
            return self.started

    def end(self, number: int) -> None:
        """Frame ``number`` has been drawn (or given up)."""
        with self._cond:
            self.ended = max(self.ended, number)
            self._cond.notify_all()

    def wait_past(self, number: int, timeout: float) -> bool:
        """Wait until a frame started after frame ``number`` has ended, at most ``timeout`` s."""
        with self._cond:
            return self._cond.wait_for(lambda: self.ended > number, timeout)


#: The viewport's frames (started and ended by :func:`.drawing.viewport.draw_callback`).
FRAMES = FrameCount()
