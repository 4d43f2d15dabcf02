"""Self-describing baked tables in OpenEXR and a validating reader.

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
``thinfilm_sh/cache_key``       str, only in the cache's entries (:mod:`.table_cache`): the entry's
                                key, the tag that tells its own files from others

The hash covers the *stored* values (after rounding to float32/half, little-endian, C order),
the shape, precision, kind, format version and the canonical JSON of the attributes, so the
reader recomputes it from what it decoded and any flipped pixel or edited header is refused.

Files are untrusted input: :func:`read_table` opens and checks them with :mod:`._untrusted_exr`
(regular files only, every declared size within hard limits before anything is allocated, JSON
nesting limited); every failure is a :class:`TableError`.

:func:`write_table` writes through :func:`.atomic_write.write_file`: a temporary file beside the
destination, flushed and verified (not empty, reads back through the validating reader, ends
where its structure says), and only then renamed over the destination; every failure is a
:class:`.atomic_write.TableWriteError` naming the path, with the previous file left as it was.
The content-keyed cache of tables is :mod:`.table_cache` (``docs/cache.md`` for users).

``OpenEXR`` is imported lazily, so :func:`content_key` and :func:`half_precision_error` work
without it. This module never imports ``bpy``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import logging
import math
import os
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import _checks
from ._untrusted_exr import (
    _MAX_SHAPE_CHARS,
    MAX_CHANNELS,
    MAX_DIMS,
    MAX_TABLE_VALUES,
    TableError,
    _parse_json,
    _short,
    read_exr,
    verify_exr,
)
from .atomic_write import check_destination, write_file

__all__ = [
    "FORMAT_VERSION",
    "MAX_CHANNELS",
    "MAX_TABLE_VALUES",
    "HalfError",
    "Table",
    "TableError",
    "content_key",
    "half_precision_error",
    "read_table",
    "verify_exr",
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

_STORED_DTYPE = {"float": np.dtype("<f4"), "half": np.dtype("<f2")}
_HEX64 = re.compile(r"[0-9a-f]{64}")
_KEY_RE = re.compile(r"[A-Za-z0-9_-]{1,128}")


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
        """Shape of the table array."""
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


def write_table(path, data, attributes=None, precision: str = "float", *, kind: str = "sh_table") -> Path:
    """Store an N-D array and its metadata in one OpenEXR file, atomically; returns the path.

    Parameters
    ----------
    path : str or os.PathLike
        Destination. The parent directory must exist. An existing regular file is replaced
        atomically (written to a temporary file beside it, verified, then ``os.replace``), so
        readers and crashes never see a half-written table; anything else there (a symbolic
        link, FIFO, device, directory, hard-linked file) is refused (:func:`.atomic_write.check_destination`).
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
    raw = read_exr(path, where, exact_size=exact_size)

    import OpenEXR  # lazy: only needed for file I/O

    try:
        exr = OpenEXR.File(io.BytesIO(raw), separate_channels=True)
        header = exr.header()
        channels = exr.channels()
    except Exception as exc:  # the binding raises RuntimeError / ValueError for damaged files
        raise TableError(f"{where} is truncated or not an OpenEXR file ({exc})") from exc

    version, stored_kind, shape, precision, attributes, stored_hash = _table_header(header, where)
    stored = _table_planes(channels, shape, precision, where)
    bad = ~np.isfinite(stored)
    if np.any(bad):
        raise TableError(
            f"{where}: data contains NaN or Inf in {int(bad.sum())} entries: the file is corrupt"
        )
    actual = _content_hash(stored, shape, precision, stored_kind, attributes)
    if actual != stored_hash:
        raise TableError(f"{where}: contents do not match the stored hash: the file is corrupt")
    _check_expected(where, stored_kind, attributes, kind, expect)

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


def _table_header(header: dict, where: str) -> tuple:
    """The ``thinfilm_sh/*`` header attributes, each checked: (format version, kind, shape,
    precision, attributes, content hash). Refuses another format version, a shape beyond the
    limits, an unknown precision, attributes that are not a JSON object and a malformed hash."""
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

    return int(version), stored_kind, tuple(shape), precision, attributes, stored_hash


def _table_planes(channels: dict, shape: tuple, precision: str, where: str) -> np.ndarray:
    """The stored array (at its stored precision) from the decoded channels, each checked against
    the header's shape and precision."""
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
    return np.stack(planes, axis=-1).reshape(shape)


def _check_expected(where: str, stored_kind: str, attributes: dict, kind, expect) -> None:
    """Refuse a stale or mismatched table: another kind, or an attribute unlike ``expect``'s."""
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
