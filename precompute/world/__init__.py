"""The World's lighting from a panorama: equirect images (``hdri``), its bright lamps (``lamps``),
the GGX prefilter for the split sum (``prefilter``) and the one call that analyses a panorama
for the draw (``environment``).
"""
