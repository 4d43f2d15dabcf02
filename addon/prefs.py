"""The add-on's preferences (the table cache directory) and where the extension is installed.

This module is ``<extension package>.addon.prefs``; Blender keys add-on preferences by the
extension package itself, e.g. ``bl_ext.user_default.thinfilm_sh`` (:data:`PACKAGE`). Imported
on its own (no parent package) it falls back to the manifest id (:data:`EXTENSION_ID`).
"""

import os
import tempfile

import bpy
from bpy.props import StringProperty
from bpy.types import AddonPreferences

__all__ = [
    "EXTENSION_ID",
    "PACKAGE",
    "ThinFilmSHPreferences",
    "cache_dir",
    "default_cache_dir",
    "preferences",
]

#: The extension's id in ``blender_manifest.toml``.
EXTENSION_ID = "thinfilm_sh"
#: The package Blender imported the extension as (``addon``'s parent), else :data:`EXTENSION_ID`.
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
