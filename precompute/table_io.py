"""Self-describing baked tables in OpenEXR, a validating reader, safe writes and a content-keyed cache.

A baked table is an N-D float array (for example (T, A, K, 9): thickness × view angle × SH
coefficient × a flattened 3×3 matrix) plus a flat dict of JSON-serialisable metadata. It is
stored as ONE scanline OpenEXR file with lossless ZIP compression, laid out as a 2-D image:

- the last axis becomes the channels ``c00``, ``c01``, … (zero-padded so that OpenEXR's
  alphabetical channel order is the numeric order);
- the second-to-last axis is the image width;
- all leading axes are flattened, in C order, into the image height (a 1-D array is a
  1 × 1 image with one channel per element).

Header attributes (all strings except the version, because the OpenEXR binding silently
drops lists of ints, truncates ints to 32 bits and floats to float32):

``thinfilm_sh/format_version``  int, :data:`FORMAT_VERSION`
``thinfilm_sh/kind``            str, e.g. ``"sh_table"``
``thinfilm_sh/shape``           str, JSON list of the full N-D shape
``thinfilm_sh/precision``       str, ``"float"`` (FLOAT32 pixels) or ``"half"`` (HALF pixels)
``thinfilm_sh/attributes``      str, canonical JSON of the caller's metadata (sorted keys)
``thinfilm_sh/content_hash``    str, sha256 hex, see :func:`_content_hash`
``thinfilm_sh/cache_key``       str, only in :class:`TableCache` entries: the entry's key (the tag
                                that lets :meth:`TableCache.clear` tell its own files from others)

The hash covers the *stored* values (after rounding to float32/half, little-endian, C order),
the shape, precision, kind, format version and the canonical JSON of the attributes, so the
reader recomputes it from what it decoded and any flipped pixel or edited header is refused.

Files are untrusted input. :func:`read_table` opens only regular files (never through a
symbolic link, never blocking on a FIFO), reads at most the file's size, checks every size the
file declares against hard limits (:data:`MAX_TABLE_VALUES`, :data:`MAX_CHANNELS`, …) before
anything is allocated, and limits JSON nesting; every failure is a :class:`TableError`.

Every write (:func:`write_table`, :func:`write_file`, :func:`write_bytes`) goes to a temporary
file beside the destination, is flushed and verified (not empty, reads back through the
validating reader, ends where its structure says), and only then replaces the destination; a
destination that is not a plain regular file (symbolic link, FIFO, device, directory, hard
link) is refused, and every failure is a :class:`TableWriteError` naming the path, with the
previous file left as it was. ``docs/cache.md`` describes the cache for users.

``OpenEXR`` is imported lazily, so :func:`content_key` and :func:`half_precision_error` work
without it. This module never imports ``bpy``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import hashlib
import io
import json
import logging
import math
import os
import re
import stat
import struct
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from . import _checks

__all__ = [
    "DEFAULT_CACHE_MAX_BYTES",
    "FORMAT_VERSION",
    "MAX_CHANNELS",
    "MAX_TABLE_VALUES",
    "CacheDirError",
    "HalfError",
    "Table",
    "TableCache",
    "TableError",
    "TableWriteError",
    "check_destination",
    "content_key",
    "default_cache_dir",
    "half_precision_error",
    "read_table",
    "verify_exr",
    "write_bytes",
    "write_file",
    "write_table",
]

log = logging.getLogger(__name__)

#: Version of the on-disk layout written by :func:`write_table`; :func:`read_table` accepts only this.
FORMAT_VERSION = 1

PRECISIONS = ("float", "half")
HALF_MAX = 65504.0  # largest finite IEEE half
HALF_MIN_NORMAL = 2.0**-14  # smallest positive normal half

_PREFIX = "thinfilm_sh/"
_VERSION_ATTR = _PREFIX + "format_version"
_KIND_ATTR = _PREFIX + "kind"
_SHAPE_ATTR = _PREFIX + "shape"
_PRECISION_ATTR = _PREFIX + "precision"
_ATTRIBUTES_ATTR = _PREFIX + "attributes"
_HASH_ATTR = _PREFIX + "content_hash"
_CACHE_TAG_ATTR = _PREFIX + "cache_key"

_EXR_MAGIC = b"\x76\x2f\x31\x01"  # OpenEXR magic number 20000630, little-endian
_STORED_DTYPE = {"float": np.dtype("<f4"), "half": np.dtype("<f2")}
_HEX64 = re.compile(r"[0-9a-f]{64}")
_KEY_RE = re.compile(r"[A-Za-z0-9_-]{1,128}")

# Hard limits, checked before anything a file declares is allocated (and by the writer, so that
# everything written can be read back). The largest table the planner can be asked for,
# 512 thicknesses × 512 view angles × 169 SH coefficients (l = 12) × 9, has 3.99e8 values.
#: Most values a table may hold (2**29 ≈ 5.4e8, 2 GiB as float32).
MAX_TABLE_VALUES = 2**29
#: Most channels (entries of a table's last axis) a table file may have.
MAX_CHANNELS = 4096
MAX_DIMS = 8  # axes of a table's shape (tables have 1–4)
MAX_HEADER_BYTES = 4 * 2**20  # an EXR header; a table's attribute JSON is ≤ 200 KB (8192 wavelengths)
_MAX_SHAPE_CHARS = 256  # the shape's JSON: ≤ 8 ints
MAX_HEADER_ATTRIBUTES = 1024  # a table has 14
MAX_JSON_DEPTH = 64  # nesting of a header's JSON; a table's attributes nest 4 deep
MAX_FILE_BYTES = 4 * MAX_TABLE_VALUES + MAX_HEADER_BYTES + 2**24  # pixels + header + chunk table
_MAX_NAME = 256  # an EXR attribute or channel name, with its terminating null byte
# How far each OpenEXR compression can shrink pixel data at most, to refuse a small file declaring a
# huge image before the binding allocates it: none 1; RLE 64 (a 2-byte run codes ≤ 128 bytes);
# zlib/deflate 1032 (RFC 1951: a 258-byte match costs ≥ 2 bits, plus block overhead). Others (PIZ,
# PXR24, B44, DWA, …) have no tight published bound; 4096 is generous for them.
_MAX_COMPRESSION_RATIO = {0: 1, 1: 64, 2: 1032, 3: 1032}
_OTHER_COMPRESSION_RATIO = 4096
# Scanlines per chunk by compression (OpenEXR file layout): NONE RLE ZIPS 1, ZIP PXR24 16,
# PIZ B44 B44A DWAA 32, DWAB 256.
_LINES_PER_CHUNK = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}
_PIXEL_BYTES = {0: 4, 1: 2, 2: 4}  # UINT, HALF, FLOAT
_EXR_TILED, _EXR_DEEP, _EXR_MULTIPART = 0x200, 0x800, 0x1000  # version-field flags

#: Default size limit of a :class:`TableCache` on disk (``THINFILM_SH_CACHE_MAX_BYTES`` overrides it).
DEFAULT_CACHE_MAX_BYTES = 2 * 1024**3
_OUTPUT_MODE = 0o644  # published outputs are ordinary shareable files (mkstemp creates 0600)
_PRIVATE_DIR_MODE = 0o700


class TableError(ValueError):
    """A table file is missing data, unreadable, corrupt, or not the table that was expected."""


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


class CacheDirError(OSError):
    """A :class:`TableCache` directory is unsafe (a symbolic link, someone else's, writable by
    others) or cannot be created; ``str()`` says which and what to do."""

    def __init__(self, path, message: str, code: int | None = None):
        super().__init__(code, message, os.fspath(path))
        self.message = message

    def __str__(self) -> str:
        return self.message


@dataclasses.dataclass(frozen=True, eq=False)
class Table:
    """A table read back by :func:`read_table`.

    ``data`` is a read-only float64 array of the original shape holding exactly the stored
    float32/half values (copy it to modify). ``attributes`` is the caller's metadata as decoded
    from JSON (tuples come back as lists).
    """

    data: np.ndarray
    attributes: dict
    precision: str
    content_hash: str
    format_version: int
    kind: str
    path: str = ""

    @property
    def shape(self) -> tuple[int, ...]:
        return self.data.shape


class HalfError(NamedTuple):
    """Rounding error of storing an array as IEEE half (see :func:`half_precision_error`)."""

    max_abs: float
    max_rel: float


# ----------------------------------------------------------------------------------------------
# Canonical forms and hashes
# ----------------------------------------------------------------------------------------------


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (set, frozenset)):
        raise TypeError("sets have no stable order; pass a sorted list")
    raise TypeError(f"object of type {type(value).__name__} is not JSON-serialisable")


def _canonical_json(value, name: str = "attributes") -> str:
    """Compact, key-sorted JSON with NaN/Inf refused; numpy scalars/arrays become numbers/lists."""
    try:
        return json.dumps(
            value,
            sort_keys=True,
            separators=(",", ":"),
            ensure_ascii=False,
            allow_nan=False,
            default=_json_default,
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be JSON-serialisable with finite numbers: {exc}") from exc


def _normalise_attributes(attributes) -> dict:
    if attributes is None:
        attributes = {}
    if not isinstance(attributes, dict):
        raise ValueError(f"attributes must be a dict, got {type(attributes).__name__}")
    bad = [k for k in attributes if not isinstance(k, str)]
    if bad:
        raise ValueError(f"attributes keys must be strings, got {bad[0]!r}")
    return json.loads(_canonical_json(attributes))


def content_key(attributes) -> str:
    """A short stable key for a bake's *inputs*: sha256 of their canonical JSON, 16 hex digits.

    Key order does not matter; tuples and lists are equivalent, as are numpy scalars and the
    Python numbers they hold. 64 bits make an accidental collision among even a million cached
    bakes improbable (~3e-8), and :meth:`TableCache.load` with ``expect`` guards against it.
    """
    canonical = _canonical_json(_normalise_attributes(attributes))
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()[:16]


def _content_hash(stored: np.ndarray, shape, precision: str, kind: str, attributes: dict) -> str:
    """sha256 over a canonical JSON preamble then the stored values (little-endian, C order)."""
    preamble = _canonical_json(
        {
            "attributes": attributes,
            "format_version": FORMAT_VERSION,
            "kind": kind,
            "precision": precision,
            "shape": list(shape),
        }
    )
    digest = hashlib.sha256()
    digest.update(b"thinfilm_sh table\0")
    digest.update(preamble.encode("utf-8"))
    digest.update(b"\0")
    digest.update(np.ascontiguousarray(stored, dtype=_STORED_DTYPE[precision]).tobytes(order="C"))
    return digest.hexdigest()


# ----------------------------------------------------------------------------------------------
# Precision
# ----------------------------------------------------------------------------------------------


def _check_data(data) -> np.ndarray:
    if np.iscomplexobj(data):
        raise ValueError("data must be real, got a complex array")
    arr = _checks.finite_array("data", data, dtype=np.float64)
    if arr.ndim == 0:
        raise ValueError("data must have at least one axis, got a scalar")
    if 0 in arr.shape:
        raise ValueError(f"data has an empty axis, shape {arr.shape}")
    if arr.ndim > MAX_DIMS or arr.size > MAX_TABLE_VALUES or arr.shape[-1] > MAX_CHANNELS:
        raise ValueError(
            f"data of shape {arr.shape} is beyond what a table file may hold ({MAX_DIMS} axes, "
            f"{MAX_TABLE_VALUES} values, {MAX_CHANNELS} entries on the last axis)"
        )
    return arr


def _to_stored(arr: np.ndarray, precision: str) -> np.ndarray:
    """Round float64 ``arr`` to the stored dtype, refusing values that would overflow to Inf."""
    _checks.choice("precision", precision, PRECISIONS)
    peak = float(np.max(np.abs(arr)))
    if precision == "half" and peak > HALF_MAX:
        raise ValueError(
            f"data has |value| up to {peak:g}, above half's largest finite value {HALF_MAX:g} "
            "(it would become Inf); use precision='float' or rescale"
        )
    with np.errstate(over="ignore"):
        stored = arr.astype(_STORED_DTYPE[precision])
    if not np.all(np.isfinite(stored)):
        raise ValueError(f"data has |value| up to {peak:g}, which would become Inf as {precision}")
    return stored


def half_precision_error(data) -> HalfError:
    """Max absolute and max relative error of storing ``data`` as IEEE half.

    ``max_rel`` is taken over entries in half's normal range (|x| ≥ 2^-14 ≈ 6.1e-5), where
    round-to-nearest bounds it by 2^-11 ≈ 4.9e-4 (10-bit mantissa); smaller entries are
    subnormal or flush to zero with absolute error ≤ 2^-25 ≈ 3e-8, included in ``max_abs``.
    Raises ``ValueError`` for NaN/Inf or for values beyond ±65504.
    """
    arr = _check_data(data)
    stored = _to_stored(arr, "half").astype(np.float64)
    err = np.abs(stored - arr)
    normal = np.abs(arr) >= HALF_MIN_NORMAL
    max_rel = float(np.max(err[normal] / np.abs(arr[normal]))) if np.any(normal) else 0.0
    return HalfError(max_abs=float(np.max(err)), max_rel=max_rel)


# ----------------------------------------------------------------------------------------------
# Layout
# ----------------------------------------------------------------------------------------------


def _layout(shape) -> tuple[int, int, int]:
    """(height, width, channels) of the 2-D image holding an array of ``shape``."""
    channels = shape[-1]
    width = shape[-2] if len(shape) >= 2 else 1
    height = math.prod(shape[:-2]) if len(shape) >= 3 else 1
    return height, width, channels


def _channel_names(count: int) -> list[str]:
    digits = max(2, len(str(count - 1)))
    return [f"c{i:0{digits}d}" for i in range(count)]


# ----------------------------------------------------------------------------------------------
# Writing
# ----------------------------------------------------------------------------------------------


def _replace(src: str, dst: str) -> None:
    """``os.replace`` with a short retry: on Windows it fails while ``dst`` is open elsewhere."""
    for attempt in range(5):
        try:
            os.replace(src, dst)
            return
        except PermissionError:
            if os.name != "nt" or attempt == 4:
                raise
            time.sleep(0.05 * (attempt + 1))


def _file_kind(mode: int) -> str:
    """What a stat mode describes, in words."""
    for test, name in (
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISREG, "a regular file"),
    ):
        if test(mode):
            return name
    return "a special file"


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
            _replace(tmp, os.fspath(path))
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


def write_table(path, data, attributes=None, precision: str = "float", *, kind: str = "sh_table") -> Path:
    """Store an N-D array and its metadata in one OpenEXR file, atomically; returns the path.

    Parameters
    ----------
    path : str or os.PathLike
        Destination. The parent directory must exist. An existing regular file is replaced
        atomically (written to a temporary file beside it, verified, then ``os.replace``), so
        readers and crashes never see a half-written table; anything else there (a symbolic
        link, FIFO, device, directory, hard-linked file) is refused (:func:`check_destination`).
    data : array_like, real, finite, at least 1-D, no empty axis
        Rounded to float32 (``precision="float"``) or IEEE half (``"half"``). At most
        :data:`MAX_TABLE_VALUES` values and :data:`MAX_CHANNELS` entries on the last axis.
    attributes : dict of str → JSON-serialisable, optional
        Metadata (material parameters, SH order, colour space, …). numpy scalars and arrays are
        converted to numbers and lists; NaN/Inf are refused.
    precision : {"float", "half"}
        Half halves the file but rounds with relative error ≤ 2^-11 (see
        :func:`half_precision_error`); |values| above 65504 are refused.
    kind : str
        What the table is, stored in ``thinfilm_sh/kind`` (e.g. ``"sh_table"``).

    Raises
    ------
    ValueError
        Bad ``data``/``attributes``/``precision``/``kind``; raised before anything is written.
    TableWriteError
        The destination was refused, or the file could not be written in full (disk full,
        permission, quota, read-only file system): the file written is read back through
        :func:`read_table` before it replaces anything, so an empty or truncated table is never
        published. The message names ``path``; the previous file is unchanged.
    """
    return _write_table(path, data, attributes, precision, kind, {})


def _write_table(path, data, attributes, precision: str, kind: str, extra_header: dict) -> Path:
    arr = _check_data(data)
    stored = _to_stored(arr, precision)
    attrs = _normalise_attributes(attributes)
    if not isinstance(kind, str) or not kind:
        raise ValueError(f"kind must be a non-empty string, got {kind!r}")
    path = check_destination(path)

    import OpenEXR  # lazy: only needed for file I/O

    height, width, count = _layout(arr.shape)
    image = stored.reshape(height, width, count)
    channels = {name: np.ascontiguousarray(image[:, :, c]) for c, name in enumerate(_channel_names(count))}
    digest = _content_hash(stored, arr.shape, precision, kind, attrs)
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        _VERSION_ATTR: FORMAT_VERSION,
        _KIND_ATTR: kind,
        _SHAPE_ATTR: json.dumps(list(arr.shape)),
        _PRECISION_ATTR: precision,
        _ATTRIBUTES_ATTR: _canonical_json(attrs),
        _HASH_ATTR: digest,
        **extra_header,
    }

    def writer(tmp: str) -> None:
        OpenEXR.File(header, channels).write(tmp)

    def verify(tmp: str) -> None:
        table = _read_table(tmp, None, kind, exact_size=True)
        if table.content_hash != digest or table.shape != arr.shape:
            raise TableError(f"table {tmp!r} reads back as another table")

    return write_file(path, writer, verify=verify)


# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------


def _header_value(header: dict, name: str, kind: type, where: str):
    if name not in header:
        raise TableError(f"{where}: header attribute {name!r} is missing (not a Thin Film SH table?)")
    value = header[name]
    if kind is int and (isinstance(value, bool) or not isinstance(value, (int, np.integer))):
        raise TableError(f"{where}: header attribute {name!r} must be an int, got {type(value).__name__}")
    if kind is str and not isinstance(value, str):
        raise TableError(f"{where}: header attribute {name!r} must be a string, got {type(value).__name__}")
    return value


_JSON_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)  # a JSON string, escapes included
_OPEN_BRACKETS, _CLOSE_BRACKETS = np.frombuffer(b"[{", np.uint8), np.frombuffer(b"]}", np.uint8)


def _json_depth(text: str) -> int:
    """Deepest bracket nesting of JSON ``text``, counted without recursion (strings skipped)."""
    skeleton = np.frombuffer(_JSON_STRING.sub("", text).encode("utf-8", "replace"), np.uint8)
    if skeleton.size == 0:
        return 0
    steps = np.isin(skeleton, _OPEN_BRACKETS).astype(np.int64) - np.isin(skeleton, _CLOSE_BRACKETS)
    return int(max(0, np.cumsum(steps).max()))


def _parse_json(text: str, name: str, where: str, *, limit: int = MAX_HEADER_BYTES):
    if len(text) > limit:
        raise TableError(f"{where}: header attribute {name!r} is longer than {limit} characters: refused")
    depth = _json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise TableError(
            f"{where}: header attribute {name!r} nests {depth} levels deep, more than {MAX_JSON_DEPTH}: "
            "refused (not a Thin Film SH table)"
        )
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise TableError(f"{where}: header attribute {name!r} is not valid JSON: {exc}") from exc


def _short(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[:limit] + "…"


# Open flags for reading untrusted files: never through a symbolic link at the last component, never
# blocking (opening a FIFO with O_NONBLOCK returns at once; fstat then refuses it).
_READ_FLAGS = (
    os.O_RDONLY
    | getattr(os, "O_NOFOLLOW", 0)
    | getattr(os, "O_NONBLOCK", 0)
    | getattr(os, "O_CLOEXEC", 0)
    | getattr(os, "O_BINARY", 0)
)


def _open_regular(path: str, where: str) -> tuple[int, os.stat_result]:
    """An open descriptor of the regular file ``path`` and its fstat; :class:`TableError` for
    anything else (looked at with ``lstat`` first, so a device or FIFO is never even opened)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{where} does not exist") from exc
    except OSError as exc:
        raise TableError(f"{where} cannot be inspected: {exc.strerror or exc}") from exc
    if stat.S_ISLNK(mode):
        raise TableError(f"{where} is a symbolic link: refused (tables are never read through a link)")
    if stat.S_ISDIR(mode):
        raise TableError(f"{where} is a directory, not a table file")
    if not stat.S_ISREG(mode):
        raise TableError(f"{where} is {_file_kind(mode)}, not a regular file: refused")
    try:
        fd = os.open(path, _READ_FLAGS)
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{where} does not exist") from exc
    except OSError as exc:  # ELOOP: replaced by a link since the lstat; EACCES, EIO, …
        raise TableError(f"{where} cannot be opened: {exc.strerror or exc}") from exc
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise TableError(f"{where} is {_file_kind(st.st_mode)}, not a regular file: refused")
    except BaseException as exc:
        os.close(fd)
        if isinstance(exc, OSError):
            raise TableError(f"{where} cannot be inspected: {exc.strerror or exc}") from exc
        raise
    return fd, st


def _pread(fd: int, count: int, offset: int) -> bytes:
    if hasattr(os, "pread"):
        return os.pread(fd, count, offset)
    os.lseek(fd, offset, os.SEEK_SET)  # Windows
    return os.read(fd, count)


def _read_regular(path, where: str, limit: int) -> bytes:
    """All bytes of the regular file ``path``, reading no more than its size (≤ ``limit``)."""
    fd, st = _open_regular(os.fspath(path), where)
    try:
        if st.st_size > limit:
            raise TableError(f"{where} is {st.st_size} bytes, more than a table file may be ({limit})")
        blocks, remaining = [], st.st_size
        while remaining > 0:
            block = os.read(fd, min(remaining, 1 << 24))
            if not block:
                break
            blocks.append(block)
            remaining -= len(block)
    except OSError as exc:
        raise TableError(f"{where} cannot be read: {exc.strerror or exc}") from exc
    finally:
        os.close(fd)
    return b"".join(blocks)


def _cstring(read_at, offset: int, broken) -> tuple[str, int]:
    """A null-terminated EXR name at ``offset`` (≤ 255 bytes) and the offset after it."""
    block = read_at(offset, _MAX_NAME)
    end = block.find(b"\0")
    if end < 0:
        raise broken("the header ends early" if len(block) < _MAX_NAME else "a name is longer than 255 bytes")
    return block[:end].decode("latin-1"), offset + end + 1


def _parse_attributes(read_at, size: int, broken) -> tuple[dict, int]:
    """The EXR header after the 8-byte preamble, as name → (type, value offset, value length),
    and the offset just past it. Values are not read: ``read_at(offset, count)`` is asked for at
    most 256 bytes at a time, so a huge or hostile header costs nothing to walk."""
    found: dict = {}
    offset = 8
    while True:
        name, offset = _cstring(read_at, offset, broken)
        if not name:
            return found, offset
        if len(found) >= MAX_HEADER_ATTRIBUTES:
            raise broken(f"more than {MAX_HEADER_ATTRIBUTES} header attributes")
        type_name, offset = _cstring(read_at, offset, broken)
        head = read_at(offset, 4)
        if len(head) < 4:
            raise broken("the header ends early")
        (length,) = struct.unpack("<i", head)
        offset += 4
        if length < 0 or offset + length > size:
            raise broken(f"header attribute {name!r} runs past the end of the file")
        if offset + length > 8 + MAX_HEADER_BYTES:
            raise broken(f"the header is longer than {MAX_HEADER_BYTES} bytes")
        found[name] = (type_name, offset, length)
        offset += length


def _exr_structure(raw: bytes, where: str) -> int:
    """Check the OpenEXR structure of ``raw`` against the hard limits before anything is decoded;
    returns the offset where its last chunk ends (its size, for a complete file).

    Refuses tiled, deep and multi-part files (a table is a single-part scanline image), more than
    :data:`MAX_CHANNELS` channels, a data window whose pixels would exceed :data:`MAX_TABLE_VALUES`
    float32 values or more than the file could hold at its compression's best ratio, and a chunk
    table or chunk that runs past the end of the file.
    """

    def broken(detail: str) -> TableError:
        return TableError(f"{where} is truncated or not an OpenEXR file ({detail})")

    if len(raw) < 8:
        raise broken("shorter than an OpenEXR preamble")
    (version,) = struct.unpack_from("<i", raw, 4)
    if version & 0xFF != 2:
        raise broken(f"unsupported OpenEXR version {version & 0xFF}")
    if version & (_EXR_TILED | _EXR_DEEP | _EXR_MULTIPART):
        raise TableError(f"{where} is a tiled, deep or multi-part OpenEXR file, which a table never is")
    attributes, offset = _parse_attributes(lambda at, count: raw[at : at + count], len(raw), broken)

    def value(name: str, type_name: str, length: int | None = None) -> bytes:
        if name not in attributes:
            raise broken(f"no {name!r} header attribute")
        found_type, at, count = attributes[name]
        if found_type != type_name or (length is not None and count != length):
            raise broken(f"header attribute {name!r} is a {found_type} of {count} bytes")
        return raw[at : at + count]

    chlist = value("channels", "chlist")
    channels = pixel_bytes = cursor = 0
    while True:
        end = chlist.find(b"\0", cursor)
        if end < 0 or (end > cursor and end + 17 > len(chlist)):
            raise broken("the channel list ends early")
        if end == cursor:
            break
        pixel_type, _linear, x_sampling, y_sampling = struct.unpack_from("<iB3xii", chlist, end + 1)
        if pixel_type not in _PIXEL_BYTES or x_sampling < 1 or y_sampling < 1:
            raise broken(f"channel {chlist[cursor:end]!r} has pixel type {pixel_type}")
        channels += 1
        if channels > MAX_CHANNELS:
            raise TableError(
                f"{where} declares more than {MAX_CHANNELS} channels: refused (a table has at most "
                f"{MAX_CHANNELS})"
            )
        pixel_bytes += _PIXEL_BYTES[pixel_type]
        cursor = end + 17
    (compression,) = value("compression", "compression", 1)
    if compression not in _LINES_PER_CHUNK:
        raise broken(f"unknown compression {compression}")
    x_min, y_min, x_max, y_max = struct.unpack("<4i", value("dataWindow", "box2i", 16))
    width, height = x_max - x_min + 1, y_max - y_min + 1
    if width < 1 or height < 1:
        raise broken(f"empty data window {width}×{height}")
    declared = width * height * pixel_bytes
    ratio = _MAX_COMPRESSION_RATIO.get(compression, _OTHER_COMPRESSION_RATIO)
    if declared > 4 * MAX_TABLE_VALUES or declared > ratio * len(raw):
        raise TableError(
            f"{where} declares {width}×{height} pixels of {channels} channels ({declared} bytes), more "
            f"than a table may hold ({4 * MAX_TABLE_VALUES} bytes) or a file of {len(raw)} bytes can: "
            "refused"
        )
    chunks = -(-height // _LINES_PER_CHUNK[compression])
    table_end = offset + 8 * chunks
    if table_end > len(raw):
        raise broken("the chunk offset table runs past the end of the file")
    starts = np.frombuffer(raw, "<u8", chunks, offset).astype(np.int64)
    if np.any(starts < table_end) or np.any(starts > len(raw) - 8):
        raise broken("a chunk offset points outside the file")
    data = np.frombuffer(raw, np.uint8)
    sizes = data[starts[:, None] + np.arange(4, 8)].copy().view("<i4").ravel().astype(np.int64)
    ends = starts + 8 + sizes
    if np.any(sizes < 0) or np.any(ends > len(raw)):
        raise broken("a chunk runs past the end of the file")
    return int(ends.max())


def _cache_tag(path) -> str | None:
    """The ``thinfilm_sh/cache_key`` tag of the regular file ``path``, or None (absent, not a
    regular file, unreadable). Walks the header with a few small reads, whatever the file's size."""
    try:
        fd, st = _open_regular(os.fspath(path), f"file {os.fspath(path)!r}")
    except (OSError, TableError):
        return None
    try:

        def broken(detail: str) -> TableError:
            return TableError(detail)

        if _pread(fd, 4, 0) != _EXR_MAGIC:
            return None
        attributes, _ = _parse_attributes(lambda at, count: _pread(fd, count, at), st.st_size, broken)
        type_name, at, count = attributes.get(_CACHE_TAG_ATTR, ("", 0, 0))
        if type_name != "string" or not 0 < count <= 128:
            return None
        return _pread(fd, count, at).decode("ascii", "replace")
    except (OSError, TableError):
        return None
    finally:
        os.close(fd)


def verify_exr(path) -> None:
    """Check that ``path`` is a complete single-part scanline OpenEXR file (every chunk present,
    the file ending where its last chunk ends) within the reader's limits; :class:`TableError`
    otherwise. For outputs other than tables, e.g. a render's scene-linear EXR."""
    path = os.fspath(path)
    where = f"file {path!r}"
    raw = _read_regular(path, where, MAX_FILE_BYTES)
    if raw[:4] != _EXR_MAGIC:
        raise TableError(f"{where} is truncated or not an OpenEXR file (bad magic number)")
    end = _exr_structure(raw, where)
    if end != len(raw):
        raise TableError(f"{where} is {len(raw)} bytes but its last chunk ends at byte {end}")


def _same(expected, found) -> bool:
    """Equality after a JSON round trip (tuples = lists, numpy = Python), bools distinct from ints."""
    if isinstance(expected, bool) or isinstance(found, bool):
        return type(expected) is type(found) and expected == found
    if isinstance(expected, (list, tuple)) and isinstance(found, (list, tuple)):
        return len(expected) == len(found) and all(_same(e, f) for e, f in zip(expected, found, strict=True))
    if isinstance(expected, dict) and isinstance(found, dict):
        return expected.keys() == found.keys() and all(_same(expected[k], found[k]) for k in expected)
    return expected == found


def read_table(path, expect: dict | None = None, *, kind: str | None = None) -> Table:
    """Read and fully validate a table written by :func:`write_table`.

    Checks the OpenEXR structure, every ``thinfilm_sh/*`` header attribute and its type, the
    format version, that the channels and pixel size match the stored shape and precision,
    that all values are finite, and that the content hash recomputed from the decoded values
    matches the stored one. ``expect`` maps attribute names to values they must equal
    (compared after a JSON round trip); ``kind``, if given, must equal the stored kind.

    The file is untrusted: only a regular file is opened (a symbolic link, FIFO, device or
    directory is refused without reading it), no more than its size is read, every size it
    declares (channels, data window, chunk table, shape) is checked against the hard limits
    (:data:`MAX_TABLE_VALUES`, :data:`MAX_CHANNELS`, :data:`MAX_FILE_BYTES`) before anything is
    allocated, and header JSON deeper than :data:`MAX_JSON_DEPTH` is refused.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist (the message names it).
    TableError
        Anything else wrong, with a message naming the file and the problem (also for an
        unreadable file: permission, I/O error).
    """
    return _read_table(path, expect, kind)


def _read_table(path, expect: dict | None, kind: str | None, *, exact_size: bool = False) -> Table:
    path = os.fspath(path)
    where = f"table {path!r}"
    raw = _read_regular(path, where, MAX_FILE_BYTES)
    if raw[:4] != _EXR_MAGIC:
        raise TableError(f"{where} is truncated or not an OpenEXR file (bad magic number)")
    end = _exr_structure(raw, where)
    if exact_size and end != len(raw):
        raise TableError(f"{where} is {len(raw)} bytes but its last chunk ends at byte {end}")

    import OpenEXR  # lazy: only needed for file I/O

    try:
        exr = OpenEXR.File(io.BytesIO(raw), separate_channels=True)
        header = exr.header()
        channels = exr.channels()
    except Exception as exc:  # the binding raises RuntimeError / ValueError for damaged files
        raise TableError(f"{where} is truncated or not an OpenEXR file ({exc})") from exc

    version = _header_value(header, _VERSION_ATTR, int, where)
    if int(version) != FORMAT_VERSION:
        raise TableError(
            f"{where}: unsupported format version {int(version)}; this reader supports version "
            f"{FORMAT_VERSION} only (re-bake the table)"
        )
    stored_kind = _header_value(header, _KIND_ATTR, str, where)
    shape_text = _header_value(header, _SHAPE_ATTR, str, where)
    precision = _header_value(header, _PRECISION_ATTR, str, where)
    attrs_text = _header_value(header, _ATTRIBUTES_ATTR, str, where)
    stored_hash = _header_value(header, _HASH_ATTR, str, where)

    shape = _parse_json(shape_text, _SHAPE_ATTR, where, limit=_MAX_SHAPE_CHARS)
    if (
        not isinstance(shape, list)
        or not shape
        or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape)
    ):
        raise TableError(
            f"{where}: header attribute {_SHAPE_ATTR!r} must list positive ints, got {_short(shape_text)!r}"
        )
    if len(shape) > MAX_DIMS or math.prod(shape) > MAX_TABLE_VALUES or shape[-1] > MAX_CHANNELS:
        raise TableError(
            f"{where}: header attribute {_SHAPE_ATTR!r} declares shape {_short(shape_text)}, more than a "
            f"table may hold ({MAX_DIMS} axes, {MAX_TABLE_VALUES} values, {MAX_CHANNELS} channels): refused"
        )
    shape = tuple(shape)
    if precision not in PRECISIONS:
        raise TableError(
            f"{where}: header attribute {_PRECISION_ATTR!r} must be one of {list(PRECISIONS)}, "
            f"got {precision!r}"
        )
    attributes = _parse_json(attrs_text, _ATTRIBUTES_ATTR, where)
    if not isinstance(attributes, dict):
        raise TableError(f"{where}: header attribute {_ATTRIBUTES_ATTR!r} must be a JSON object")
    if not _HEX64.fullmatch(stored_hash):
        raise TableError(f"{where}: header attribute {_HASH_ATTR!r} is not a sha256 hex digest")

    height, width, count = _layout(shape)
    names = _channel_names(count)
    if sorted(channels) != names:
        found = sorted(channels)
        shown = found if len(found) <= 12 else [*found[:12], "…"]
        raise TableError(
            f"{where}: channel names do not match shape {shape}: expected {names[0]}…{names[-1]} "
            f"({count} channels), found {shown} ({len(found)} channels)"
        )
    dtype = _STORED_DTYPE[precision]
    planes = []
    for name in names:
        pixels = channels[name].pixels
        if pixels is None:
            raise TableError(f"{where} is truncated or not an OpenEXR file (channel {name!r} has no pixels)")
        pixels = np.asarray(pixels)
        if pixels.shape != (height, width):
            raise TableError(
                f"{where}: shape mismatch: header shape {shape} needs {height}×{width} pixels "
                f"(height × width), channel {name!r} has {'×'.join(map(str, pixels.shape))}"
            )
        if pixels.dtype.newbyteorder("<") != dtype.newbyteorder("<"):
            raise TableError(
                f"{where}: channel {name!r} holds {pixels.dtype} pixels but the header says precision "
                f"{precision!r} ({dtype})"
            )
        planes.append(pixels.astype(dtype, copy=False))
    stored = np.stack(planes, axis=-1).reshape(shape)

    bad = ~np.isfinite(stored)
    if np.any(bad):
        raise TableError(
            f"{where}: data contains NaN or Inf in {int(bad.sum())} entries: the file is corrupt"
        )
    actual = _content_hash(stored, shape, precision, stored_kind, attributes)
    if actual != stored_hash:
        raise TableError(f"{where}: contents do not match the stored hash: the file is corrupt")

    if kind is not None and stored_kind != kind:
        raise TableError(f"{where}: stale or mismatched table: kind expected {kind!r}, found {stored_kind!r}")
    if expect:
        wanted = json.loads(_canonical_json(dict(expect), "expect"))
        for key in sorted(wanted):
            if key not in attributes or not _same(wanted[key], attributes[key]):
                found = repr(attributes[key]) if key in attributes else "no such attribute"
                raise TableError(
                    f"{where}: stale or mismatched table: attribute {key!r} expected {wanted[key]!r}, "
                    f"found {found}"
                )

    data = stored.astype(np.float64)
    data.flags.writeable = False
    return Table(
        data=data,
        attributes=attributes,
        precision=precision,
        content_hash=stored_hash,
        format_version=int(version),
        kind=stored_kind,
        path=path,
    )


# ----------------------------------------------------------------------------------------------
# Cache
# ----------------------------------------------------------------------------------------------


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
        raise CacheDirError(path, f"{where} is {_file_kind(st.st_mode)}, not a directory", errno.ENOTDIR)
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
            os.makedirs(path.parent, mode=_PRIVATE_DIR_MODE, exist_ok=True)
            with contextlib.suppress(FileExistsError):  # another process may create it first
                os.mkdir(path, _PRIVATE_DIR_MODE)
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
    if created and stat.S_IMODE(st.st_mode) != _PRIVATE_DIR_MODE:
        with contextlib.suppress(OSError):  # a umask that removed owner bits; the mkdir made it ours
            os.chmod(path, _PRIVATE_DIR_MODE)
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
        if not isinstance(key, str) or not _KEY_RE.fullmatch(key):
            raise ValueError(f"key must be 1–128 characters of [A-Za-z0-9_-], got {key!r}")
        return self.tables_dir / f"{key}.exr"

    def _prepare(self, create: bool) -> bool:
        """Check (or create) the directory and the subfolder; False if they do not exist yet."""
        if not _ensure_dir(self.directory, create=create, private=self.private):
            return False
        return _ensure_dir(self.tables_dir, create=create, private=True)

    def load(self, key: str, expect: dict | None = None, *, kind: str | None = None) -> Table | None:
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
            table = read_table(path, expect=expect, kind=kind)
        except FileNotFoundError:  # removed by another process in between
            return None
        except TableError as exc:
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
            _replace(os.fspath(path), os.fspath(aside))  # renames a link or FIFO itself, never its target
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
                    reason = f"{_file_kind(st.st_mode)} with {st.st_nlink} link(s), not a plain file"
                    self._quarantine(path, st, TableError(f"entry {str(path)!r} is {reason}"))
            try:
                written = _write_table(path, data, attributes, precision, kind, {_CACHE_TAG_ATTR: key})
                break
            except TableWriteError as exc:
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
                if key is None or _cache_tag(path) == key:
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
                ours = stat.S_ISREG(st.st_mode) and _cache_tag(entry.path) == entry_match.group(1)
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
