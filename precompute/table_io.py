"""Self-describing baked tables in OpenEXR, a validating reader and a content-keyed cache.

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

The hash covers the *stored* values (after rounding to float32/half, little-endian, C order),
the shape, precision, kind, format version and the canonical JSON of the attributes, so the
reader recomputes it from what it decoded and any flipped pixel or edited header is refused.

``OpenEXR`` is imported lazily, so :func:`content_key` and :func:`half_precision_error` work
without it. This module never imports ``bpy``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import logging
import math
import os
import re
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from . import _checks

__all__ = [
    "FORMAT_VERSION",
    "HalfError",
    "Table",
    "TableCache",
    "TableError",
    "content_key",
    "default_cache_dir",
    "half_precision_error",
    "read_table",
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

_EXR_MAGIC = b"\x76\x2f\x31\x01"  # OpenEXR magic number 20000630, little-endian
_STORED_DTYPE = {"float": np.dtype("<f4"), "half": np.dtype("<f2")}
_HEX64 = re.compile(r"[0-9a-f]{64}")
_KEY_RE = re.compile(r"[A-Za-z0-9_-]{1,128}")


class TableError(ValueError):
    """A table file is missing data, unreadable, corrupt, or not the table that was expected."""


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


def write_table(path, data, attributes=None, precision: str = "float", *, kind: str = "sh_table") -> Path:
    """Store an N-D array and its metadata in one OpenEXR file, atomically; returns the path.

    Parameters
    ----------
    path : str or os.PathLike
        Destination. The parent directory must exist. An existing file is replaced atomically
        (written to a temporary file beside it, then ``os.replace``), so readers and crashes
        never see a half-written table.
    data : array_like, real, finite, at least 1-D, no empty axis
        Rounded to float32 (``precision="float"``) or IEEE half (``"half"``).
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
    """
    arr = _check_data(data)
    stored = _to_stored(arr, precision)
    attrs = _normalise_attributes(attributes)
    if not isinstance(kind, str) or not kind:
        raise ValueError(f"kind must be a non-empty string, got {kind!r}")
    path = Path(os.fspath(path))
    if path.is_dir():
        raise ValueError(f"path {str(path)!r} is a directory")

    import OpenEXR  # lazy: only needed for file I/O

    height, width, count = _layout(arr.shape)
    image = stored.reshape(height, width, count)
    channels = {name: np.ascontiguousarray(image[:, :, c]) for c, name in enumerate(_channel_names(count))}
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        _VERSION_ATTR: FORMAT_VERSION,
        _KIND_ATTR: kind,
        _SHAPE_ATTR: json.dumps(list(arr.shape)),
        _PRECISION_ATTR: precision,
        _ATTRIBUTES_ATTR: _canonical_json(attrs),
        _HASH_ATTR: _content_hash(stored, arr.shape, precision, kind, attrs),
    }

    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        OpenEXR.File(header, channels).write(tmp)
        with open(tmp, "rb+") as handle:  # flush to disk before the rename makes it visible
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; tables are ordinary shareable files
        _replace(tmp, os.fspath(path))
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path


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


def _parse_json(text: str, name: str, where: str):
    try:
        return json.loads(text)
    except ValueError as exc:
        raise TableError(f"{where}: header attribute {name!r} is not valid JSON: {exc}") from exc


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

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist (the message names it).
    TableError
        Anything else wrong, with a message naming the file and the problem.
    """
    path = os.fspath(path)
    where = f"table {path!r}"
    try:
        with open(path, "rb") as handle:
            raw = handle.read()
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{where} does not exist") from exc
    except IsADirectoryError as exc:
        raise TableError(f"{where} is a directory, not a table file") from exc
    if raw[:4] != _EXR_MAGIC:
        raise TableError(f"{where} is truncated or not an OpenEXR file (bad magic number)")

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

    shape = _parse_json(shape_text, _SHAPE_ATTR, where)
    if (
        not isinstance(shape, list)
        or not shape
        or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape)
    ):
        raise TableError(
            f"{where}: header attribute {_SHAPE_ATTR!r} must list positive ints, got {shape_text!r}"
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
    """``$THINFILM_SH_CACHE`` if set, else ``$XDG_CACHE_HOME/thinfilm_sh``, else ``~/.cache/thinfilm_sh``.

    A relative ``XDG_CACHE_HOME`` is ignored, as the XDG spec requires. Nothing is created.
    """
    override = os.environ.get("THINFILM_SH_CACHE")
    if override:
        return Path(override).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and os.path.isabs(xdg):
        return Path(xdg) / "thinfilm_sh"
    return Path.home() / ".cache" / "thinfilm_sh"


class TableCache:
    """Baked tables on disk, keyed by :func:`content_key` of the bake's inputs.

    Entries are ``<directory>/<key>.exr``. Writes are atomic (temporary file + ``os.replace``),
    so concurrent writers of the same key are safe: the last rename wins and every reader sees
    one complete file. An entry that fails validation is moved aside to ``<key>.exr.corrupt``
    and reported as a miss, so a corrupt table is never used. The directory is created on the
    first :meth:`store`.
    """

    def __init__(self, directory=None):
        self.directory = Path(os.fspath(directory)) if directory is not None else default_cache_dir()

    def __repr__(self) -> str:
        return f"TableCache({str(self.directory)!r})"

    def path_for(self, key: str) -> Path:
        """Path of the entry for ``key`` (letters, digits, ``_`` and ``-`` only)."""
        if not isinstance(key, str) or not _KEY_RE.fullmatch(key):
            raise ValueError(f"key must be 1–128 characters of [A-Za-z0-9_-], got {key!r}")
        return self.directory / f"{key}.exr"

    def load(self, key: str, expect: dict | None = None, *, kind: str | None = None) -> Table | None:
        """The cached table for ``key``, or None if absent or invalid (then moved aside, logged)."""
        path = self.path_for(key)
        try:
            before = os.stat(path)
        except FileNotFoundError:
            return None
        try:
            return read_table(path, expect=expect, kind=kind)
        except FileNotFoundError:  # removed by another process in between
            return None
        except TableError as exc:
            self._quarantine(path, before, exc)
            return None

    def _quarantine(self, path: Path, before: os.stat_result, exc: Exception) -> None:
        try:
            after = os.stat(path)
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
            _replace(os.fspath(path), os.fspath(aside))
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
        """Write ``data`` as the entry for ``key`` (atomically) and return its path."""
        path = self.path_for(key)
        self.directory.mkdir(parents=True, exist_ok=True)
        return write_table(path, data, attributes, precision, kind=kind)

    def clear(self, *, stale_temp_seconds: float = 3600.0) -> int:
        """Delete every entry and moved-aside entry; returns how many files were removed.

        Only this cache's own files are touched (``*.exr``, ``*.exr.corrupt`` and temporary
        files older than ``stale_temp_seconds``, which a crashed writer left behind; younger ones
        may belong to a writer still running). The directory itself is kept.
        """
        if not self.directory.is_dir():
            return 0
        removed = 0
        now = time.time()
        for entry in self.directory.iterdir():
            name = entry.name
            ours = not name.startswith(".") and (name.endswith(".exr") or name.endswith(".exr.corrupt"))
            if name.startswith(".") and name.endswith(".tmp") and ".exr." in name:
                with contextlib.suppress(OSError):
                    ours = now - entry.stat().st_mtime > stale_temp_seconds
            if ours and entry.is_file():
                with contextlib.suppress(FileNotFoundError):
                    entry.unlink()
                    removed += 1
        return removed
