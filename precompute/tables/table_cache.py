"""The content-keyed cache of baked tables on disk: private, bounded, safe to clear.

A :class:`TableCache` keeps each table as ``<key>.exr`` (written by :func:`.table_io.write_table`,
tagged with its key) in a ``thinfilm_sh_tables`` subfolder of its directory, which it creates
0700 and refuses when it is a symbolic link, someone else's or writable by others
(:class:`CacheDirError`). An entry that fails the validating reader is moved aside
(``.corrupt``) and never used; beyond :data:`DEFAULT_CACHE_MAX_BYTES` (or
``THINFILM_SH_CACHE_MAX_BYTES``) the least recently used entries are deleted; ``clear`` removes
only the files the cache wrote. Users read ``docs/cache.md``. This module never imports ``bpy``.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import re
import stat
import time
from pathlib import Path

from .. import _checks
from . import _untrusted_exr, atomic_write, table_io

__all__ = ["DEFAULT_CACHE_MAX_BYTES", "CacheDirError", "TableCache", "default_cache_dir"]

log = logging.getLogger(__name__)

#: Default size limit of a :class:`TableCache` on disk (``THINFILM_SH_CACHE_MAX_BYTES`` overrides it).
DEFAULT_CACHE_MAX_BYTES = 2 * 1024**3


class CacheDirError(OSError):
    """A :class:`TableCache` directory is unsafe (a symbolic link, someone else's, writable by
    others) or cannot be created; ``str()`` says which and what to do."""

    def __init__(self, path, message: str, code: int | None = None):
        super().__init__(code, message, os.fspath(path))
        self.message = message

    def __str__(self) -> str:
        return self.message


def default_cache_dir() -> Path:
    """Where a :class:`TableCache` keeps its tables unless it is given a directory.

    ``$THINFILM_SH_CACHE`` if set (``~`` expanded), else ``$XDG_CACHE_HOME/thinfilm_sh``, else
    ``~/.cache/thinfilm_sh``: a per-user directory, never a shared one such as ``/tmp``. A relative
    ``XDG_CACHE_HOME`` is ignored, as the XDG spec requires. Nothing is created here.
    """
    override = os.environ.get("THINFILM_SH_CACHE")
    if override:
        return Path(override).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and os.path.isabs(xdg):
        return Path(xdg) / "thinfilm_sh"
    return Path.home() / ".cache" / "thinfilm_sh"


def _parse_bytes(text: str, name: str) -> int:
    """'2147483648', '2G', '500M', '1.5GiB' → bytes (K, M, G, T are powers of 1024)."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*([KMGT]?)(?:i?B)?\s*", text, re.IGNORECASE)
    if not match:
        raise ValueError(f"{name} must be a size in bytes such as 2147483648, 2G or 500M, got {text!r}")
    return int(float(match.group(1)) * 1024 ** " KMGT".index(match.group(2).upper() or " "))


def _cache_max_bytes(max_bytes) -> int:
    if max_bytes is not None:
        return _checks.positive_int("max_bytes", max_bytes, minimum=0)
    text = os.environ.get("THINFILM_SH_CACHE_MAX_BYTES", "").strip()
    return _parse_bytes(text, "THINFILM_SH_CACHE_MAX_BYTES") if text else DEFAULT_CACHE_MAX_BYTES


def _check_dir(path: Path, st: os.stat_result, *, private: bool) -> None:
    """Refuse a cache directory that someone else could use to plant or redirect tables."""
    where = f"cache directory {str(path)!r}"
    if stat.S_ISLNK(st.st_mode):
        raise CacheDirError(
            path,
            f"{where} is a symbolic link: refused (whoever controls the link controls where tables are "
            "read and written); name the directory it points to instead, or remove the link",
            errno.ELOOP,
        )
    if not stat.S_ISDIR(st.st_mode):
        raise CacheDirError(
            path, f"{where} is {_untrusted_exr._file_kind(st.st_mode)}, not a directory", errno.ENOTDIR
        )
    if not hasattr(os, "geteuid"):  # Windows: no POSIX owner or mode bits to check
        return
    uid = os.geteuid()
    if st.st_uid != uid:
        raise CacheDirError(
            path,
            f"{where} belongs to uid {st.st_uid}, not to you (uid {uid}): refused (its owner could plant "
            "or replace tables); remove it, or set THINFILM_SH_CACHE to a directory of your own",
            errno.EPERM,
        )
    if private and st.st_mode & 0o022:
        raise CacheDirError(
            path,
            f"{where} is writable by other users (mode {stat.S_IMODE(st.st_mode):o}): refused (they could "
            f"plant or replace tables); run 'chmod go-w {path}', or set THINFILM_SH_CACHE to another "
            "directory",
            errno.EPERM,
        )


def _ensure_dir(path: Path, *, create: bool, private: bool) -> bool:
    """Check one cache directory (creating it with mode 0700 if ``create``); False if absent."""
    created = False
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        if not create:
            return False
        try:
            os.makedirs(path.parent, mode=atomic_write.PRIVATE_DIR_MODE, exist_ok=True)
            with contextlib.suppress(FileExistsError):  # another process may create it first
                os.mkdir(path, atomic_write.PRIVATE_DIR_MODE)
                created = True
            st = os.lstat(path)
        except OSError as exc:
            raise CacheDirError(
                path, f"cache directory {str(path)!r} cannot be created: {exc.strerror or exc}", exc.errno
            ) from exc
    except OSError as exc:
        raise CacheDirError(
            path, f"cache directory {str(path)!r} cannot be inspected: {exc.strerror or exc}", exc.errno
        ) from exc
    _check_dir(path, st, private=private)
    if created and stat.S_IMODE(st.st_mode) != atomic_write.PRIVATE_DIR_MODE:
        with contextlib.suppress(OSError):  # a umask that removed owner bits; the mkdir made it ours
            os.chmod(path, atomic_write.PRIVATE_DIR_MODE)
    return True


_ENTRY_NAME = re.compile(r"([A-Za-z0-9_-]{1,128})\.exr")
_QUARANTINE_NAME = re.compile(r"[A-Za-z0-9_-]{1,128}\.exr\.corrupt")
_TEMP_NAME = re.compile(r"\.[A-Za-z0-9_-]{1,128}\.exr\.[A-Za-z0-9_]+\.tmp")


class TableCache:
    """Baked tables on disk, keyed by :func:`content_key` of the bake's inputs.

    Layout
        Entries are ``<directory>/thinfilm_sh_tables/<key>.exr`` (:meth:`path_for`), each tagged
        with its key in the header attribute ``thinfilm_sh/cache_key``. The cache touches nothing
        else in ``directory``, so any folder may be named, and :meth:`clear` deletes only files
        that carry the tag of their name (never, say, a user's HDRI that ends in ``.exr``).
    Location and safety
        ``directory=None`` means :func:`default_cache_dir`: ``$THINFILM_SH_CACHE`` if set, else
        the user's XDG cache directory. Directories the cache creates are mode 0700. Before any
        use the directory must not be a symbolic link and must belong to the user; the default
        directory (and always the ``thinfilm_sh_tables`` subfolder) must also not be writable by
        group or others. A directory named explicitly (the argument or ``THINFILM_SH_CACHE``) may
        be group-writable: the user chose to share it. A refusal is a :class:`CacheDirError`.
    Writes
        Atomic and verified (:func:`write_table`): concurrent writers of one key are safe, the
        last rename wins, every reader sees one complete file, and a full disk is an error, never
        an empty table.
    Validation and quarantine
        :meth:`load` reads through :func:`read_table`; an entry that fails (corrupt, truncated,
        a symbolic link, FIFO, device, size bomb, too deep JSON, not the expected table) is moved
        aside to ``<key>.exr.corrupt`` beside it, logged and reported as a miss, so the next bake
        replaces it instead of failing again.
    Size
        After each :meth:`store` the least recently used entries (by modification time, which
        :meth:`load` refreshes on a hit) are deleted until the cache holds at most ``max_bytes``
        (default ``$THINFILM_SH_CACHE_MAX_BYTES``, else :data:`DEFAULT_CACHE_MAX_BYTES` = 2 GiB;
        the entry just stored is always kept).
    """

    #: The cache's own subfolder of ``directory``, holding every file it writes.
    SUBFOLDER = "thinfilm_sh_tables"

    def __init__(self, directory=None, max_bytes: int | None = None):
        named = directory is not None or bool(os.environ.get("THINFILM_SH_CACHE"))
        self.directory = Path(os.fspath(directory)) if directory is not None else default_cache_dir()
        #: True for the default per-user directory: it must not be writable by group or others.
        self.private = not named
        self.max_bytes = _cache_max_bytes(max_bytes)

    def __repr__(self) -> str:
        return f"TableCache({str(self.directory)!r})"

    @property
    def tables_dir(self) -> Path:
        """The subfolder holding the entries: ``<directory>/thinfilm_sh_tables``."""
        return self.directory / self.SUBFOLDER

    def path_for(self, key: str) -> Path:
        """Path of the entry for ``key`` (letters, digits, ``_`` and ``-`` only)."""
        if not isinstance(key, str) or not table_io._KEY_RE.fullmatch(key):
            raise ValueError(f"key must be 1–128 characters of [A-Za-z0-9_-], got {key!r}")
        return self.tables_dir / f"{key}.exr"

    def _prepare(self, create: bool) -> bool:
        """Check (or create) the directory and the subfolder; False if they do not exist yet."""
        if not _ensure_dir(self.directory, create=create, private=self.private):
            return False
        return _ensure_dir(self.tables_dir, create=create, private=True)

    def load(self, key: str, expect: dict | None = None, *, kind: str | None = None) -> table_io.Table | None:
        """The cached table for ``key``, or None if absent or invalid (then moved aside, logged).

        Raises :class:`CacheDirError` if the cache directory is unsafe (see the class).
        """
        path = self.path_for(key)
        if not self._prepare(create=False):
            return None
        try:
            before = os.lstat(path)
        except FileNotFoundError:
            return None
        try:
            table = table_io.read_table(path, expect=expect, kind=kind)
        except FileNotFoundError:  # removed by another process in between
            return None
        except table_io.TableError as exc:
            self._quarantine(path, before, exc)
            return None
        self._touch(path)
        return table

    @staticmethod
    def _touch(path: Path) -> None:
        """Mark an entry as just used (its modification time orders the eviction)."""
        with contextlib.suppress(OSError, NotImplementedError):  # a read-only cache still serves
            if os.utime in os.supports_follow_symlinks:
                os.utime(path, follow_symlinks=False)
            else:
                os.utime(path)

    def _quarantine(self, path: Path, before: os.stat_result, exc: Exception) -> None:
        try:
            after = os.lstat(path)
        except FileNotFoundError:
            return
        if (after.st_ino, after.st_size, after.st_mtime_ns) != (
            before.st_ino,
            before.st_size,
            before.st_mtime_ns,
        ):
            # Another process replaced the entry while we read it; leave the new file alone.
            log.warning("thinfilm_sh cache: ignoring entry %s that changed while read (%s)", path, exc)
            return
        aside = path.with_name(path.name + ".corrupt")
        try:
            atomic_write.replace_file(
                os.fspath(path), os.fspath(aside)
            )  # renames a link or FIFO itself, never its target
            log.warning("thinfilm_sh cache: invalid entry moved to %s: %s", aside, exc)
        except OSError as move_exc:
            with contextlib.suppress(OSError):
                os.unlink(path)
            log.warning(
                "thinfilm_sh cache: invalid entry %s removed (%s; move failed: %s)", path, exc, move_exc
            )

    def store(
        self, key: str, data, attributes=None, precision: str = "float", *, kind: str = "sh_table"
    ) -> Path:
        """Write ``data`` as the entry for ``key`` (atomically, verified) and return its path.

        Then evicts least recently used entries beyond ``max_bytes``. Raises ``ValueError`` for
        bad data, :class:`CacheDirError` for an unsafe directory and :class:`TableWriteError`
        (naming the path) if the table cannot be written; a previous entry is then unchanged.
        """
        path = self.path_for(key)
        for attempt in range(2):
            self._prepare(create=True)
            try:
                st = os.lstat(path)
            except FileNotFoundError:
                pass
            else:
                if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
                    kind = _untrusted_exr._file_kind(st.st_mode)
                    reason = f"{kind} with {st.st_nlink} link(s), not a plain file"
                    self._quarantine(path, st, table_io.TableError(f"entry {str(path)!r} is {reason}"))
            try:
                written = table_io._write_table(
                    path, data, attributes, precision, kind, {table_io._CACHE_TAG_ATTR: key}
                )
                break
            except atomic_write.TableWriteError as exc:
                if exc.errno != errno.ENOENT or attempt:  # ENOENT: a concurrent clear() removed the folder
                    raise
        try:
            self.evict(keep=path)
        except OSError as exc:
            log.warning("thinfilm_sh cache: eviction in %s failed: %s", self.tables_dir, exc)
        return written

    def _files(self) -> list[tuple[int, str, int, str | None]]:
        """(mtime ns, name, size, key or None if quarantined) of the regular entry files."""
        files = []
        with os.scandir(self.tables_dir) as entries:
            for entry in entries:
                entry_match = _ENTRY_NAME.fullmatch(entry.name)
                if not entry_match and not _QUARANTINE_NAME.fullmatch(entry.name):
                    continue
                try:
                    st = entry.stat(follow_symlinks=False)
                except FileNotFoundError:
                    continue
                if stat.S_ISREG(st.st_mode):
                    key = entry_match.group(1) if entry_match else None
                    files.append((st.st_mtime_ns, entry.name, st.st_size, key))
        return files

    def size_bytes(self) -> int:
        """Bytes held by the entries and quarantined entries (0 if the cache does not exist)."""
        if not self._prepare(create=False):
            return 0
        return sum(size for _, _, size, _ in self._files())

    def evict(self, max_bytes: int | None = None, *, keep=None) -> int:
        """Delete least recently used files until the cache holds at most ``max_bytes``.

        ``max_bytes`` defaults to the cache's limit; ``keep`` (a path) is never deleted. Entries
        are ordered by modification time (refreshed on each :meth:`load` hit), newest first; once
        the running total passes the limit, that file and every older one go. Only files this
        cache wrote (tagged entries) and quarantined entries are deleted. Returns how many.
        """
        limit = (
            self.max_bytes if max_bytes is None else _checks.positive_int("max_bytes", max_bytes, minimum=0)
        )
        if not self._prepare(create=False):
            return 0
        files = self._files()
        if sum(size for _, _, size, _ in files) <= limit:
            return 0
        keep_name = Path(os.fspath(keep)).name if keep is not None else None
        used = removed = 0
        over = False
        for _, name, size, key in sorted(files, reverse=True):
            if name != keep_name and (over or used + size > limit):
                over = True
                path = self.tables_dir / name
                if key is None or _untrusted_exr._string_attribute(path, table_io._CACHE_TAG_ATTR) == key:
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(path)
                        removed += 1
                    continue
            used += size
        if removed:
            log.info(
                "thinfilm_sh cache: evicted %d file(s) from %s (limit %d bytes)",
                removed,
                self.tables_dir,
                limit,
            )
        return removed

    def clear(self, *, stale_temp_seconds: float = 3600.0) -> int:
        """Delete this cache's files; returns how many were removed.

        Only files this cache created are touched, and only inside its subfolder: entries
        ``<key>.exr`` that are regular files carrying the ``thinfilm_sh/cache_key`` tag of their
        own name, quarantined ``<key>.exr.corrupt`` entries, and temporary files older than
        ``stale_temp_seconds`` (left by a crashed writer; younger ones may belong to a writer
        still running). The subfolder is removed if that leaves it empty; ``directory`` is kept.
        Raises :class:`CacheDirError` if the directory is unsafe.
        """
        if not self._prepare(create=False):
            return 0
        removed = 0
        now = time.time()
        with os.scandir(self.tables_dir) as scan:
            entries = list(scan)
        for entry in entries:
            name = entry.name
            try:
                st = entry.stat(follow_symlinks=False)
            except FileNotFoundError:
                continue
            entry_match = _ENTRY_NAME.fullmatch(name)
            if entry_match:
                ours = stat.S_ISREG(st.st_mode) and _untrusted_exr._string_attribute(
                    entry.path, table_io._CACHE_TAG_ATTR
                ) == entry_match.group(1)
            elif _QUARANTINE_NAME.fullmatch(name):
                ours = not stat.S_ISDIR(st.st_mode)  # whatever was moved aside: a link goes, not its target
            elif _TEMP_NAME.fullmatch(name):
                ours = stat.S_ISREG(st.st_mode) and now - st.st_mtime > stale_temp_seconds
            else:
                ours = False
            if ours:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(entry.path)
                    removed += 1
        with contextlib.suppress(OSError):  # only succeeds when empty
            os.rmdir(self.tables_dir)
        return removed
