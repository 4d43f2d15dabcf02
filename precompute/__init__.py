"""Thin Film SH precompute core.

Pure numpy (published colour tables shipped as data): spectral thin-film optics, microfacet BRDFs, spherical
harmonics and table baking. This package never imports ``bpy``; it runs standalone
(``python -m precompute``) and inside Blender alike.

Conventions used throughout (see ``docs/conventions.md``):

- wavelengths λ in nanometres, thicknesses d in nanometres;
- complex refractive index N = n + i·k with k ≥ 0 for absorbing media
  (time dependence e^{-iωt});
- angles given as cosines in [0, 1];
- arrays broadcast, with the wavelength on the last axis.

One subpackage per entity (docs/ARCHITECTURE.md): ``optics`` (thin-film optics), ``materials``,
``colour``, ``sh`` (spherical harmonics), ``bakes``, ``tables`` (tables on disk), ``world`` (the
World's lighting), ``effects`` (the effect plan), ``output`` (reference renders and image files),
``commands`` (the command line) and ``shading`` (the shader's numpy mirror); ``brdf`` (GGX,
Smith, multiple scattering) and ``constants`` sit here.
"""

__all__ = ["bakes", "brdf", "colour", "materials", "optics", "sh", "shading"]
