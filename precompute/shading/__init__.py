"""The numpy mirror of the shader: one module per GLSL chunk, and the rules both share.

======================================  ====================================================
GLSL (glsl/ and generated)              numpy (precompute/shading/)
======================================  ====================================================
tf_frame.glsl                           frame.py: ``view_aligned_frame``, ``zyz_from_frame``
``tf_view_aligned_frame``,              (``GIMBAL_SIN``: policy.py)
``tf_zyz_from_frame``
tf_sh_rotate.glsl                       sh_rotation.py: ``rotate_z_batch``,
``tf_local_coefficients_direct``;       ``x_rotation_bands``, ``apply_bands``,
tests/glsl/tf_sh_rotate_loops.glsl      ``local_coefficients``
(reference) ``tf_rotate_z``,
``tf_apply_x90``,
``tf_local_coefficients``
tf_table.glsl ``tf_lerp_index``,        table.py: ``lerp_index``, ``lookup``,
``tf_table_lerp``, ``tf_table_fetch``   ``thickness_position``
tf_shade.glsl ``tf_shade``,             sh_sum.py: ``shade_sh``
``tf_shade_at``; generated
``tf_banded_sum``
tf_split_sum.glsl                       split_sum.py: ``level_blend``, ``lookup``,
``tf_prefiltered_lookup``,              ``lamp_weight_at``, ``dominant_cosine``,
``tf_shade_split_sum_at``,              ``shade_split_sum``, ``shade_combined``
``tf_shade_combined``
tf_lamps.glsl ``tf_shade_lamps``,       lamps.py: ``shade``, ``lamp_weight``,
``tf_film_at``                          ``level_lamp_weights``
tf_radiance_grid.glsl                   radiance_grid.py: ``coordinates``, ``lookup``
``tf_shade_grid``                       (the grid: ``build``, ``cell_geometry``)
``#define``s of the shading rules       policy.py: ``glsl_defines`` (and every rule's value)
(``TF_MAX_LAMPS``, ``TF_MIN_COS``, …)
variant ``#define``s (``TF_L_MAX``,     variant.py: ``Variant.defines``, ``choose_variant``
``TF_SPLIT_SUM``, ``TF_MOMENT``, …)
generated code (``tf_banded_sum``,      codegen.py: ``banded_source``, ``x90_band_lines``,
the X(±90°) constants' layout)          ``x_rotation_scalars``, ``operation_counts``
======================================  ====================================================

The brute-force ground truth these are checked against (no SH) is precompute/output/render.py's
``shade_reference``; tests/test_gpu_draw.py runs the GLSL per pixel against these functions.
This package imports nothing on import: take the modules you need.
"""
