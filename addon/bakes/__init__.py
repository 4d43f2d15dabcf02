"""Bakes: a description's SH table, its film table and its radiance grid, made off the draw.

Tables in memory, on disk or baked (``tables``), the viewport's bake queue and the one bake-job
type, the bake helper process (``bake_helper`` and its script ``bake_process``), what an edit
asks for early (``bake_asks``) and the outgoing-radiance grids (``radiance_grids``). Imports
nothing of its own: name the module.
"""
