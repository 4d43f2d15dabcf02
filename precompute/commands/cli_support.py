"""What both command lines share: exit codes, checks done before any work, one top-level handler.

``python -m precompute`` (:mod:`precompute.commands.cli`) and the headless Blender commands
(``addon/headless/headless.py``) both use it, so they refuse the same bad input with the same words and
exit with the same codes (docs/cli-exit-codes.md):

====  ================  =====================================================================
code  name              meaning
====  ================  =====================================================================
0     EXIT_OK           everything asked for was done
1     EXIT_PARTIAL      done, but something could not be evaluated and was replaced by its
                        documented fallback (a material drawn magenta, a World lit by the
                        fallback colour, non-finite pixels written as 0); each is reported
2     EXIT_REFUSED      refused before any work: a bad option, path, size or value; nothing written
3     EXIT_INTERNAL     an internal error (a bug): one line on stderr, the traceback in a log file
4     EXIT_IO           an output could not be written (or an input read) during the work: disk
                        full, permissions, a file that vanished; the message names the path
130   EXIT_INTERRUPTED  interrupted (Ctrl-C)
====  ================  =====================================================================

Checks before work (each raises :class:`UsageError` naming the option): :func:`image_size`
(1–16384 pixels), :func:`exposure` (finite, |stops| ≤ 64), :func:`output_file` and
:func:`output_dir` (not a directory/device/FIFO/link where a file goes, a folder we can write
in). :func:`unique_file_names` gives each material its own file name. :func:`run` is the one
top-level handler.

Pure Python; never imports ``bpy``.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import sys
import tempfile
import time
import traceback
from pathlib import Path

from ..tables import atomic_write

__all__ = [
    "ArgumentParser",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_IO",
    "EXIT_OK",
    "EXIT_PARTIAL",
    "EXIT_REFUSED",
    "MAX_EXPOSURE",
    "MAX_IMAGE_SIZE",
    "MAX_SUPERSAMPLE",
    "UsageError",
    "exposure",
    "exposure_arg",
    "file_stem",
    "image_size",
    "image_size_arg",
    "output_dir",
    "output_file",
    "refusing",
    "run",
    "supersample",
    "supersample_arg",
    "unique_file_names",
]

EXIT_OK = 0
EXIT_PARTIAL = 1
EXIT_REFUSED = 2
EXIT_INTERNAL = 3
EXIT_IO = 4
EXIT_INTERRUPTED = 130

#: Largest image side in pixels: 16384² RGBA float32 is 4 GiB, the most a render should ask of a
#: GPU; Blender's own resolution limit (65536 × 327 %) would be 10⁵ GiB.
MAX_IMAGE_SIZE = 16384
#: Largest |exposure| in stops: 2^64 ≈ 1.8e19 already maps every non-zero pixel to white or
#: black; Blender's own Exposure slider stops at ±32. 2^1024 overflows a float.
MAX_EXPOSURE = 64.0
#: Most samples per pixel along each axis of a headless frame: 16² = 256 per pixel is past
#: what anti-aliasing gains (4² already matches Cycles' filter to ≈ 0.1 ΔE2000), and the
#: enlarged buffer is capped by the GPU's texture size anyway.
MAX_SUPERSAMPLE = 16


class UsageError(ValueError):
    """Input refused before any work started; ``str()`` names the option or value."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser, refusing bad arguments in one line (not the whole usage) with exit 2."""

    def error(self, message: str):
        """Refuse a bad command line with exit code 2 (argparse's own exit is also 2)."""
        self.exit(EXIT_REFUSED, f"{self.prog}: error: {message} (see --help)\n")


# ----------------------------------------------------------------------------------------------
# Numbers
# ----------------------------------------------------------------------------------------------
def image_size(option: str, value) -> int:
    """``value`` as an image side in 1…:data:`MAX_IMAGE_SIZE` pixels, else UsageError."""
    if isinstance(value, bool):
        raise UsageError(f"{option} must be a whole number of pixels, got {value!r}")
    if not isinstance(value, int):
        try:
            as_float = float(value)
        except (TypeError, ValueError):
            raise UsageError(f"{option} must be a whole number of pixels, got {value!r}") from None
        if not (math.isfinite(as_float) and as_float == int(as_float)):
            raise UsageError(f"{option} must be a whole number of pixels, got {value!r}")
        value = int(as_float)
    if not 1 <= value <= MAX_IMAGE_SIZE:
        raise UsageError(f"{option} must be 1–{MAX_IMAGE_SIZE} pixels, got {value}")
    return value


def exposure(option: str, value) -> float:
    """``value`` as an exposure in stops, finite with |value| ≤ :data:`MAX_EXPOSURE`."""
    try:
        stops = float(value)
    except (TypeError, ValueError, OverflowError):
        raise UsageError(f"{option} must be a number of stops, got {value!r}") from None
    if not math.isfinite(stops) or abs(stops) > MAX_EXPOSURE:
        raise UsageError(f"{option} must be finite and within ±{MAX_EXPOSURE:g} stops, got {value!r}")
    return stops


def supersample(option: str, value) -> int:
    """``value`` as samples per pixel along each axis, a whole number in 1…:data:`MAX_SUPERSAMPLE`."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise UsageError(f"{option} must be a whole number, got {value!r}")
    if not 1 <= value <= MAX_SUPERSAMPLE:
        raise UsageError(f"{option} must be 1–{MAX_SUPERSAMPLE}, got {value}")
    return value


def _argparse_type(check, option: str, convert):
    def parse(text: str):
        try:
            return check(option, convert(text))
        except (TypeError, ValueError, OverflowError) as exc:
            message = str(exc) if isinstance(exc, UsageError) else f"invalid value {text!r}"
            raise argparse.ArgumentTypeError(message.removeprefix(f"{option} ")) from None

    parse.__name__ = check.__name__  # argparse names the type in its messages
    return parse


def image_size_arg(option: str):
    """An argparse ``type=`` for an image side (argparse then names the option and exits 2)."""
    return _argparse_type(image_size, option, int)


def supersample_arg(option: str):
    """An argparse ``type=`` for samples per pixel along each axis."""
    return _argparse_type(supersample, option, int)


def exposure_arg(option: str):
    """An argparse ``type=`` for an exposure in stops."""
    return _argparse_type(exposure, option, float)


# ----------------------------------------------------------------------------------------------
# Paths
# ----------------------------------------------------------------------------------------------
def _existing_ancestor(path: Path) -> Path:
    for parent in (path, *path.parents):
        if os.path.lexists(parent):
            return parent
    return Path(".")


def _check_folder(option: str, folder: Path) -> None:
    """UsageError unless files can be created in ``folder`` (or, if it does not exist yet, in its
    nearest existing ancestor, where it will be created). Probed by creating and removing a
    temporary file, which is right for read-only file systems and for root too."""
    base = _existing_ancestor(folder)
    if not base.is_dir():
        raise UsageError(f"{option}: {str(base)!r} is not a folder, so {str(folder)!r} cannot be created")
    try:
        fd, probe = tempfile.mkstemp(dir=base, prefix=".thinfilm_sh-probe-")
    except OSError as exc:
        raise UsageError(f"{option}: cannot write in {str(base)!r}: {exc.strerror or exc}") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)


def output_file(option: str, path) -> Path:
    """``path`` as a Path if a file may be written there, else UsageError naming ``option``.

    Refused: an empty path, a path ending in a separator, a directory, a symbolic link, FIFO,
    device, socket or multiply linked file (:func:`table_io.check_destination`), and a folder
    that cannot be written in. A missing folder is fine if it can be created.
    """
    text = os.fspath(path) if path is not None else ""
    if not text or not str(text).strip():
        raise UsageError(f"{option} needs a file path")
    if str(text).endswith(("/", os.sep)):
        raise UsageError(f"{option} {str(text)!r} names a folder; give a file path")
    target = Path(text)
    if target.is_dir() and not target.is_symlink():
        raise UsageError(f"{option} {str(target)!r} is a directory; give a file path inside it")
    _check_folder(option, target.parent)
    try:
        atomic_write.check_destination(target)
    except atomic_write.TableWriteError as exc:
        raise UsageError(f"{option}: {exc}") from None
    return target


def output_dir(option: str, path) -> Path:
    """``path`` as a Path if files may be written into it (it exists as a real folder, or can be
    created), else UsageError naming ``option``."""
    text = os.fspath(path) if path is not None else ""
    if not text or not str(text).strip():
        raise UsageError(f"{option} needs a folder path")
    folder = Path(text)
    if os.path.lexists(folder):
        if folder.is_symlink():
            raise UsageError(f"{option} {str(folder)!r} is a symbolic link; give the folder itself")
        if not folder.is_dir():
            raise UsageError(f"{option} {str(folder)!r} exists and is not a folder")
    _check_folder(option, folder)
    return folder


# ----------------------------------------------------------------------------------------------
# File names
# ----------------------------------------------------------------------------------------------
_UNSAFE = re.compile(r"[^A-Za-z0-9_-]")
#: Names Windows reserves in every folder, whatever the extension.
_RESERVED = {"CON", "PRN", "AUX", "NUL"} | {f"{p}{i}" for p in ("COM", "LPT") for i in range(1, 10)}
_MAX_STEM = 100


def file_stem(name: str) -> str:
    """A portable file name stem for ``name``: ASCII letters, digits, ``_`` and ``-``; every other
    character becomes ``_`` (as Blender's ``bpy.path.clean_name`` does for punctuation)."""
    stem = _UNSAFE.sub("_", str(name))[:_MAX_STEM] or "material"
    return stem + "_" if stem.upper() in _RESERVED else stem


def unique_file_names(names, suffix: str = ".exr") -> dict[str, str]:
    """{name: file name} with a different file for every name, in a stable order.

    Names whose :func:`file_stem` is the name itself keep it (``Mat_001`` → ``Mat_001.exr``);
    the others, in sorted order, get the stem or, when it is taken, ``stem-2``, ``stem-3``, …
    (``Mat 001`` → ``Mat_001-2.exr``, ``Mat.001`` → ``Mat_001-3.exr``). Names are compared
    ignoring case, as macOS and Windows file systems do.
    """
    ordered = sorted(set(names))
    taken: set[str] = set()
    out: dict[str, str] = {}
    for name in ordered:
        if file_stem(name) == name and name.casefold() not in taken:
            out[name] = name + suffix
            taken.add(name.casefold())
    for name in ordered:
        if name in out:
            continue
        stem = file_stem(name)
        candidate, i = stem, 1
        while candidate.casefold() in taken:
            i += 1
            candidate = f"{stem}-{i}"
        out[name] = candidate + suffix
        taken.add(candidate.casefold())
    return {name: out[name] for name in ordered}


# ----------------------------------------------------------------------------------------------
# The top-level handler
# ----------------------------------------------------------------------------------------------
@contextlib.contextmanager
def refusing():
    """Inside, ValueError and OSError mean the input was refused before any work: they become
    :class:`UsageError` (exit 2) with the same message."""
    try:
        yield
    except UsageError:
        raise
    except (ValueError, OSError) as exc:
        raise UsageError(_one_line(exc)) from exc


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    return " ".join(text.split())


def write_log(prog: str, exc: BaseException) -> Path | None:
    """The traceback of ``exc`` in a new private file (mode 0600) in the temporary folder; its path,
    or None if even that could not be written."""
    try:
        fd, path = tempfile.mkstemp(prefix=f"{prog}-error-", suffix=".log")
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(f"{prog}: internal error at {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
            handle.write(f"argv: {sys.argv!r}\n\n")
            handle.write("".join(traceback.format_exception(exc)))
        return Path(path)
    except OSError:
        return None


def run(body, *, prog: str, stream=None) -> int:
    """Call ``body()`` and return its exit code; every exception becomes one line on ``stream``
    (stderr) and an exit code: UsageError 2, OSError 4, KeyboardInterrupt 130, anything else 3
    with the traceback written to a log file whose path the line gives. ``SystemExit`` (argparse
    after printing its own message, ``--help``) returns its code."""
    stream = sys.stderr if stream is None else stream
    try:
        return int(body())
    except SystemExit as exc:
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else EXIT_REFUSED)
    except UsageError as exc:
        print(f"{prog}: error: {_one_line(exc)}", file=stream)
        return EXIT_REFUSED
    except OSError as exc:
        print(f"{prog}: error: {_one_line(exc)}", file=stream)
        return EXIT_IO
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=stream)
        return EXIT_INTERRUPTED
    except Exception as exc:  # the one place that catches everything: a bug, reported once
        log = write_log(prog, exc)
        where = f"details in {log}" if log is not None else "no log could be written"
        print(f"{prog}: internal error: {type(exc).__name__}: {_one_line(exc)} ({where})", file=stream)
        return EXIT_INTERNAL
