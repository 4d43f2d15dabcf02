"""Untrusted OpenEXR files: opened safely and checked against hard limits before decoding.

A table file (and a render's EXR) is untrusted input. This module opens only regular files
(never through a symbolic link, never blocking on a FIFO), reads at most a file's size, walks
the OpenEXR header and chunk table with its own parser and checks every size the file declares
(:data:`MAX_TABLE_VALUES`, :data:`MAX_CHANNELS`, header bytes and attributes, chunks) before the
OpenEXR binding allocates anything, and limits JSON nesting. Every failure is a
:class:`TableError`. :mod:`.table_io` builds the table format on it. No ``bpy``, no ``OpenEXR``.
"""

from __future__ import annotations

import json
import os
import re
import stat
import struct

import numpy as np

_EXR_MAGIC = b"\x76\x2f\x31\x01"  # OpenEXR magic number 20000630, little-endian
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


class TableError(ValueError):
    """A table file is missing data, unreadable, corrupt, or not the table that was expected."""


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

    channels, pixel_bytes = _channel_list(value("channels", "chlist"), where, broken)
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
    return _chunks_end(raw, offset, -(-height // _LINES_PER_CHUNK[compression]), broken)


def _channel_list(chlist: bytes, where: str, broken) -> tuple[int, int]:
    """Walk an OpenEXR ``chlist`` attribute: (number of channels, bytes per pixel over all of
    them). Refuses an unknown pixel type, a sampling below 1 and more than :data:`MAX_CHANNELS`."""
    channels = pixel_bytes = cursor = 0
    while True:
        end = chlist.find(b"\0", cursor)
        if end < 0 or (end > cursor and end + 17 > len(chlist)):
            raise broken("the channel list ends early")
        if end == cursor:
            return channels, pixel_bytes
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


def _chunks_end(raw: bytes, offset: int, chunks: int, broken) -> int:
    """Check the chunk offset table at ``offset`` (``chunks`` entries) and every chunk it points to
    lie inside ``raw``; returns the offset where the last chunk ends."""
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


def _string_attribute(path, name: str) -> str | None:
    """The string header attribute ``name`` (at most 128 bytes) of the regular OpenEXR file
    ``path``, or None (absent, not a regular file, unreadable). Walks the header with a few small
    reads, whatever the file's size."""
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
        type_name, at, count = attributes.get(name, ("", 0, 0))
        if type_name != "string" or not 0 < count <= 128:
            return None
        return _pread(fd, count, at).decode("ascii", "replace")
    except (OSError, TableError):
        return None
    finally:
        os.close(fd)


def read_exr(path: str, where: str, *, exact_size: bool) -> bytes:
    """The bytes of the OpenEXR file at ``path``, read once and checked before any decoding: a
    regular file within :data:`MAX_FILE_BYTES`, the magic number, every chunk present and, with
    ``exact_size``, nothing after the last one; :class:`TableError` otherwise (``where`` names
    the file in the message)."""
    raw = _read_regular(path, where, MAX_FILE_BYTES)
    if raw[:4] != _EXR_MAGIC:
        raise TableError(f"{where} is truncated or not an OpenEXR file (bad magic number)")
    end = _exr_structure(raw, where)
    if exact_size and end != len(raw):
        raise TableError(f"{where} is {len(raw)} bytes but its last chunk ends at byte {end}")
    return raw


def verify_exr(path) -> None:
    """Check that ``path`` is a complete single-part scanline OpenEXR file (every chunk present,
    the file ending where its last chunk ends) within the reader's limits; :class:`TableError`
    otherwise. For outputs other than tables, e.g. a render's scene-linear EXR."""
    path = os.fspath(path)
    read_exr(path, f"file {path!r}", exact_size=True)
