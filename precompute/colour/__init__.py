"""Colour: the published colour tables, spectra ↔ XYZ ↔ working RGB, and the film's colour.

``colour_tables`` (the shipped CIE and RGB-space data), ``spectra`` (wavelength grids, CMFs,
illuminants, XYZ), ``rgb_spaces`` (the working spaces, their matrices and channel
sensitivities, RGB → spectrum), ``composite`` (spiky illuminants), ``film_colour`` (the film's
RGB matrices per u), ``film_channels`` (Cycles' per-channel film), ``colour_difference``
(the one ΔE2000), ``display_lut`` (the display transform as a 3-D LUT, the numpy twin of
``glsl/tf_display.glsl``).
"""
