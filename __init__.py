"""Thin Film SH: physically based thin-film interference previewed in Blender's viewport.

The repository root is the extension package (see ``blender_manifest.toml``); Blender imports it
as ``bl_ext.<repository>.thinfilm_sh``. All Blender-facing code lives in ``addon/``; this file only
forwards to it. The glTF add-on looks its user extensions up by these two names on an enabled
add-on's module (``addon/materials/gltf.py``: KHR_materials_iridescence both ways).
"""

from .addon import glTF2ExportUserExtension, glTF2ImportUserExtension, register, unregister

__all__ = ["glTF2ExportUserExtension", "glTF2ImportUserExtension", "register", "unregister"]
