"""Materials: a Blender material's thin film as the preview shows it.

The extension's property groups (``props``), a Principled BSDF's film (``principled``), the
description the preview bakes (``description``), transparent walls (``transparency``) and
glTF's KHR_materials_iridescence (``gltf``). Imports nothing of its own: name the module.
"""
