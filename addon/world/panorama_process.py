"""The panorama helper process: World panoramas rendered with Cycles outside Blender's main process.

Run as a script by :mod:`.panorama_helper`, never imported by the add-on for its code (only for
the protocol's constants below, which need nothing but the standard library)::

    blender --background --factory-startup --python panorama_process.py -- PACKAGE_ROOT
    python panorama_process.py PACKAGE_ROOT                 # bpy as a Python module

``PACKAGE_ROOT`` is the extension package's folder (the parent of ``addon/``). The script imports
:func:`.panorama.render_world_panorama` from the add-on's own files under a private package name
without running the add-on's ``__init__`` files (nothing is registered here), so the helper renders
exactly what the add-on renders in process: same camera, resolution, samples and seed.

Protocol, one JSON object per line:

- stdout, once started: ``MARK {"ready": true, "pid": …, "working_space": …}``;
- stdin, one request: ``{"id": n, "blend": path, "world": name, "out": path, "width": w,
  "samples": s}``: the World ``name`` is appended from the .blend ``path`` (written by
  ``bpy.data.libraries.write``), rendered, saved to ``out`` as a float32 ``.npy`` of shape
  (w/2, w, 3), and removed again (with the images and node groups it brought);
- stdout, its answer: ``MARK {"id": n, "ok": true, "ms": …}`` or ``MARK {"id": n, "ok": false,
  "error": "…", "ms": …}``.

Other output on stdout (Blender's and Cycles' progress lines) is not prefixed by :data:`MARK`
and is ignored by the parent. The process exits when its stdin closes: the parent unregistered
the add-on, stopped the helper, or died, so no helper outlives its Blender.
"""

from __future__ import annotations

import importlib
import json
import os
import sys
import time
import types

#: Prefix of the lines of stdout that belong to the protocol.
MARK = "THINFILM_SH_PANORAMA "
#: Private package name the add-on's files are imported under in the helper.
PACKAGE = "_thinfilm_sh_panorama_helper"


def _stub_package(name: str, path: str) -> None:
    """A package ``name`` whose submodules are found in ``path``, its ``__init__`` not run."""
    module = types.ModuleType(name)
    module.__path__ = [path]
    module.__package__ = name
    sys.modules[name] = module


def load_panorama(root: str):
    """The add-on's :mod:`.panorama` module imported from ``root`` (the extension package's
    folder) without running the package's, ``addon``'s or ``addon/world``'s ``__init__``."""
    for folder in ((), ("addon",), ("addon", "world")):  # the packages above panorama.py
        _stub_package(".".join((PACKAGE, *folder)), os.path.join(root, *folder))
    return importlib.import_module(f"{PACKAGE}.addon.world.panorama")


def _drop_appended(bpy, world) -> None:
    """Remove the appended World and everything it brought that is now unused."""
    bpy.data.worlds.remove(world)
    bpy.data.orphans_purge(do_local_ids=True, do_linked_ids=True, do_recursive=True)
    for library in list(bpy.data.libraries):
        bpy.data.libraries.remove(library)


def render_request(bpy, panorama, request: dict):
    """Append the request's World, render its panorama, remove the World again.

    Returns
    -------
    ndarray, shape (width/2, width, 3), float32
        As :func:`.panorama.render_world_panorama` returns it.
    """
    name = request["world"]
    with bpy.data.libraries.load(request["blend"], link=False) as (source, target):
        if name not in source.worlds:
            raise LookupError(f"World {name!r} is not in {request['blend']}")
        target.worlds = [name]
    world = target.worlds[0]
    try:
        return panorama.render_world_panorama(world, int(request["width"]), int(request["samples"]))
    finally:
        _drop_appended(bpy, world)


def _save(path: str, rgb) -> None:
    """Write ``rgb`` to ``path`` (.npy) whole or not at all."""
    import numpy as np  # in the helper only: the protocol constants import with the stdlib alone

    partial = path + ".part"
    with open(partial, "wb") as handle:
        np.save(handle, np.ascontiguousarray(rgb, dtype=np.float32))
    os.replace(partial, path)


def _answer(message: dict) -> None:
    sys.stdout.write(MARK + json.dumps(message) + "\n")
    sys.stdout.flush()


def serve(root: str) -> None:
    """Answer requests from stdin until it closes (see the module's docstring)."""
    import bpy  # in the helper only (≈ 1.5 s): the add-on imports this module for MARK

    panorama = load_panorama(root)
    space = getattr(getattr(bpy.data, "colorspace", None), "working_space", "") or "Linear Rec.709"
    _answer({"ready": True, "pid": os.getpid(), "working_space": space})
    for line in sys.stdin:
        if not line.strip():
            continue
        start = time.perf_counter()
        request = json.loads(line)
        answer = {"id": request.get("id")}
        try:
            _save(request["out"], render_request(bpy, panorama, request))
            answer["ok"] = True
        except Exception as exc:  # the World's failure, answered: the parent decides
            answer.update(ok=False, error=f"{type(exc).__name__}: {exc}")
        answer["ms"] = 1000.0 * (time.perf_counter() - start)
        _answer(answer)


def _root_from_argv(argv: list) -> str:
    """PACKAGE_ROOT: the argument after ``--`` (Blender binary), else the first one."""
    args = argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]
    if not args:
        raise SystemExit("usage: panorama_process.py PACKAGE_ROOT")
    return args[0]


if __name__ == "__main__":
    # Python put this script's folder (addon/world/) first on sys.path: its modules are not ours
    _HERE = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]
    serve(_root_from_argv(sys.argv))
