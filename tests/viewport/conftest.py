"""Fixtures of the viewport tests: the extension registered once per file, an empty scene per test.

test_live.py defines its own ``tf``/``scene`` (a start-up file with a 3D viewport, other
modules); the plain helpers (``film``, ``grid``, ``collect``, ``redraw``) are those of
test_viewport_state.py, which the other files here import from it.
"""

import importlib
import types

import pytest
from _extension import EXTENSION_ID, gpu_layer, linked_extension


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    root = tmp_path_factory.mktemp("extension")
    with linked_extension(root) as package:
        package.register()
        ns = types.SimpleNamespace(package=package, cache_dir=str(root / "cache"))
        for name in (
            "scene_draw",
            "props",
            "prefs",
            "tables",
            "thickness",
            "viewport",
            "ui",
            "panorama",
            "world",
        ):
            setattr(ns, name, importlib.import_module(f"{EXTENSION_ID}.addon.{name}"))
        ns.gpu = gpu_layer()
        ns.bake = importlib.import_module(f"{EXTENSION_ID}.precompute.bake")
        ns.table_io = importlib.import_module(f"{EXTENSION_ID}.precompute.table_io")
        ns.table_cache = importlib.import_module(f"{EXTENSION_ID}.precompute.table_cache")
        addons = bpy.context.preferences.addons
        if addons.get(EXTENSION_ID) is None:
            addons.new().module = EXTENSION_ID
        ns.gpu.context.ensure_gpu_context()
        try:
            yield ns
        finally:
            entry = addons.get(EXTENSION_ID)
            if entry is not None:
                addons.remove(entry)


@pytest.fixture
def scene(bpy, tf):
    """An empty file (no World: nothing to render for the lighting), the caches emptied."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    tf.tables.clear_caches()  # memory, remembered failures and the disk cache
    tf.scene_draw.CACHES.clear()
    return bpy.context.scene
