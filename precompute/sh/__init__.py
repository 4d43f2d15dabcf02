"""Real spherical harmonics, one convention written once (``harmonics``: the basis, its index
l(l+1)+m and the sign convention), with ``projection``, ``rotations`` (block-diagonal band
matrices), ``windows`` (ringing) and ``zonal`` (clamped cosine, irradiance, convolution).
"""
