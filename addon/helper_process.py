"""A long-lived child process of the add-on, its pipes and its private folder, and its life in
the session (:class:`HelperSlot`): what the panorama helper (:mod:`.panorama_helper`) and the
bake helper (:mod:`.bake_helper`) share.

Each helper is started by its module's ``warm`` and ends when its stdin closes (``stop``, the
add-on's ``unregister``, or Blender's exit: the pipe closes with its parent), so no helper
outlives its Blender. Its stderr goes to ``helper.log`` in its private folder (0700), which
:meth:`ChildProcess.stop` removes.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import threading
import time

__all__ = ["PACKAGE_ROOT", "STOP_WAIT_S", "ChildProcess", "HelperSlot"]

#: The extension package's folder (the parent of ``addon/``): each helper's script is given it,
#: to import the extension's own files from.
PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: How long :meth:`ChildProcess.stop` lets the helper exit on its own (stdin closed) before
#: killing it.
STOP_WAIT_S = 2.0


class ChildProcess:
    """One helper process: started with ``argv``, stdin and stdout piped (text lines when
    ``text``, else bytes), stderr to ``helper.log`` in a private folder named ``prefix``…"""

    def __init__(self, argv: list[str], prefix: str, *, text: bool, env: dict | None = None):
        self.folder = tempfile.mkdtemp(prefix=prefix)  # private: 0700
        self.started = time.perf_counter()
        self.stopped = False  # stopped on purpose (unregister, a restart): not a failure
        self._log = open(os.path.join(self.folder, "helper.log"), "wb")  # noqa: SIM115 (closed in stop)
        options = dict(text=True, encoding="utf-8", errors="replace", bufsize=1) if text else {}
        try:
            self.proc = subprocess.Popen(
                argv,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=self._log,
                env=env,
                creationflags=getattr(subprocess, "CREATE_NO_WINDOW", 0),  # Windows: no console
                **options,
            )
        except BaseException:
            self._log.close()
            shutil.rmtree(self.folder, ignore_errors=True)
            raise

    def alive(self) -> bool:
        """Whether the process still runs."""
        return self.proc.poll() is None

    def _why(self, what: str) -> str:
        code = self.proc.poll()
        return f"{what}{f' (exit code {code})' if code is not None else ''}; its log: {self._log.name}"

    def rss_bytes(self) -> int | None:
        """The process's resident memory (Linux), or None."""
        try:
            with open(f"/proc/{self.proc.pid}/status") as status:
                for line in status:
                    if line.startswith("VmRSS:"):
                        return int(line.split()[1]) * 1024
        except OSError:
            return None
        return None

    def stop(self) -> None:
        """Close its stdin (it exits), kill it if it has not within :data:`STOP_WAIT_S`, remove
        its folder."""
        self.stopped = True
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._log.close()
        shutil.rmtree(self.folder, ignore_errors=True)


class HelperSlot:
    """The one helper process of a kind for the session: started on demand (:meth:`warm`),
    started again when it exited while idle, given up for the session when it fails
    (:meth:`give_up`: logged once, ``fallback`` says what happens instead).

    ``start()`` makes a :class:`ChildProcess` (raising OSError when it cannot); ``usable(process)``
    says whether a started one can still take work; ``stats`` counts "started" and "given_up".
    """

    def __init__(self, what: str, fallback: str, start, logger, stats, usable=None):
        self.what, self.fallback = what, fallback
        self._start, self._log, self._stats = start, logger, stats
        self._usable = usable or (lambda process: process.alive())
        self.lock = threading.Lock()
        self.process = None
        self.given_up = ""  # why it was given up for this session ("" while it is not)

    def warm(self) -> None:
        """Start the helper unless one runs (a process start, a few ms). Never raises: a failed
        start gives it up."""
        with self.lock:
            if self.process is not None and self._usable(self.process):
                return
            old, self.process = self.process, None
        if old is not None:
            self._log.warning("Thin Film SH: the %s %s: starting it again", self.what, old._why("had exited"))
            old.stop()
        try:
            started = self._start()
        except OSError as exc:
            self.give_up(f"could not be started ({exc})")
            return
        self._stats["started"] += 1
        with self.lock:
            self.process = started

    def current(self):
        """The running helper, or None."""
        with self.lock:
            return self.process

    def give_up(self, why: str) -> None:
        """Stop the helper and do without it for the session (logged once, at error level)."""
        with self.lock:
            first = not self.given_up
            self.given_up = self.given_up or why
            old, self.process = self.process, None
        if old is not None:
            old.stop()
        if first:
            self._stats["given_up"] += 1
            self._log.error("Thin Film SH: the %s %s. %s", self.what, why, self.fallback)

    def process_id(self) -> int | None:
        """The running helper's process id, or None (tests)."""
        with self.lock:
            process = self.process
        return process.proc.pid if process is not None and process.alive() else None

    def stop(self) -> None:
        """Stop the helper (the next :meth:`warm` starts it again)."""
        with self.lock:
            old, self.process = self.process, None
        if old is not None:
            old.stop()

    def reset(self) -> None:
        """Stop the helper and forget that it was given up (a re-enabled add-on tries again)."""
        self.stop()
        self.given_up = ""
