"""The repository as a Blender extension: manifest, built package, registration in a real bpy.

Blender's own extension tool (``blender_ext.py``, shipped inside the ``bpy`` wheel) validates the
manifest and builds the package; the add-on is then imported under its extension id from a
symlink and registered in the ``bpy`` module. bpy is imported only in this module, and only by
the tests that need a Blender session.
"""

import ast
import importlib
import importlib.util
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.blender

REPO = Path(__file__).resolve().parents[2]  # tests/<feature>/this file
MANIFEST = tomllib.loads((REPO / "blender_manifest.toml").read_text(encoding="utf-8"))
EXTENSION_ID = MANIFEST["id"]
REGISTER_CYCLES = 10


def _bpy_scripts_dir() -> Path:
    """``bpy/<version>/scripts`` of the installed bpy wheel, found without importing bpy."""
    spec = importlib.util.find_spec("bpy")
    assert spec is not None and spec.submodule_search_locations, "the bpy module is not installed"
    (bpy_dir,) = spec.submodule_search_locations
    found = sorted(Path(bpy_dir).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    assert found, f"blender_ext.py not found under {bpy_dir}"
    return found[-1].parents[3]


def _blender_ext(*args: str) -> subprocess.CompletedProcess:
    """Run Blender's extension command-line tool with this interpreter."""
    tool = _bpy_scripts_dir() / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    return subprocess.run(
        [sys.executable, str(tool), *args], capture_output=True, text=True, timeout=300, check=False
    )


def _valid_tags() -> str:
    """Blender's list of allowed tags (the standalone tool checks none unless given one)."""
    tags = _bpy_scripts_dir() / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    assert tags.is_file(), tags
    return str(tags)


def test_manifest_passes_blenders_validator():
    """Blender's own `extension validate` accepts the manifest and package: what the extensions platform runs
    before listing it."""
    result = _blender_ext("validate", "--valid-tags", _valid_tags(), str(REPO))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Success" in result.stdout


def test_built_package_is_valid_and_holds_only_the_addon(tmp_path):
    archive = tmp_path / f"{EXTENSION_ID}-{MANIFEST['version']}.zip"
    result = _blender_ext(
        "build", "--source-dir", str(REPO), "--output-filepath", str(archive), "--valid-tags", _valid_tags()
    )
    assert result.returncode == 0, result.stdout + result.stderr

    result = _blender_ext("validate", "--valid-tags", _valid_tags(), str(archive))
    assert result.returncode == 0, result.stdout + result.stderr

    with zipfile.ZipFile(archive) as zf:
        names = zf.namelist()
    for required in ("blender_manifest.toml", "__init__.py", "addon/__init__.py", "precompute/__init__.py"):
        assert required in names
    excluded_tops = {"tests", "benchmarks", "docs", "scripts", "out", "build", "dist"}
    leaked = [
        n
        for n in names
        if n.split("/")[0] in excluded_tops
        or any(part.startswith(".") or part == "__pycache__" for part in n.split("/"))
        or n.endswith((".pyc", ".blend1", ".zip"))
        or n in ("pyproject.toml", "requirements.txt", "requirements-dev.txt")
    ]
    assert not leaked, f"development files in the package: {leaked}"
    assert "LICENSE" in names
    # colour-science is not bundled: no packaged module may import it (the tables ship as data).
    with zipfile.ZipFile(archive) as zf:
        importers = [
            n
            for n in names
            if n.endswith(".py")
            and any(
                (isinstance(node, ast.Import) and any(a.name.split(".")[0] == "colour" for a in node.names))
                or (
                    isinstance(node, ast.ImportFrom)
                    and (node.module or "").split(".")[0] == "colour"
                    and not node.level
                )
                for node in ast.walk(ast.parse(zf.read(n)))
            )
        ]
    assert not importers, f"packaged modules importing colour-science: {importers}"
    assert any(n.startswith("precompute/data/colour/") for n in names)


def test_root_init_only_forwards_to_addon():
    """The repository root is the extension package: its __init__ must stay a thin forwarder."""
    tree = ast.parse((REPO / "__init__.py").read_text(encoding="utf-8"))
    body = list(tree.body)
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        body = body[1:]  # docstring
    imports = [n for n in body if isinstance(n, ast.ImportFrom)]
    assert imports and all(n.level == 1 and n.module == "addon" for n in imports)
    names = {alias.name for n in imports for alias in n.names}
    assert {"register", "unregister"} <= names
    others = [n for n in body if not isinstance(n, ast.ImportFrom)]
    assert all(
        isinstance(n, ast.Assign) and [t.id for t in n.targets if isinstance(t, ast.Name)] == ["__all__"]
        for n in others
    ), "the root __init__.py may only import from .addon (and set __all__)"


# --- in a real Blender session ----------------------------------------------------------------


@pytest.fixture
def extension(bpy, tmp_path):
    """The repository imported as the package ``thinfilm_sh`` (as Blender would name it)."""
    link = tmp_path / EXTENSION_ID
    os.symlink(REPO, link, target_is_directory=True)
    sys.path.insert(0, str(tmp_path))
    try:
        module = importlib.import_module(EXTENSION_ID)
        assert Path(module.__file__).resolve() == REPO / "__init__.py"
        yield module
    finally:
        module = sys.modules.get(EXTENSION_ID)
        if module is not None:
            module.unregister()
        sys.path.remove(str(tmp_path))
        for name in [n for n in sys.modules if n == EXTENSION_ID or n.startswith(EXTENSION_ID + ".")]:
            del sys.modules[name]


def _registered(classes):
    return [cls.__name__ for cls in classes if cls.is_registered]


def test_register_unregister_cycles_leave_nothing_behind(bpy, extension):
    addon = importlib.import_module(f"{EXTENSION_ID}.addon")
    classes = addon.classes
    assert classes, "addon.classes is empty"
    prefs_classes = [cls for cls in classes if issubclass(cls, bpy.types.AddonPreferences)]
    assert len(prefs_classes) == 1
    assert prefs_classes[0].bl_idname == EXTENSION_ID  # add-on preferences are keyed by the package

    types_before = set(dir(bpy.types))
    class_names = {cls.__name__ for cls in classes}
    for cycle in range(REGISTER_CYCLES):
        extension.register()
        assert _registered(classes) == [cls.__name__ for cls in classes], f"cycle {cycle}"
        # Panels, operators, menus, ... show up in bpy.types; nothing else may.
        assert set(dir(bpy.types)) - types_before <= class_names
        extension.register()  # a second call must be harmless
        extension.unregister()
        assert _registered(classes) == [], f"cycle {cycle}"
        assert set(dir(bpy.types)) == types_before, f"cycle {cycle}"
        extension.unregister()  # and so must a second unregister


def test_preferences_hold_the_cache_directory(bpy, extension, tmp_path):
    prefs_mod = importlib.import_module(f"{EXTENSION_ID}.addon.ui.prefs")
    extension.register()
    addons = bpy.context.preferences.addons
    assert addons.get(EXTENSION_ID) is None
    assert prefs_mod.preferences() is None
    assert prefs_mod.cache_dir() == prefs_mod.default_cache_dir() != ""

    # Enable it the way Blender's preferences do: an add-on entry keyed by the package name.
    entry = addons.new()
    try:
        entry.module = EXTENSION_ID
        prefs = prefs_mod.preferences()
        assert prefs is not None and isinstance(prefs, bpy.types.AddonPreferences)
        prop = prefs.bl_rna.properties["cache_dir"]
        assert (prop.subtype, prop.default) == ("DIR_PATH", "")
        assert prefs.cache_dir == "" and prefs_mod.cache_dir() == prefs_mod.default_cache_dir()
        prefs.cache_dir = str(tmp_path)
        assert prefs_mod.cache_dir() == str(tmp_path)
    finally:
        addons.remove(entry)
        extension.unregister()
    assert addons.get(EXTENSION_ID) is None


def test_every_cache_is_registered_documented_and_emptied(bpy, extension):
    """addon.caches: every registered cache is described in its docstring; a file load empties
    the per-file ones, unregister all of them."""
    caches = importlib.import_module(f"{EXTENSION_ID}.addon.caches")
    registered = caches.registered()
    assert {"tables", "world_sh", "plans", "plan_orders_seen", "scene_draw", "shaders", "uniforms"} <= set(
        registered
    )
    for name in registered:
        assert f"``{name}``" in caches.__doc__, f"cache {name!r} is not documented in addon/caches.py"

    extension.register()
    tables, ui = registered["tables"].cache, registered["plan_orders_seen"].cache
    tables["key"] = "table"
    ui.add(0.5)
    scene_draw = importlib.import_module(f"{EXTENSION_ID}.addon.drawing.scene_draw")
    scene_draw.CACHES.tables["key"] = "texture"
    bpy.ops.wm.read_factory_settings(use_empty=True)  # load_post: the per-file caches only
    assert not scene_draw.CACHES.tables and tables.get("key") == "table" and 0.5 in ui
    extension.unregister()
    assert len(tables) == 0 and not ui


def test_the_lru_drops_the_least_recently_used_entry(bpy, extension):
    caches = importlib.import_module(f"{EXTENSION_ID}.addon.caches")
    lru = caches.LRU(2)
    lru["a"], lru["b"] = 1, 2
    assert lru["a"] == 1  # "a" is now the most recent
    lru["c"] = 3
    assert "b" not in lru and lru.get("b", "gone") == "gone" and len(lru) == 2
    lru.clear()
    assert len(lru) == 0
    with pytest.raises(ValueError):
        caches.LRU(0)
