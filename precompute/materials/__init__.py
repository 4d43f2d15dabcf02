"""A material's description: the validated ``Material`` and its presets (``material``), the limits
on every value (``validate``), Principled's metals as n + ik (``conductors``) and the procedural
thickness noise (``noise``).
"""
