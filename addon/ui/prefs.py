"""The add-on's preferences (the table cache's directory and size limit) and where the extension
is installed.

This module is ``<extension package>.addon.ui.prefs``; Blender keys add-on preferences by the
extension package itself, e.g. ``bl_ext.user_default.thinfilm_sh`` (:data:`PACKAGE`). Imported
on its own (no parent package) it falls back to the manifest id (:data:`EXTENSION_ID`).

Where the table cache lives, first match wins (:func:`cache_location`; docs/cache.md):

1. ``--cache-dir`` of the headless commands (:func:`.tables.cache_dir_override`);
2. the environment variable ``THINFILM_SH_CACHE`` (:data:`CACHE_ENV`), as everywhere else;
3. the *Cache Directory* preference;
4. installed as an extension: ``cache`` in the extension's user directory (Blender keeps it
   across upgrades);
5. otherwise the per-user default of :func:`precompute.tables.table_cache.default_cache_dir`
   (``$XDG_CACHE_HOME/thinfilm_sh`` or ``~/.cache/thinfilm_sh``, created 0700).

Its size limit: ``THINFILM_SH_CACHE_MAX_BYTES`` if set, else the *Cache Size Limit* preference
(:data:`DEFAULT_CACHE_LIMIT_MIB` = 2 GiB), else table_io's default (2 GiB).
"""

import os

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty
from bpy.types import AddonPreferences

from ...precompute.tables import table_cache

__all__ = [
    "CACHE_ENV",
    "DEFAULT_CACHE_LIMIT_MIB",
    "EXTENSION_ID",
    "PACKAGE",
    "SIZE_ENV",
    "ThinFilmSHPreferences",
    "cache_dir",
    "cache_location",
    "cache_max_bytes",
    "default_cache_dir",
    "overlay_enabled",
    "bake_helper_enabled",
    "preferences",
    "render_helper_enabled",
]

#: The extension's id in ``blender_manifest.toml``.
EXTENSION_ID = "thinfilm_sh"
#: The package Blender imported the extension as (``addon``'s parent), else :data:`EXTENSION_ID`.
PACKAGE = (__package__ or "").rpartition(".addon.")[0] or EXTENSION_ID
#: Environment variable naming the cache directory (wins over the preference).
CACHE_ENV = "THINFILM_SH_CACHE"
#: Environment variable with the cache's size limit in bytes, e.g. ``500M`` (wins over the preference).
SIZE_ENV = "THINFILM_SH_CACHE_MAX_BYTES"
_MIB = 1024**2
#: The size limit preference's default: table_cache.DEFAULT_CACHE_MAX_BYTES (2 GiB) in MiB.
DEFAULT_CACHE_LIMIT_MIB = table_cache.DEFAULT_CACHE_MAX_BYTES // _MIB


def _extension_cache_dir() -> str:
    """``cache`` in the extension's user directory, or "" when not installed as an extension."""
    try:
        return bpy.utils.extension_path_user(PACKAGE, path="cache", create=False) or ""
    except ValueError:  # the package is not under bl_ext: not installed as an extension
        return ""


def default_cache_dir() -> str:
    """Where baked tables go when the preference is empty (nothing is created here).

    ``$THINFILM_SH_CACHE`` if set; installed as an extension, ``cache`` in the extension's user
    directory; otherwise the per-user default of :func:`precompute.tables.table_cache.default_cache_dir`,
    never a shared folder such as ``/tmp``.
    """
    if os.environ.get(CACHE_ENV):
        return str(table_cache.default_cache_dir())
    return _extension_cache_dir() or str(table_cache.default_cache_dir())


def preferences(context=None):
    """This extension's preferences, or None while it isn't enabled in Blender's preferences."""
    context = context or bpy.context
    addon = context.preferences.addons.get(PACKAGE)
    return addon.preferences if addon is not None else None


def cache_location(context=None) -> tuple:
    """(directory, source) of the table cache: the directory to give
    :class:`~precompute.tables.table_cache.TableCache` (None: its own private per-user default) and what
    chose it: ``"THINFILM_SH_CACHE"``, ``"preference"``, ``"extension"`` or ``"default"``.

    Raises :class:`~precompute.tables.table_cache.CacheDirError` for a preference relative to the .blend
    file (``//…``) while the file is not saved, or otherwise not absolute: it would name a folder
    relative to whatever the current directory happens to be.
    """
    if os.environ.get(CACHE_ENV):
        return None, CACHE_ENV  # TableCache reads it: a directory the user named
    prefs = preferences(context)
    chosen = prefs.cache_dir.strip() if prefs is not None else ""
    if chosen:
        if chosen.startswith("//") and not bpy.data.filepath:
            raise table_cache.CacheDirError(
                chosen,
                f"the Cache Directory preference {chosen!r} is relative to the .blend file, which is "
                "not saved yet: save the file or choose an absolute folder",
            )
        path = bpy.path.abspath(chosen)
        if not os.path.isabs(path):
            raise table_cache.CacheDirError(
                chosen, f"the Cache Directory preference {chosen!r} is not an absolute folder: choose one"
            )
        return path, "preference"
    extension = _extension_cache_dir()
    if extension:
        return extension, "extension"
    return None, "default"


def cache_dir(context=None) -> str:
    """The cache directory in use, for display: see :func:`cache_location`."""
    try:
        directory, _source = cache_location(context)
    except table_cache.CacheDirError as exc:
        return exc.filename
    return directory if directory is not None else str(table_cache.default_cache_dir())


def cache_max_bytes(context=None) -> int | None:
    """The cache's size limit in bytes from the preference, or None when
    ``THINFILM_SH_CACHE_MAX_BYTES`` is set or the preferences are not there (TableCache then
    reads the variable, else uses its 2 GiB default)."""
    if os.environ.get(SIZE_ENV, "").strip():
        return None
    prefs = preferences(context)
    return int(prefs.cache_limit_mib) * _MIB if prefs is not None else None


_SOURCES = {
    CACHE_ENV: f"set by {CACHE_ENV} (overrides the preference)",
    "preference": "this preference",
    "extension": "the extension's user directory",
    "default": "your private cache directory",
}


def overlay_enabled(context=None) -> bool:
    """The *Show Thin Film Overlay* preference (True while the preferences are not there)."""
    prefs = preferences(context)
    return bool(prefs.show_overlay) if prefs is not None else True


def overlay_in_rendered(context=None) -> bool:
    """The *Overlay in Rendered Shading* preference (True while the preferences are not there):
    the overlay is also drawn in Rendered shading when the engine is EEVEE (addon/drawing/viewport.py)."""
    prefs = preferences(context)
    return bool(prefs.show_in_rendered) if prefs is not None else True


def render_helper_enabled(context=None) -> bool:
    """The *Render Procedural Worlds in a Helper Process* preference (True while the preferences
    are not there; :mod:`.panorama_helper`)."""
    prefs = preferences(context)
    return bool(prefs.use_render_helper) if prefs is not None else True


def bake_helper_enabled(context=None) -> bool:
    """The *Bake in a Helper Process* preference (True while the preferences are not there;
    :mod:`.bake_helper`)."""
    prefs = preferences(context)
    return bool(prefs.use_bake_helper) if prefs is not None else True


class ThinFilmSHPreferences(AddonPreferences):
    """The extension's preferences: the overlay switch, the table cache's folder and size."""

    bl_idname = PACKAGE

    show_overlay: BoolProperty(
        name="Show Thin Film Overlay",
        description="Draw thin films over the 3D viewports and in headless renders. Off: nothing "
        "is drawn or baked in the background (each viewport also has its own switch in its "
        "Overlays popover)",
        default=True,
    )

    show_in_rendered: BoolProperty(
        name="Overlay in Rendered Shading (EEVEE)",
        description="Also draw the thin-film overlay in Rendered shading when the render engine is "
        "EEVEE, over EEVEE's own (native) film and depth-tested against EEVEE's depth. Off: "
        "Rendered shading shows EEVEE's native film alone",
        default=True,
    )

    use_render_helper: BoolProperty(
        name="Render Procedural Worlds in a Helper Process",
        description="Render the panorama of a procedural World (Sky Texture, mixes, ...) in a "
        "background Blender process, so the viewport keeps running while it renders. Off: it is "
        "rendered in Blender itself, which pauses the interface for about a second per World edit",
        default=True,
    )

    use_bake_helper: BoolProperty(
        name="Bake in a Helper Process",
        description="Bake the viewport's film tables in a background Python process, so an edit's "
        "new table is ready in tens of milliseconds whatever the interface is drawing. Off: they "
        "are baked on a thread of Blender itself, which waits while the interface draws",
        default=True,
    )

    cache_dir: StringProperty(
        name="Cache Directory",
        description="Where baked thin-film and spherical-harmonic tables are stored (in a "
        "'thinfilm_sh_tables' subfolder; nothing else there is touched). Leave empty for a private "
        f"per-user directory. The environment variable {CACHE_ENV} overrides it",
        subtype="DIR_PATH",
        options={"PATH_SUPPORTS_BLEND_RELATIVE"},  # "//…": beside the open .blend file
        default="",
    )
    cache_limit_mib: IntProperty(
        name="Cache Size Limit (MiB)",
        description="Largest size of the table cache on disk; the least recently used tables are "
        f"deleted beyond it (0: keep only the newest). The environment variable {SIZE_ENV} overrides it",
        default=DEFAULT_CACHE_LIMIT_MIB,
        min=0,
        soft_max=64 * 1024,
    )

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "show_overlay")
        layout.prop(self, "show_in_rendered")
        layout.prop(self, "use_render_helper")
        layout.prop(self, "use_bake_helper")
        layout.prop(self, "cache_dir")
        layout.prop(self, "cache_limit_mib")
        col = layout.column(align=True)
        col.active = False
        for line, icon in cache_status(context):
            col.label(text=line, icon=icon)


def cache_status(context=None) -> list:
    """(text, icon) lines for the preferences: where the cache is, how full, or why it is unusable."""
    try:
        directory, source = cache_location(context)
        cache = table_cache.TableCache(directory, max_bytes=cache_max_bytes(context))
        used = cache.size_bytes()  # checks the directory (no symbolic link, yours, private)
    except (OSError, ValueError) as exc:
        return [(f"Table cache unusable: {exc}", "ERROR")]
    return [
        (f"In use: {cache.tables_dir} ({_SOURCES[source]})", "FILE_FOLDER"),
        (f"Holds {used / _MIB:.1f} MiB of at most {cache.max_bytes / _MIB:.0f} MiB", "DISK_DRIVE"),
    ]
