"""Named numerical constants, each with the reason it exists."""

#: Visible range used for every spectral integral (CIE 1931 2° CMFs are tabulated 360–830 nm).
WAVELENGTH_MIN_NM = 360.0
WAVELENGTH_MAX_NM = 830.0

#: Smallest cosine used where a division by a cosine would blow up (grazing views).
#: At 1e-4 the view is 89.994° from the normal, finer than any table resolution we use.
MIN_COS = 1e-4

#: Smallest GGX α. Blender clamps roughness² similarly; below this the lobe is a delta
#: that no quadrature can resolve.
MIN_ALPHA = 1e-4

#: Phase step (radians) that one wavelength sub-sample may span when band-averaging
#: thin-film fringes. π/4 gives ≥ 8 samples per fringe: the midpoint rule then integrates
#: a cosine fringe to < 1 % (sinc(π/8) ≈ 0.974 per harmonic, measured in tests).
MAX_PHASE_STEP = 0.25 * 3.141592653589793
