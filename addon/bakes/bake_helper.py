"""The viewport's table bakes in a helper process, so they never wait for Blender's main thread
(issue 16).

A bake on a thread of Blender's own process runs a few hundred numpy calls and needs Python's
global lock between them; Blender's main thread holds that lock while it draws (every Python
draw callback and interface panel). Measured on the 2-core machine with the soap preset's warm
bake and film table (``benchmarks/bake_helper.py``, docs/bake-helper.md): on a thread 36 ms with
the main thread idle, 132 ms beside a Python loop, 409 ms while it redrew the viewport; in the
helper 44, 73 and 89 ms. So a viewport bake goes to one long-lived process
(:mod:`.bake_process`: the same :func:`precompute.bakes.bake.bake` and film table, bit for bit), and
the bake's worker thread (:meth:`.bake_jobs.BakeJob.run`) waits for the answer on its pipe,
which holds no lock:

1. :func:`warm` starts the process when a viewport first draws films (0.4–0.6 s to import
   numpy and :mod:`precompute`; 40–65 MiB resident), so it is ready, and its kernel caches
   warm, by the first edit;
2. the main thread hands a bake over when its job starts (:func:`submit`, a :class:`Ticket`:
   a frame written to the pipe), unless its table is in memory or on disk;
3. :func:`baker` is the bake function the worker passes to :func:`.tables.get_table_with_source`:
   it waits for the ticket; the film table (and a rough film's SH grid) comes back with the
   table;
4. a superseded bake is cancelled in the helper too (at its next checkpoint).

Failures never lose a table: a helper that cannot start, dies, or stays silent for
:data:`SILENCE_S` is given up for the session with one logged error, and the bake runs on the
worker thread as before. A bake's own error (an invalid material) comes back as the exception
it raised, recorded by the viewport as before. The preference *Bake in a Helper Process*
(:func:`.prefs.bake_helper_enabled`) or ``THINFILM_SH_BAKE_HELPER=0`` turns it off (the tests
do, except tests/viewport/test_bake_helper.py). Headless renders, the Bake button and the command line
bake in process (nothing to draw meanwhile).
"""

from __future__ import annotations

import builtins
import collections
import itertools
import logging
import os
import queue
import sys
import threading
import time

from ...precompute.bakes import bake as precompute_bake
from ...precompute.colour import film_colour
from ...precompute.materials.material import Material
from .. import helper_process
from ..gpu import resources
from ..ui import prefs
from . import bake_process

log = logging.getLogger(__name__)

__all__ = [
    "ENV",
    "SILENCE_S",
    "STATS",
    "HelperError",
    "Ticket",
    "bake",
    "baker",
    "command",
    "enabled",
    "info",
    "process_id",
    "stop",
    "submit",
    "warm",
]

#: The helper script (run, not imported, by the helper process).
SCRIPT = os.path.abspath(bake_process.__file__)
#: Environment variable: "0", "off", "no" or "false" turns the helper off, whatever the preference.
ENV = "THINFILM_SH_BAKE_HELPER"
#: Longest the helper may stay silent (no progress, no answer) before it is given up: it reports
#: progress every ≲ 0.1 s of work and starts in ≈ 0.2 s; 300× that for a machine busy rendering.
SILENCE_S = 60.0
#: How often a waiting worker looks whether its bake was superseded.
POLL_S = 0.005

#: Counts (tests and benchmarks): "started", "submitted", "baked", "errors" (a bake's own),
#: "failed" (the helper's), "cancelled", "given_up".
STATS: collections.Counter = collections.Counter()


class HelperError(RuntimeError):
    """The helper process could not start, died or stayed silent: it is given up."""


def command() -> list[str]:
    """The helper's command line: this process's Python (Blender's bundled one in Blender; the
    interpreter that imports bpy as a module otherwise) running :mod:`.bake_process`."""
    return [sys.executable, SCRIPT, helper_process.PACKAGE_ROOT]  # it imports precompute from there


#: The helper's BLAS runs on one thread: its products are small (a soap table's contraction is
#: 0.3 M multiply-adds), and a second BLAS thread spinning for work would take the core that
#: Blender's own threads (llvmpipe draws the frame on them) need.
SINGLE_THREADED = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}


def _environment() -> dict:
    """The helper's environment: this one with :data:`SINGLE_THREADED`."""
    return {**os.environ, **SINGLE_THREADED}


#: Pipe capacity asked for (Linux ``F_SETPIPE_SZ``; the default 64 KiB takes a radiance grid's
#: 9–27 MiB in hundreds of hand-overs between the two processes).
PIPE_BYTES = 1 << 20


def _widen(pipe) -> None:
    """Ask for a :data:`PIPE_BYTES` pipe where the system can (Linux); elsewhere nothing."""
    try:
        import fcntl

        fcntl.fcntl(pipe.fileno(), getattr(fcntl, "F_SETPIPE_SZ", 1031), PIPE_BYTES)
    except (ImportError, OSError, ValueError):
        pass


class _Process(helper_process.ChildProcess):
    """The helper process, a thread reading its frames and handing each to the bake it answers."""

    def __init__(self, argv: list[str]):
        super().__init__(argv, "thinfilm_sh_bake_", text=False, env=_environment())
        for pipe in (self.proc.stdin, self.proc.stdout):
            _widen(pipe)
        self.ready = threading.Event()
        self.ready_s: float | None = None
        self.ended = False
        self._waiting: dict[int, queue.Queue] = {}
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True, name="thinfilm_sh bake helper").start()

    def _read(self) -> None:
        try:
            while (message := bake_process.receive(self.proc.stdout)) is not None:
                if message[0] == "ready":
                    self.ready_s = time.perf_counter() - self.started
                    self.ready.set()
                    continue
                with self._lock:
                    waiting = self._waiting.get(message[1])
                if waiting is not None:  # else a cancelled bake's late answer
                    waiting.put(message)
        except Exception as exc:  # a broken frame: the helper is unusable
            log.error("Thin Film SH: the bake helper's answer could not be read: %s", exc)
        finally:
            with self._lock:
                self.ended = True
                for waiting in self._waiting.values():
                    waiting.put(None)
            self.ready.set()

    def open(self, ident: int) -> queue.Queue:
        """The queue the answers to bake ``ident`` arrive in (None: the helper ended)."""
        answers: queue.Queue = queue.Queue()
        with self._lock:
            if self.ended:
                answers.put(None)
            self._waiting[ident] = answers
        return answers

    def close(self, ident: int) -> None:
        with self._lock:
            self._waiting.pop(ident, None)

    def send(self, message) -> None:
        """One frame to the helper (any thread)."""
        try:
            with self._send_lock:
                bake_process.send(self.proc.stdin, message)
        except (OSError, ValueError) as exc:
            raise HelperError(self._why(f"could not be sent a bake ({exc})")) from exc


_ids = itertools.count(1)
#: The last bake's figures (benchmarks, docs): "bake_ms" in the helper, "wait_ms" here (from
#: the request to the answer).
LAST: dict = {}
#: The session's bake helper (:class:`.helper_process.HelperSlot`).
SLOT = helper_process.HelperSlot(
    what="bake helper process",
    fallback="Tables are baked in Blender itself from now on: edits redraw more slowly while the "
    "interface is busy.",
    start=lambda: _Process(command()),
    logger=log,
    stats=STATS,
    usable=lambda process: process.alive() and not process.ended,
)


def enabled() -> bool:
    """Whether viewport bakes go to the helper: not turned off by :data:`ENV` or the preference,
    and not given up."""
    if os.environ.get(ENV, "").strip().lower() in {"0", "off", "no", "false"}:
        return False
    return prefs.bake_helper_enabled() and not SLOT.given_up


def warm() -> None:
    """Start the helper if it is enabled and not running (a process start, a few ms; it then
    imports numpy on its own). Never raises: a failed start gives it up."""
    if enabled():
        SLOT.warm()


_BUILTIN_ERRORS = {name for name in dir(builtins) if name.endswith("Error")}


def _failure(type_name: str, message: str) -> Exception:
    """The exception a bake raised in the helper, rebuilt here (a built-in error keeps its type)."""
    kind = getattr(builtins, type_name, None) if type_name in _BUILTIN_ERRORS else None
    if isinstance(kind, type) and issubclass(kind, Exception):
        try:
            return kind(message)
        except TypeError:
            pass
    return RuntimeError(f"{type_name}: {message}")


def _table(fields: dict) -> precompute_bake.BakeResult:
    """A table from :func:`.bake_process.table_fields`."""
    return precompute_bake.BakeResult(**{**fields, "material": Material.from_dict(fields["material"])})


def _final(process: _Process, answers: queue.Queue, progress) -> tuple:
    """The bake's last message ("done", "failed" or "cancelled"), its progress passed on to
    ``progress`` meanwhile (and every :data:`POLL_S`, so a superseded bake raises promptly)."""
    fraction, text = 0.0, ""
    deadline = time.perf_counter() + SILENCE_S
    while True:
        try:
            message = answers.get(timeout=POLL_S)
        except queue.Empty:
            if progress is not None:
                progress(fraction, text)
            if time.perf_counter() > deadline:
                raise HelperError(f"was silent for {SILENCE_S:g} s during a bake") from None
            continue
        if message is None:
            raise HelperError(process._why("exited"))
        deadline = time.perf_counter() + SILENCE_S
        if message[0] != "progress":
            return message
        fraction, text = message[2], message[3]
        if progress is not None:
            progress(fraction, text)


class Ticket:
    """A bake handed to the helper (:func:`submit`): :meth:`wait` for its answer on a worker
    thread, or :meth:`cancel` it (the table turned out to be in the disk cache)."""

    def __init__(self, process: _Process, desc: Material, film: bool, grid: dict | None = None):
        self.process, self.ident = process, next(_ids)
        self.answers = process.open(self.ident)
        self.start = time.perf_counter()
        self.done = False
        #: The SH grid's texels (:class:`.gpu.resources.GridTexels`) built with the table when
        #: ``grid`` asked for it and the film reads one, else None; set by :meth:`wait`.
        self.grid = None
        try:
            process.send(("bake", self.ident, desc.to_dict(), bool(film), grid))
        except BaseException:
            process.close(self.ident)
            raise
        STATS["submitted"] += 1

    def cancel(self) -> None:
        """Stop the bake in the helper (at its next checkpoint) and forget its answer."""
        if self.done:
            return
        self.done = True
        self.process.close(self.ident)
        if not self.process.ended:
            STATS["cancelled"] += 1
            try:
                self.process.send(("cancel", self.ident))
            except HelperError:
                pass

    def wait(self, progress=None):
        """(table, film table or None): see :func:`bake`."""
        try:
            message = _final(self.process, self.answers, progress)
        except BaseException:
            self.cancel()  # superseded (or silent): stop it there too
            raise
        self.done = True
        self.process.close(self.ident)
        if message[0] == "done":
            STATS["baked"] += 1
            LAST.update(bake_ms=float(message[4]), wait_ms=1000.0 * (time.perf_counter() - self.start))
            table = film_colour.FilmTable(**message[3]) if message[3] is not None else None
            if message[5] is not None:
                self.grid = resources.GridTexels(message[5]["rgba"], tuple(message[5]["shape"]))
            return _table(message[2]), table
        if message[0] == "failed":
            STATS["errors"] += 1
            raise _failure(message[2], message[3])
        raise HelperError("cancelled a bake nobody cancelled")


def submit(desc: Material, film: bool, grid: dict | None = None) -> Ticket:
    """Hand the bake of ``desc`` to the helper, starting it if need be (with its film table when
    ``film``, and its SH grid when ``grid``, :meth:`.radiance_grids.Chain.helper_spec`): a frame
    written to a pipe (≈ 0.1 ms), so the main thread may call it (the depsgraph handler does: a
    worker thread would wait for the lock the next draw holds). Whether the helper is to be used
    is the caller's to ask (:func:`enabled` reads the preferences: main thread). Raises
    :class:`HelperError` when the helper is given up, not running or cannot take it; one that
    cannot take it (its pipe broke: it died as the bake was sent) is given up here, as a bake it
    failed would be, so the caller's in-process bake is the last until the add-on restarts."""
    if SLOT.given_up:
        raise HelperError(SLOT.given_up)
    SLOT.warm()
    process = SLOT.current()
    if process is None:
        raise HelperError("is not running")
    try:
        return Ticket(process, desc, film, grid)
    except HelperError as exc:
        STATS["failed"] += 1
        SLOT.give_up(str(exc))
        raise


def bake(desc: Material, film: bool, progress=None):
    """(table, film table or None) of ``desc`` baked by the helper; the calling worker thread
    waits. ``progress(fraction, text)`` is called with the helper's progress and every
    :data:`POLL_S` while waiting; an exception it raises cancels the bake in the helper too and
    propagates. Raises :class:`HelperError` (the helper is unusable: bake in process) or the
    bake's own error."""
    return submit(desc, film).wait(progress)


def baker(ticket: Ticket, keep_film):
    """The bake function for :func:`.tables.get_table_with_source`: ``(desc, progress) →
    BakeResult`` by the helper through ``ticket`` (the bake handed over on the main thread), its
    film table, if it came with it, given to ``keep_film(desc, film_table)``; in process
    (:func:`precompute.bakes.bake.bake`) when the helper fails (it is given up). Runs on a worker:
    it reads no preference (bpy)."""

    def run(desc, progress=None):
        try:
            result, table = ticket.wait(progress)
        except HelperError as exc:
            STATS["failed"] += 1
            SLOT.give_up(str(exc))
            return precompute_bake.bake(desc, progress)
        if table is not None:
            keep_film(desc, table)
        return result

    return run


def info() -> dict:
    """The helper's state and figures: pid, start-up seconds, resident memory, why it was given
    up (benchmarks, docs)."""
    process = SLOT.current()
    found = {"given_up": SLOT.given_up, **STATS, **LAST}
    if process is not None:
        found.update(pid=process.proc.pid, start_s=process.ready_s, rss_bytes=process.rss_bytes())
    return found


#: The running helper's process id, or None (tests).
process_id = SLOT.process_id
#: Stop the helper (the next :func:`warm` starts it again).
stop = SLOT.stop
#: Stop the helper and forget that it was given up (a re-enabled add-on tries it again).
unregister = SLOT.reset


def register() -> None:
    """Nothing to start: the helper starts when a viewport first draws films (:func:`warm`)."""
