"""Importing the repository as the extension package, for the tests that run real Blender.

Blender imports an extension by its id; the tests do the same through a symlink named
``thinfilm_sh`` in a temporary folder, so the add-on's relative imports resolve as installed.
"""

import contextlib
import importlib
import os
import sys
from pathlib import Path

EXTENSION_ID = "thinfilm_sh"
REPO = Path(__file__).resolve().parent.parent


@contextlib.contextmanager
def linked_extension(root: Path, *, unregister: bool = True):
    """Yield the package imported from ``root/thinfilm_sh`` → the repository; on exit unregister it
    (``register``/``unregister`` are safe to repeat) and forget every module of it."""
    os.symlink(REPO, root / EXTENSION_ID, target_is_directory=True)
    sys.path.insert(0, str(root))
    package = None
    try:
        package = importlib.import_module(EXTENSION_ID)
        assert Path(package.__file__).resolve() == REPO / "__init__.py"
        yield package
    finally:
        if unregister and package is not None:
            package.unregister()
        sys.path.remove(str(root))
        for name in [n for n in sys.modules if n == EXTENSION_ID or n.startswith(EXTENSION_ID + ".")]:
            del sys.modules[name]


#: The add-on's GPU layer, module by module (addon/gpu/).
GPU_MODULES = ("context", "layout", "shaders", "resources", "mesh", "draw")
#: The reference rotation of the shading library: generic loops, compiled by tests only.
REFERENCE_ROTATION = REPO / "tests" / "glsl" / "tf_sh_rotate_loops.glsl"


def gpu_layer():
    """``thinfilm_sh.addon.gpu`` with its modules imported (``gpu_layer().draw.draw_items``);
    call inside :func:`linked_extension`."""
    for name in GPU_MODULES:
        importlib.import_module(f"{EXTENSION_ID}.addon.gpu.{name}")
    return importlib.import_module(f"{EXTENSION_ID}.addon.gpu")


def set_cache_preference(bpy, prefs, cache_dir) -> None:
    """Point the registered extension's Cache Directory preference at ``cache_dir`` (adding the
    add-on's preferences entry when Blender has none, as in a module-only session)."""
    addons = bpy.context.preferences.addons
    if addons.get(EXTENSION_ID) is None:
        addons.new().module = EXTENSION_ID
    prefs.preferences().cache_dir = str(cache_dir)


def empty_file(bpy, ns, size):
    """An empty factory file with the extension ``ns`` (:func:`registered_extension`, with its
    ``prefs``) registered again and its private cache chosen; the scene's resolution ``size``
    (width, height) at 100 %. Returns the scene."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    ns.package.register()
    set_cache_preference(bpy, ns.prefs, ns.cache_dir)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    return scene


@contextlib.contextmanager
def registered_extension(bpy, root: Path, modules, *, cache_preference: bool = True, gpu: bool = False):
    """The extension imported from ``root`` and registered, as a namespace: ``package``,
    ``cache_dir`` (``root/cache`` as a string, what the Cache Directory preference holds) and each
    of ``modules`` ("addon.headless.headless", "precompute.bakes.bake", …) under its last name.
    ``cache_preference``: the Cache Directory preference set to ``cache_dir``, else only the
    add-on's preferences entry made; ``gpu``: a GPU context ensured and ``gpu`` the GPU layer
    (:func:`gpu_layer`). On exit the preferences entry is removed and the package forgotten."""
    import types

    with linked_extension(root) as package:
        addons = bpy.context.preferences.addons
        try:
            package.register()
            ns = types.SimpleNamespace(package=package, cache_dir=str(root / "cache"))
            for dotted in modules:
                setattr(ns, dotted.rpartition(".")[2], importlib.import_module(f"{EXTENSION_ID}.{dotted}"))
            if cache_preference:
                prefs = importlib.import_module(f"{EXTENSION_ID}.addon.ui.prefs")
                set_cache_preference(bpy, prefs, ns.cache_dir)
            elif addons.get(EXTENSION_ID) is None:
                addons.new().module = EXTENSION_ID
            if gpu:
                ns.gpu = gpu_layer()
                ns.gpu.context.ensure_gpu_context()
            yield ns
        finally:
            entry = addons.get(EXTENSION_ID)
            if entry is not None:
                addons.remove(entry)


def assert_helper_ends_with_stdin_and_unregister(package, helper, timeout: float) -> None:
    """A helper process module (``addon.world.panorama_helper``, ``addon.bakes.bake_helper``): its process
    exits on its own when its stdin closes (what its parent's death does), and the package's
    ``unregister`` leaves no process behind (exited and reaped: no orphan, no zombie)."""
    name = helper.__name__.rpartition(".")[2]
    helper.warm()
    process = helper.SLOT.process
    assert process.ready.wait(timeout), f"the {name} process did not say it was ready in {timeout:.0f} s"
    assert process.alive(), f"the {name} process died after starting"
    process.proc.stdin.close()
    code = process.proc.wait(timeout)
    assert code == 0, f"the {name} process exited {code} when its stdin closed (its parent died): must be 0"
    helper.stop()

    helper.warm()
    pid = helper.process_id()
    assert pid is not None, f"warm() started no {name} process"
    assert helper.SLOT.process.ready.wait(timeout), (
        f"the second {name} process was not ready in {timeout:.0f} s"
    )
    package.unregister()
    try:
        assert helper.process_id() is None, f"unregister left the {name} process in its slot"
        assert not os.path.exists(f"/proc/{pid}"), (
            f"unregister left the {name} process {pid} (orphan or zombie)"
        )
    finally:
        package.register()
