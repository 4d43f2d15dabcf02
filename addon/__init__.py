"""The thin bpy layer of the extension: registration of its classes, property and hooks.

Everything here is Blender glue. The physics lives in ``precompute/`` (which never imports
``bpy``) and the shaders in ``glsl/``. Where the add-on keeps state: :mod:`.caches`.
"""

import bpy
from bpy.props import PointerProperty

from . import caches
from .bakes import bake_helper
from .drawing import viewport
from .eevee import sync as eevee_films  # not `eevee`: that is the room's package
from .headless import headless as commands  # not `headless`: that is the room's package
from .materials import gltf, props
from .ui import ops, prefs
from .ui import ui as panels  # not `ui`: that is the room's package
from .world import panorama_helper

#: The glTF add-on looks these names up on enabled add-ons (KHR_materials_iridescence, :mod:`.gltf`).
glTF2ExportUserExtension = gltf.ExportUserExtension
glTF2ImportUserExtension = gltf.ImportUserExtension

classes = (prefs.ThinFilmSHPreferences, *props.classes, *ops.classes, *panels.classes)

# ----------------------------------------------------------------------------------------------
# HOOKS for other parts of the add-on (viewport draw handler, command line, ...).
#
# Each entry is a module (or any object) with register() and unregister(). They run AFTER the
# classes above are registered and the Material property exists, and are unregistered in
# reverse order BEFORE them. Both calls must be harmless when repeated (register() is called
# twice by the tests). To add one: import it above and append it to the tuple.
# ----------------------------------------------------------------------------------------------
modules: tuple = (panorama_helper, bake_helper, viewport, commands, eevee_films)

#: Name of the per-material settings: ``material.thinfilm_sh``.
MATERIAL_PROPERTY = "thinfilm_sh"


def register():
    """Register every class, the Material property, then the hook modules; repeat calls are harmless."""
    for cls in classes:
        if not cls.is_registered:
            bpy.utils.register_class(cls)
    if not hasattr(bpy.types.Material, MATERIAL_PROPERTY):
        setattr(
            bpy.types.Material,
            MATERIAL_PROPERTY,
            PointerProperty(
                type=props.ThinFilmMaterialSettings,
                name="Thin Film SH",
                description="Thin-film interference settings of this material for the viewport preview",
            ),
        )
    for module in modules:
        module.register()


def unregister():
    """Undo :func:`register` in reverse order, then empty every cache (:func:`caches.clear`)."""
    for module in reversed(modules):
        module.unregister()
    if hasattr(bpy.types.Material, MATERIAL_PROPERTY):
        delattr(bpy.types.Material, MATERIAL_PROPERTY)
    for cls in reversed(classes):
        if cls.is_registered:
            bpy.utils.unregister_class(cls)
    caches.clear()
