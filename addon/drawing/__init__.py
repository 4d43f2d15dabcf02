"""Drawing: what the viewport and the headless frame draw, and the viewport's draw handler.

Visible objects → draw items (``scene_draw``), light objects (``lights``), shader variants
compiled ahead (``shader_warmup``), colour management (``display``) and the 3D viewport's draw
handler and timer (``viewport``). The GPU objects are in ``addon/gpu/``. Imports nothing of its
own: name the module.
"""
