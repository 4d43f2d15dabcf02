"""Procedural Worlds' panoramas rendered by a helper process, so Blender's main thread only hands
the World over (issue 16).

bpy is not thread-safe, so the viewport cannot render a World's Cycles panorama on a thread of
its own process; rendered on the main thread (:func:`.panorama.render_world_panorama`) it froze
Blender for 0.7–0.8 s per Sky Texture edit. Instead:

1. **Main thread** (the viewport's timer, :func:`.world_job.service` → :func:`.world.read_world`
   with ``render=``:func:`submit`): the World and what it depends on are written to a private
   temporary .blend (``bpy.data.libraries.write``, absolute paths, packed images inside: ≈ 1–2 ms)
   and its path is sent to the helper; :func:`submit` returns a :class:`Pending`.
2. **The helper** (:mod:`.panorama_process`, one long-lived process started by :func:`warm` at
   the viewport's first World read, so it is warm when the first procedural World comes) appends
   the World, renders it with the very same :func:`.panorama.render_world_panorama` (samples,
   seed, size) and saves the panorama as a float32 ``.npy`` beside the .blend.
3. **A worker thread** (:func:`.world_job._analyse`) waits for the answer (:func:`resolve`) and
   goes on with the World's analysis; the draw keeps the old lighting meanwhile.

The command is the Blender binary when there is one (``bpy.app.binary_path``:
``[binary, "--background", "--factory-startup", "--python", script, "--", root]``), else the
Python running bpy as a module (``[sys.executable, script, root]``).

Failures never hang the timer: a helper that cannot start, dies or answers later than
:data:`RENDER_TIMEOUT_S` is stopped and given up for the session with one logged error, and the
World is read again on the main thread as before (:class:`HelperError`; ``world_job`` does it).
A World the helper cannot render (:class:`RenderFailed`) is read again on the main thread too,
where it gets today's message and fallback colour; the helper stays. The preference *Render
Procedural Worlds in a Helper Process* (:func:`.prefs.render_helper_enabled`) turns it off; so
does a file whose working colour space is not the helper's (factory start-up: Linear Rec.709),
since the appended World's colours would be read in another space. The process exits when its
stdin closes (:func:`stop`, :func:`unregister`, or Blender's exit).
"""

from __future__ import annotations

import collections
import dataclasses
import itertools
import json
import logging
import os
import queue
import sys
import threading
import time

import bpy
import numpy as np

from .. import helper_process
from ..colour_space import working_space
from ..ui import prefs
from . import panorama_process
from .panorama import PANORAMA_SAMPLES, PANORAMA_WIDTH

log = logging.getLogger(__name__)

__all__ = [
    "RENDER_TIMEOUT_S",
    "START_TIMEOUT_S",
    "STATS",
    "HelperError",
    "Pending",
    "RenderFailed",
    "command",
    "command_for",
    "enabled",
    "info",
    "resolve",
    "stop",
    "submit",
    "warm",
]

#: The helper script (run, not imported, by the helper process).
SCRIPT = os.path.abspath(panorama_process.__file__)
#: Longest wait for a started helper to be ready: ``import bpy`` takes ≈ 1.5–3 s on the 2-core
#: machine (docs/world-latency.md); 20× that for a machine busy with a render.
START_TIMEOUT_S = 60.0
#: Longest wait for one panorama once the helper is ready: a 256×128, 32-sample render takes
#: ≈ 0.5–1.5 s; a heavy node tree or a loaded machine many times that.
RENDER_TIMEOUT_S = 60.0
#: The working space of the helper's factory start-up (it cannot be set from Python).
HELPER_WORKING_SPACE = "Linear Rec.709"

#: Counts (tests and benchmarks): "started", "submitted", "rendered", "failed", "given_up".
STATS: collections.Counter = collections.Counter()


class HelperError(RuntimeError):
    """The helper process could not start, died or took too long: it is given up."""


class RenderFailed(RuntimeError):
    """The helper answered that it could not render this World (the World's failure)."""


def command_for(binary: str, python: str) -> list[str]:
    """The helper's command line for Blender's ``binary`` ("" for bpy as a Python module, run by
    ``python``)."""
    root = helper_process.PACKAGE_ROOT  # the script imports panorama.py from there
    if binary:
        return [binary, "--background", "--factory-startup", "--python", SCRIPT, "--", root]
    return [python, SCRIPT, root]


def command() -> list[str]:
    """The helper's command line here: Blender's binary in background mode, else this Python."""
    return command_for(bpy.app.binary_path, sys.executable)


class _Process(helper_process.ChildProcess):
    """One helper process: its pipes, a thread reading its answers, its private folder."""

    def __init__(self, argv: list[str]):
        super().__init__(argv, "thinfilm_sh_panorama_", text=True)
        self.ready = threading.Event()
        self.ready_s: float | None = None
        self.working_space = ""
        self.answers: queue.Queue = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True, name="thinfilm_sh panorama helper")
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            if not line.startswith(panorama_process.MARK):
                continue  # Blender's and Cycles' own output
            try:
                message = json.loads(line[len(panorama_process.MARK) :])
            except ValueError:
                continue
            if message.get("ready"):
                self.working_space = str(message.get("working_space", ""))
                self.ready_s = time.perf_counter() - self.started
                self.ready.set()
            else:
                self.answers.put(message)
        self.answers.put(None)  # end of output: the process exited
        self.ready.set()

    def send(self, request: dict) -> None:
        """Write one request line (main thread; a line never fills the pipe)."""
        try:
            self.proc.stdin.write(json.dumps(request) + "\n")
            self.proc.stdin.flush()
        except (OSError, ValueError) as exc:
            raise HelperError(f"could not be sent the World ({exc})") from exc

    def answer(self, ident: int, timeout: float) -> dict:
        """The answer to request ``ident`` (a worker thread waits here), or HelperError."""
        if not self.ready.wait(START_TIMEOUT_S) or self.ready_s is None:
            raise HelperError(self._why("did not start"))
        deadline = time.perf_counter() + timeout
        while True:
            remaining = deadline - time.perf_counter()
            try:
                message = self.answers.get(timeout=max(remaining, 0.0))
            except queue.Empty:
                raise HelperError(f"took longer than {timeout:g} s to render the World") from None
            if message is None:
                self.answers.put(None)  # for whoever waits next
                raise HelperError(self._why("exited"))
            if message.get("id") == ident:
                return message


_ids = itertools.count(1)
#: The last hand-over's figures (benchmarks, docs): "write_ms", "wait_ms", "render_ms".
LAST: dict = {}
#: The session's panorama helper (:class:`.helper_process.HelperSlot`).
SLOT = helper_process.HelperSlot(
    "panorama helper process",
    "Procedural Worlds are rendered in Blender itself from now on: the viewport pauses while one renders.",
    lambda: _Process(command()),
    log,
    STATS,
)


def enabled() -> bool:
    """Whether procedural Worlds go to the helper: the preference is on, the helper was not
    given up, and the file's working colour space is the helper's."""
    return prefs.render_helper_enabled() and not SLOT.given_up and working_space() == HELPER_WORKING_SPACE


def warm() -> None:
    """Start the helper if it is enabled and not running (main thread: a process start, a few ms;
    the helper then imports bpy on its own). Never raises: a failed start gives it up."""
    if enabled():
        SLOT.warm()


@dataclasses.dataclass
class Pending:
    """A panorama the helper renders: :meth:`result` waits for it (a worker thread, never the
    main thread)."""

    process: _Process
    ident: int
    blend: str
    out: str

    def result(self, timeout: float | None = None) -> np.ndarray:
        """The panorama (shape (width/2, width, 3), float32, as :func:`.panorama.render_world_panorama`).

        Waits at most ``timeout`` seconds (default :data:`RENDER_TIMEOUT_S`) once the helper is
        ready. Raises :class:`HelperError` (the helper is given up) or :class:`RenderFailed`.
        """
        timeout = RENDER_TIMEOUT_S if timeout is None else timeout
        start = time.perf_counter()
        try:
            message = self.process.answer(self.ident, timeout)
        except HelperError as exc:
            _remove(self.blend)
            if not self.process.stopped:  # else stopped on purpose: the World is read again
                STATS["failed"] += 1
                self.process.stop()
                SLOT.give_up(str(exc))  # removes its folder, the .npy included
            raise
        _remove(self.blend)
        LAST.update(wait_ms=1000.0 * (time.perf_counter() - start), render_ms=message.get("ms"))
        try:
            if not message.get("ok"):
                STATS["failed"] += 1
                raise RenderFailed(str(message.get("error", "no panorama")))
            rgb = np.load(self.out, allow_pickle=False)
        finally:
            _remove(self.out)
        STATS["rendered"] += 1
        return rgb


def _remove(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass


def submit(world) -> Pending | None:
    """Hand ``world`` to the helper (main thread: a .blend write and one line to a pipe); None
    when the helper is off or could not take it (then render it here, as before)."""
    if not enabled():
        return None
    warm()
    process = SLOT.current()
    if process is None:
        return None
    ident = next(_ids)
    blend = os.path.join(process.folder, f"world-{ident}.blend")
    out = os.path.join(process.folder, f"world-{ident}.npy")
    start = time.perf_counter()
    try:
        bpy.data.libraries.write(blend, {world}, path_remap="ABSOLUTE", fake_user=True, compress=False)
        LAST["write_ms"] = 1000.0 * (time.perf_counter() - start)
        request = {"id": ident, "blend": blend, "world": world.name, "out": out}
        process.send({**request, "width": PANORAMA_WIDTH, "samples": PANORAMA_SAMPLES})
    except (OSError, RuntimeError) as exc:  # HelperError is a RuntimeError
        _remove(blend)
        SLOT.give_up(f"could not be handed the World ({exc})")
        return None
    STATS["submitted"] += 1
    return Pending(process, ident, blend, out)


def resolve(read):
    """``read`` (a :class:`.world.WorldRead`) with its panorama in ``rgb`` once the helper has
    rendered it (a worker thread waits here); ``read`` itself when nothing is pending."""
    pending = getattr(read, "pending", None)
    if pending is None:
        return read
    return dataclasses.replace(read, rgb=pending.result(), pending=None)


def info() -> dict:
    """The helper's state and figures: pid, start-up seconds, resident memory, the last write,
    wait and render times, and why it was given up (benchmarks, docs)."""
    process = SLOT.current()
    found = dict(LAST, given_up=SLOT.given_up)
    if process is not None:
        found.update(
            pid=process.proc.pid,
            start_s=process.ready_s,
            rss_bytes=process.rss_bytes(),
            working_space=process.working_space,
        )
    return found


#: The running helper's process id, or None (tests).
process_id = SLOT.process_id
#: Stop the helper (the next :func:`warm` starts it again).
stop = SLOT.stop
#: Stop the helper and forget that it was given up (a re-enabled add-on tries it again).
unregister = SLOT.reset


def register() -> None:
    """Nothing to start: the helper starts at the viewport's first World read (:func:`warm`)."""
