"""EEVEE-native films: Blender itself renders the film wherever EEVEE renders.

Each film material gets an EEVEE-only Material Output fed by a node group that reads a baked,
packed film image (the film's lobe-integrated albedo divided by EEVEE's own split sum,
:mod:`precompute.bakes.eevee_table`) at the pixel's view angle and thickness, and shades with EEVEE's
Glossy, Diffuse, Transparent and Refraction BSDFs; the material's own output (the Principled
BSDF Cycles renders) is left as it is. Rendered viewport, F12, Render Animation and
``blender -b -a`` then show the film, lit by EEVEE's lights, shadows and reflections.

Rooms: :mod:`.nodes` (the group and the EEVEE output), :mod:`.image` (the packed float image),
:mod:`.source` (what a material's EEVEE film is made from), :mod:`.wiring` (into and out of a
material), :mod:`.sync` (in step with the panel, live and headless; its ``register`` is the
add-on's hook). docs/eevee-native.md.
"""
