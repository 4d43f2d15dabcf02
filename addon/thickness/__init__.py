"""Thickness: a film's thickness per face corner, from an attribute, noise, an image or a link.

The extension's sources (``thickness``), a Principled BSDF's linked Thin Film Thickness
(``linked``), a textured thickness per pixel (``maps``), and a source as shader nodes
(``thickness_nodes``). Imports nothing of its own:
name the module.
"""
