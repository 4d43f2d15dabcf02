"""The thin bpy layer of the extension: preferences, material settings, operators and panels.

Everything here is Blender glue. The physics lives in ``precompute/`` (which never imports
``bpy``) and the shaders in ``glsl/``.
"""

import os
import tempfile

import bpy
from bpy.props import PointerProperty, StringProperty
from bpy.types import AddonPreferences

# This module is ``<extension package>.addon``; Blender keys add-on preferences by the extension
# package itself, e.g. ``bl_ext.user_default.thinfilm_sh``. Imported on its own (no parent
# package) it falls back to the manifest id.
EXTENSION_ID = "thinfilm_sh"
PACKAGE = (__package__ or "").rpartition(".")[0] or EXTENSION_ID


def default_cache_dir() -> str:
    """Where baked tables go when the preference is empty.

    Installed as an extension: the extension's user directory (kept across upgrades), ``cache``
    inside it. Otherwise (imported by path, e.g. in tests) a folder in the system temp dir.
    Nothing is created here.
    """
    try:
        path = bpy.utils.extension_path_user(PACKAGE, path="cache", create=False)
    except ValueError:  # the package is not under bl_ext: not installed as an extension
        path = ""
    return path or os.path.join(tempfile.gettempdir(), EXTENSION_ID, "cache")


def preferences(context=None):
    """This extension's preferences, or None while it isn't enabled in Blender's preferences."""
    context = context or bpy.context
    addon = context.preferences.addons.get(PACKAGE)
    return addon.preferences if addon is not None else None


def cache_dir(context=None) -> str:
    """The cache directory in use: the user's choice if set, else :func:`default_cache_dir`."""
    prefs = preferences(context)
    chosen = prefs.cache_dir.strip() if prefs is not None else ""
    return bpy.path.abspath(chosen) if chosen else default_cache_dir()


class ThinFilmSHPreferences(AddonPreferences):
    bl_idname = PACKAGE

    cache_dir: StringProperty(
        name="Cache Directory",
        description="Where baked thin-film and spherical-harmonic tables are stored. "
        "Leave empty for the extension's own user directory",
        subtype="DIR_PATH",
        default="",
    )

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "cache_dir")
        row = layout.row()
        row.active = False
        row.label(text=f"In use: {cache_dir(context)}", icon="FILE_FOLDER")


# Imported after the helpers above: materials.table_cache() calls cache_dir() from here.
from . import ops, props, ui  # noqa: E402

classes = (ThinFilmSHPreferences, *props.classes, *ops.classes, *ui.classes)

# ----------------------------------------------------------------------------------------------
# HOOKS for other parts of the add-on (viewport draw handler, command line, ...).
#
# Each entry is a module (or any object) with register() and unregister(). They run AFTER the
# classes above are registered and the Material property exists, and are unregistered in
# reverse order BEFORE them. Both calls must be harmless when repeated (register() is called
# twice by the tests). To add one: import it here and append it to the tuple, e.g.
#     from . import draw, cli
#     modules = (draw, cli)
# ----------------------------------------------------------------------------------------------
from . import headless, viewport  # noqa: E402

modules: tuple = (viewport, headless)

#: Name of the per-material settings: ``material.thinfilm_sh``.
MATERIAL_PROPERTY = "thinfilm_sh"


def register():
    """Register every class, the Material property, then the hook modules; repeat calls are harmless."""
    for cls in classes:
        if not cls.is_registered:
            bpy.utils.register_class(cls)
    if not hasattr(bpy.types.Material, MATERIAL_PROPERTY):
        setattr(bpy.types.Material, MATERIAL_PROPERTY, PointerProperty(type=props.ThinFilmMaterialSettings))
    for module in modules:
        module.register()


def unregister():
    """Undo :func:`register` in reverse order; anything not registered is skipped."""
    for module in reversed(modules):
        module.unregister()
    if hasattr(bpy.types.Material, MATERIAL_PROPERTY):
        delattr(bpy.types.Material, MATERIAL_PROPERTY)
    for cls in reversed(classes):
        if cls.is_registered:
            bpy.utils.unregister_class(cls)
