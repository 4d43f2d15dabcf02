"""The bake helper process: the viewport's table bakes run outside Blender's process (issue 16).

Run as a script by :mod:`.bake_helper`, never imported by the add-on for its code (only for the
framing functions below, which need nothing but the standard library)::

    python bake_process.py PACKAGE_ROOT      # Blender's bundled Python, or the one running bpy

``PACKAGE_ROOT`` is the extension package's folder (the parent of ``precompute/``). The script
imports :mod:`precompute` from it under a private package name (nothing of the add-on, no bpy):
the very :func:`precompute.bakes.bake.bake` and :func:`precompute.colour.film_colour.film_table` the add-on
runs in process, so a table baked here equals the one baked there bit for bit
(tests/viewport/test_bake_helper.py). Its caches (microfacet kernels, quadrature nodes, albedo weights)
stay warm between requests, and while it waits it computes the kernels of the u-degree rungs
next to the last bake's (:func:`warm_neighbours`).

Why a process: a bake is a few hundred numpy calls of 10–500 µs, and between them its thread
needs Python's global lock, which Blender's main thread holds while it draws (every add-on's
draw callback and every Python panel of the interface). On the 2-core machine the soap
bubble's warm bake with its film table took 36 ms on a thread with the main thread idle and
409 ms while it redrew the viewport, 44 and 89 ms here (docs/bake-helper.md): here it runs on
the other core, whatever the interface does.

Protocol: frames of a pickle and its arrays' out-of-band buffers (:func:`send`, :func:`receive`),
between this process and the add-on that started it (private pipes):

- to the parent, once started: ``("ready", pid)``;
- from the parent: ``("bake", id, material_dict, film, grid)``: bake
  ``Material.from_dict(material_dict)``, and its film table when ``film``, and, when ``grid``
  (``{"coeffs": the World's SH, "prefiltered": bool}``) is given and the film reads a radiance
  grid (``policy.table_uses_grid``), its SH grid's texels (``radiance_grid.texels`` of
  ``radiance_grid.build`` under ``policy.windowed_lighting``: what the viewport's worker
  would build); ``("cancel", id)``: stop that bake at its next progress checkpoint;
- to the parent: ``("progress", id, fraction, text)`` (at most every :data:`PROGRESS_EVERY_S`),
  then one of ``("done", id, table_fields, film_fields or None, ms, grid_fields or None)``,
  ``("failed", id, exception_type_name, message)``, ``("cancelled", id)``.

The process exits when its stdin closes (the parent stopped the helper, unregistered, or
died), stopping a running bake at its next checkpoint.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import pickle
import queue
import struct
import sys
import threading
import time
import types

#: Private package name the extension's files are imported under in the helper.
PACKAGE = "_thinfilm_sh_bake_helper"
#: A frame's header: the pickle's length and how many out-of-band buffers follow it.
HEADER = struct.Struct("!QI")
#: A buffer's length prefix.
LENGTH = struct.Struct("!Q")
#: Longest pickle or buffer read (a soap table with its film table is ≈ 0.8 MiB, a radiance
#: grid's texels 9–27 MiB): anything longer is a broken pipe, not ours.
MAX_FRAME = 1 << 30
#: Most out-of-band buffers in one frame (a bake's answer has about ten arrays).
MAX_BUFFERS = 256
#: The helper warms the kernels next to the last bake's (:func:`warm_neighbours`) after this long
#: without a request: the frame that shows the answer (20–80 ms on the 2-core machine's
#: llvmpipe) is drawn first, and a slider drag's next request usually comes within it.
WARM_AFTER_S = 0.25
#: Progress messages are sent at most this often (the header's bar; cancels are checked at
#: every checkpoint).
PROGRESS_EVERY_S = 0.05


class FrameError(OSError):
    """A frame could not be read: the other side closed the pipe mid-frame or wrote garbage."""


def send(stream, message) -> None:
    """Write ``message`` as one frame to the binary ``stream`` and flush it: a pickle (protocol
    5) whose large arrays follow it out of band, written from their own memory (a radiance
    grid's 9–27 MiB are not copied into the pickle, nor out of it by :func:`receive`)."""
    buffers: list = []
    data = pickle.dumps(message, protocol=5, buffer_callback=buffers.append)
    views = [buffer.raw() for buffer in buffers]
    stream.write(HEADER.pack(len(data), len(views)) + data)
    for view in views:
        stream.write(LENGTH.pack(view.nbytes))
        stream.write(view)
    stream.flush()


def _read_into(stream, view: memoryview) -> bool:
    """Fill ``view`` from ``stream``; False when the stream ended before its first byte."""
    done = 0
    while done < view.nbytes:
        got = stream.readinto(view[done:])
        if not got:
            if done == 0:
                return False
            raise FrameError(f"the pipe closed {done} bytes into a {view.nbytes}-byte read")
        done += got
    return True


def _read(stream, size: int, what: str) -> bytearray:
    if size > MAX_FRAME:
        raise FrameError(f"a {what} of {size} bytes: not one of ours")
    data = bytearray(size)
    if size and not _read_into(stream, memoryview(data)):
        raise FrameError(f"the pipe closed before a {what}")
    return data


def receive(stream):
    """The next frame's message from the binary ``stream`` (see :func:`send`), or None at its
    end. Raises :class:`FrameError` for a frame cut short or one that is not ours."""
    head = bytearray(HEADER.size)
    if not _read_into(stream, memoryview(head)):
        return None
    size, count = HEADER.unpack(head)
    if count > MAX_BUFFERS:
        raise FrameError(f"a frame of {count} buffers: not one of ours")
    data = _read(stream, size, "frame")
    buffers = []
    for _ in range(count):
        (length,) = LENGTH.unpack(_read(stream, LENGTH.size, "buffer length"))
        buffers.append(_read(stream, length, "buffer"))
    return pickle.loads(data, buffers=buffers)


def table_fields(result) -> dict:
    """A :class:`precompute.bakes.bake.BakeResult` as plain values (its class differs between this
    process's private package and the add-on's), without its node reflectance."""
    return {
        "data": result.data,
        "material": result.material.to_dict(),
        "sh_order": int(result.sh_order),
        "view_angles_rad": result.view_angles_rad,
        "thicknesses_nm": result.thicknesses_nm,
        "wavelengths_nm": result.wavelengths_nm,
        "u_nodes": int(result.u_nodes),
        "reasons": {str(k): str(v) for k, v in result.reasons.items()},
        "timings_s": {str(k): float(v) for k, v in result.timings_s.items()},
    }


def film_fields(film) -> dict | None:
    """A :class:`precompute.colour.film_colour.FilmTable` as plain values."""
    if film is None:
        return None
    return {f.name: getattr(film, f.name) for f in dataclasses.fields(film)}


def _stub_package(name: str, path: str) -> None:
    """A package ``name`` whose submodules are found in ``path``, its ``__init__`` not run."""
    module = types.ModuleType(name)
    module.__path__ = [path]
    module.__package__ = name
    sys.modules[name] = module


def load_precompute(root: str) -> types.SimpleNamespace:
    """The modules a bake needs, imported from ``root`` without the extension's ``__init__``."""
    _stub_package(PACKAGE, root)
    names = (
        "bakes.bake",
        "bakes.kernel",
        "bakes.planner",
        "colour.film_colour",
        "materials.material",
        "bakes.progress",
        "shading.policy",
        "shading.radiance_grid",
    )
    return types.SimpleNamespace(
        **{name.rpartition(".")[2]: importlib.import_module(f"{PACKAGE}.precompute.{name}") for name in names}
    )


class Cancelled(Exception):
    """The parent cancelled the running bake, or closed the pipe."""


class Interrupted(Exception):
    """A request arrived while the helper warmed a kernel."""


class _Requests:
    """The parent's messages, read on a thread: bakes queued in order, cancels noted at once."""

    def __init__(self, stream):
        self.queue: queue.Queue = queue.Queue()
        self.cancelled: set = set()
        self.closed = False
        self._stream = stream
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        try:
            while (message := receive(self._stream)) is not None:
                if message[0] == "cancel":
                    self.cancelled.add(message[1])
                else:
                    self.queue.put(message)
        except (OSError, pickle.UnpicklingError, EOFError, IndexError, TypeError) as exc:
            print(f"bake helper: unreadable request ({exc}); exiting", file=sys.stderr)
        finally:
            self.closed = True
            self.queue.put(None)

    def stopped(self, ident) -> bool:
        return self.closed or ident in self.cancelled

    def waiting(self) -> bool:
        """Whether a request (or the end) waits to be served."""
        return self.closed or not self.queue.empty()


def grid_fields(modules, material, result, spec: dict | None) -> dict | None:
    """The texels of ``result``'s SH grid under ``spec`` (see the module's docstring), or None
    when no grid was asked for or the film reads none."""
    policy, radiance_grid = modules.policy, modules.radiance_grid
    if spec is None or not policy.table_uses_grid(material, result, bool(spec["prefiltered"])):
        return None
    l_max, roughness = int(result.sh_order), float(material.roughness)
    windowed = policy.windowed_lighting(spec["coeffs"], l_max, roughness)
    rgba, shape = radiance_grid.texels(radiance_grid.build(result, windowed))
    return {"rgba": rgba, "shape": shape}


def bake_request(modules, request, requests: _Requests, out) -> tuple:
    """(the answer, the table or None) to one ``("bake", id, material_dict, film, grid)``
    request (see the module's docstring)."""
    _kind, ident, material_dict, want_film, grid_spec = request
    start = time.perf_counter()
    last = [0.0]

    def progress(fraction, text) -> None:
        if requests.stopped(ident):
            raise Cancelled
        now = time.perf_counter()
        if now - last[0] >= PROGRESS_EVERY_S:
            last[0] = now
            send(out, ("progress", ident, float(fraction), str(text)))

    try:
        material = modules.material.Material.from_dict(material_dict)
        result = modules.bake.bake(material, progress)
        film = grid = None
        with modules.progress.reporting(lambda: progress(1.0, "film table")):
            if want_film:
                film = modules.film_colour.film_table(result)
            grid = grid_fields(modules, material, result, grid_spec)
        ms = 1000.0 * (time.perf_counter() - start)
        return ("done", ident, table_fields(result), film_fields(film), ms, grid), result
    except Cancelled:
        return ("cancelled", ident), None
    except Exception as exc:  # the material's failure, answered: the parent records it
        return ("failed", ident, type(exc).__name__, str(exc)), None
    finally:
        requests.cancelled.discard(ident)


def warm_neighbours(modules, result, requests: _Requests) -> list[int]:
    """While no request waits: the microfacet kernels of the u-degree rungs next to the one
    ``result`` was baked with (the next one up first), so an edit whose film needs one more or
    one fewer node per interval (a thickness past ≈ 1025 nm for the soap preset) finds its
    kernel warm; cold it costs 65–150 ms at order 0 and seconds at l = 12. A request that
    arrives stops the warm-up at the kernel's next checkpoint (nothing half-made is cached).
    Returns the rungs warmed."""
    ladder = list(modules.planner.U_DEGREE_LADDER)
    if result.u_nodes not in ladder:
        return []
    i = ladder.index(result.u_nodes)
    rungs = [ladder[j] for j in (i + 1, i - 1) if 0 <= j < len(ladder)]
    roughness, l_max = float(result.material.roughness), int(result.sh_order)
    views = int(result.view_angles_rad.size)

    def check() -> None:
        if requests.waiting():
            raise Interrupted

    warmed = []
    try:
        with modules.progress.reporting(check):
            for rung in rungs:
                check()
                modules.kernel.microfacet_kernel(roughness, l_max, views, rung)
                if result.material.base_color is not None:
                    modules.kernel.diffuse_kernel(l_max, rung)
                warmed.append(rung)
    except Interrupted:
        pass
    return warmed


def serve(root: str, stdin, stdout) -> None:
    """Answer bake requests from ``stdin`` until it closes (see the module's docstring); once
    idle for :data:`WARM_AFTER_S`, warm the kernels the next edit may need
    (:func:`warm_neighbours`)."""
    modules = load_precompute(root)
    requests = _Requests(stdin)
    send(stdout, ("ready", os.getpid()))
    last = None  # the last bake's table, whose neighbouring kernels are warmed once idle
    while True:
        try:  # the frame that shows an answer is drawn first: warming would compete with it
            request = requests.queue.get(timeout=WARM_AFTER_S) if last is not None else requests.queue.get()
        except queue.Empty:
            warm_neighbours(modules, last, requests)
            last = None
            continue
        if request is None:
            return
        answer, last = bake_request(modules, request, requests, stdout)
        send(stdout, answer)


if __name__ == "__main__":
    # Python put this script's folder (addon/bakes/) first on sys.path: its modules are not ours
    _HERE = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]
    if len(sys.argv) != 2:
        raise SystemExit("usage: bake_process.py PACKAGE_ROOT")
    _out = os.fdopen(os.dup(1), "wb")  # the frames; print() and warnings go to stderr from now on
    os.dup2(2, 1)
    serve(sys.argv[1], sys.stdin.buffer, _out)
