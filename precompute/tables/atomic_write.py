"""Safe writes of any output: a temporary file beside the destination, flushed, verified, renamed.

:func:`write_file` (and :func:`write_bytes` on it) writes to a temporary file beside the
destination, flushes and verifies it (not empty; the caller's check, e.g. that it reads back
through the validating EXR reader), and only then renames it over the destination; a destination
that is not a plain regular file (symbolic link, FIFO, device, directory, hard link) is refused
(:func:`check_destination`), and every failure is a :class:`TableWriteError` naming the path,
with the previous file left as it was. The EXR table format that uses it is :mod:`.table_io`.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
import time
from pathlib import Path

from ._untrusted_exr import _file_kind, _read_regular

__all__ = ["PRIVATE_DIR_MODE", "TableWriteError", "check_destination", "write_bytes", "write_file"]

#: Published outputs are ordinary shareable files (mkstemp creates 0600).
_OUTPUT_MODE = 0o644
#: A private folder (the table cache's): only its owner may list or enter it.
PRIVATE_DIR_MODE = 0o700


class TableWriteError(OSError):
    """An output could not be written, or its destination was refused; ``str()`` names the path.

    ``errno`` is the operating system's code when there is one (``ENOSPC``, ``EACCES``,
    ``EDQUOT``, ``EROFS``, …); ``filename`` is the destination. Whatever was at the destination
    before is unchanged.
    """

    def __init__(self, path, message: str, code: int | None = None):
        super().__init__(code, message, os.fspath(path))
        self.message = message

    def __str__(self) -> str:
        return self.message


def replace_file(src: str, dst: str) -> None:
    """``os.replace`` with a short retry: on Windows it fails while ``dst`` is open elsewhere."""
    for attempt in range(5):
        try:
            os.replace(src, dst)
            return
        except PermissionError:
            if os.name != "nt" or attempt == 4:
                raise
            time.sleep(0.05 * (attempt + 1))


def check_destination(path) -> Path:
    """``path`` as a Path if an output may be written there, else :class:`TableWriteError`.

    A destination that does not exist, or is a regular file with no other hard link, may be
    replaced. Anything else is refused, looked at with ``lstat`` (a link is never followed):
    a symbolic link (replacing the link would silently not write where it points), a FIFO, a
    device (run as root, replacing ``/dev/null`` would break the machine), a socket, a directory,
    or a file with several hard links (replacing this name would silently separate it from the
    others). :func:`write_file` checks again just before publishing.
    """
    path = Path(os.fspath(path))
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise TableWriteError(path, f"cannot write {str(path)!r}: {exc.strerror}", exc.errno) from exc
    if not stat.S_ISREG(st.st_mode):
        raise TableWriteError(
            path,
            f"refusing to write {str(path)!r}: it exists and is {_file_kind(st.st_mode)}, not a regular "
            "file; choose another path or remove it first",
            errno.EEXIST,
        )
    if st.st_nlink > 1:
        raise TableWriteError(
            path,
            f"refusing to write {str(path)!r}: it has {st.st_nlink} hard links, and replacing it would "
            "separate it from the others; choose another path or remove it first",
            errno.EMLINK,
        )
    return path


def _write_failed(path: Path, existed: bool, what: str, code: int | None = None) -> TableWriteError:
    after = "the previous file is unchanged" if existed else "nothing was written"
    return TableWriteError(path, f"could not write {str(path)!r}: {what}; {after}", code)


def _fsync_file(path: str) -> None:
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_BINARY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    """Make a rename in ``path`` durable (POSIX; a no-op where directories cannot be opened)."""
    if os.name == "nt":
        return
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_file(path, writer, *, verify=None) -> Path:
    """Write an output safely: ``writer(temporary_path)`` fills a temporary file beside ``path``,
    which is flushed, verified and then renamed over ``path``; returns ``path`` as a Path.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder must exist. Refused if it is not a plain regular file
        (:func:`check_destination`).
    writer : callable(str)
        Writes the whole output to the path it is given (which exists, empty, mode 0600).
        ``OSError`` and ``RuntimeError`` (how the OpenEXR binding reports I/O failures) become
        :class:`TableWriteError`; anything else propagates unchanged.
    verify : callable(str), optional
        Checks the written file, raising ``ValueError`` (e.g. :class:`TableError`) if it is
        incomplete or wrong. An empty file is always refused: a full disk can make a writer
        return normally after writing nothing.

    Raises
    ------
    TableWriteError
        The destination was refused, or writing, flushing, verifying or renaming failed (disk
        full, permission, quota, read-only file system, …). The message names ``path``; the
        previous file at ``path``, if any, is unchanged and no temporary file is left.
    """
    path = check_destination(path)
    existed = os.path.lexists(path)
    parent = path.parent
    try:
        fd, tmp = tempfile.mkstemp(dir=parent, prefix=f".{path.name[:200]}.", suffix=".tmp")
        os.close(fd)
    except OSError as exc:
        raise _write_failed(path, existed, exc.strerror or str(exc), exc.errno) from exc
    try:
        try:
            writer(tmp)
            _fsync_file(tmp)
            size = os.stat(tmp).st_size
        except OSError as exc:
            raise _write_failed(path, existed, exc.strerror or str(exc), exc.errno) from exc
        except RuntimeError as exc:
            raise _write_failed(path, existed, str(exc).rstrip(". ")) from exc
        if size == 0:
            raise _write_failed(path, existed, "the file written is empty (is the disk full?)", errno.ENOSPC)
        if verify is not None:
            try:
                verify(tmp)
            except (ValueError, OSError) as exc:
                raise _write_failed(
                    path, existed, f"the file written is incomplete or wrong (is the disk full?): {exc}"
                ) from exc
        check_destination(path)  # again: something may have appeared there meanwhile
        try:
            os.chmod(tmp, _OUTPUT_MODE)
            replace_file(tmp, os.fspath(path))
        except OSError as exc:
            raise _write_failed(path, existed, exc.strerror or str(exc), exc.errno) from exc
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_dir(parent)
    return path


def write_bytes(path, payload: bytes) -> Path:
    """Write ``payload`` to ``path`` with the guarantees of :func:`write_file`; returns the path.

    Verified by reading the file back: it must hold exactly ``payload``, which must not be empty
    (an empty file cannot be told from a write that failed on a full disk).
    """
    payload = bytes(payload)
    if not payload:
        raise ValueError(f"refusing to write an empty file to {os.fspath(path)!r}")

    def writer(tmp: str) -> None:
        with open(tmp, "wb") as handle:
            handle.write(payload)

    def verify(tmp: str) -> None:
        found = _read_regular(tmp, f"file {tmp!r}", len(payload) + 1)
        if found != payload:
            raise ValueError(f"{len(found)} bytes read back, {len(payload)} written, contents differ")

    return write_file(path, writer, verify=verify)
