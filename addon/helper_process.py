"""A long-lived child process of the add-on, its pipes and its private folder: what the panorama
helper (:mod:`.panorama_helper`) and the bake helper (:mod:`.bake_helper`) share.

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
import time

__all__ = ["STOP_WAIT_S", "ChildProcess"]

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
