"""Thin Film SH: physically based thin-film interference previewed in Blender's viewport.

The repository root is the extension package (see ``blender_manifest.toml``); Blender imports it
as ``bl_ext.<repository>.thinfilm_sh``. All Blender-facing code lives in ``addon/``; this file only
forwards to it.
"""

from .addon import register, unregister

__all__ = ["register", "unregister"]
