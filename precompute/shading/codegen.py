"""All generated GLSL, and what the generated and selected code does per pixel.

- :func:`banded_source`: ``tf_banded_sum``, the z-y-z rotation of the World's SH and the SH sum
  of tf_shade.glsl written out band by band for one l_max (the fast library from l = 3 on);
  the X(±90°) products multiply only the structurally non-zero entries
  (:func:`x90_band_lines`, policy.X90_ZERO), read from the lighting uniform buffer where
  :func:`x_rotation_scalars` puts them (:func:`rx_offset`).
- :func:`define_block`: ``#define`` lines, as the library's own switch ``TF_X90_GENERATED``.
- :func:`operation_counts`: the multiply-adds, texel fetches and uniform loads one pixel of a
  :class:`~precompute.shading.variant.Variant` costs, counted in the generated source where there
  is one; the effect plan reports them (precompute/effects/).

Pure Python and numpy: the add-on (addon/gpu/shaders.py) joins these with the chunks of glsl/.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from ..materials.material import MAX_SH_ORDER
from . import policy
from .sh_rotation import x_rotation_bands
from .variant import Variant

#: Highest l_max the shaders support; the lighting uniform buffer always has room for it.
MAX_L = MAX_SH_ORDER
#: The library switch that selects the generated code (set by addon/gpu/shaders.py shading_library).
X90_GENERATED = ("TF_X90_GENERATED", "1")


def rx_offset(l: int) -> int:
    """Scalar offset of band l within one set of x-rotation blocks: Σ_{j<l} (2j+1)²."""
    return l * (2 * l - 1) * (2 * l + 1) // 3


#: Scalars of one set of x-rotation band blocks for l = 0…MAX_L, and with padding to a vec4.
RX_SCALARS = rx_offset(MAX_L + 1)
RX_PADDED = 4 * math.ceil(RX_SCALARS / 4)


@functools.cache
def x_rotation_scalars() -> np.ndarray:
    """The Rx(+90°) band blocks, l = 0…MAX_L, row-major, padded to a vec4 (Rx(−90°) = transpose)."""
    out = np.zeros(RX_PADDED, dtype=np.float64)
    flat = np.concatenate([np.asarray(b, dtype=np.float64).ravel() for b in x_rotation_bands(MAX_L, +1)])
    assert flat.size == RX_SCALARS
    out[:RX_SCALARS] = flat
    out.setflags(write=False)
    return out


def define_block(defines) -> str:
    """``#define name value`` lines for (name, value) pairs."""
    return "\n".join(f"#define {name} {value}".rstrip() for name, value in defines)


def x90_band_lines(l: int, sign: int, indent: str) -> list[str]:
    """Band l of the X(±90°) product as straight-line GLSL on the band's variables ``q0 … q2l``.

    Only the structurally non-zero entries (247 of 969 for l ≤ 8; policy.X90_ZERO) are
    multiplied; their values are read from the lighting UBO at constant offsets, so the maths is
    the dense band product of ``sh_rotation.apply_bands`` minus exact zeros
    (docs/tuning.md#x90-generated). X(−90°) reads the X(+90°) blocks transposed (entry (i, j) at
    j·size + i).
    """
    block = np.asarray(x_rotation_bands(MAX_L, sign)[l])
    size, off = 2 * l + 1, rx_offset(l)
    lines = []
    for i in range(size):
        terms = [
            f"tf_rx({off + (i * size + j if sign > 0 else j * size + i)}) * q{j}"
            for j in range(size)
            if abs(block[i, j]) > policy.X90_ZERO
        ]
        lines.append(f"{indent}vec3 r{i} = " + (" + ".join(terms) or "vec3(0.0)") + ";")
    lines += [f"{indent}q{i} = r{i};" for i in range(size)]
    return lines


@functools.cache
def banded_source(l_max: int) -> str:
    """``tf_banded_sum``: the z-y-z rotation and the SH sum of tf_shade, one band at a time.

    Rotations never mix bands, so each band is loaded into its own variables, turned (Z(c),
    X(+90°), Z(b), X(−90°), Z(a): the operations of ``tf_local_coefficients`` in the same order)
    and summed against the table before the next is touched: at most one band (25 vec3 at
    l = 12) and the angle powers are live at a time, instead of the (l + 1)² coefficients of
    ``tf_c``. Used by the fast library from l = 3 on (below, ``tf_local_coefficients_direct``).
    """
    lines = [
        "/* ---- generated: precompute/shading/codegen.py banded_source ---- */",
        "vec3 tf_banded_sum(TFLerp r, vec2 a, vec2 b, vec2 c)",
        "{",
        "  vec3 sum = vec3(0.0);",
        "  tf_accumulate_value(sum, r, 0, tf_lighting.sh[0].rgb);",
    ]
    for l in range(1, int(l_max) + 1):
        first = l * l
        for name, angle in (("pc", "c"), ("pb", "b"), ("pa", "a")):  # c_m = c_(m-1) c_1 (tf_rotate_z)
            power = angle if l == 1 else f"tf_cmul({name}{l - 1}, {angle})"
            lines.append(f"  vec2 {name}{l} = {power};")
        lines.append(f"  {{ /* band {l} */")
        lines += [f"    vec3 q{j} = tf_lighting.sh[{first + j}].rgb;" for j in range(2 * l + 1)]
        for stage in ("pc", +1, "pb", -1, "pa"):
            if isinstance(stage, str):  # tf_zpair on (+m, -m) = local (l + m, l - m)
                for m in range(1, l + 1):
                    p, n, cm = f"q{l + m}", f"q{l - m}", f"{stage}{m}"
                    lines.append(
                        f"    {{ vec3 zc = {p}; vec3 zs = {n}; {p} = zc * {cm}.x - zs * {cm}.y;"
                        f" {n} = zc * {cm}.y + zs * {cm}.x; }}"
                    )
            else:
                lines.append("    {")
                lines += x90_band_lines(l, stage, "      ")
                lines.append("    }")
        kept = l * (l + 1) // 2
        lines += [f"    tf_accumulate_value(sum, r, {kept + m}, q{l + m});" for m in range(l + 1)]
        lines.append("  }")
    lines += ["  return sum;", "}"]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# Operation counts
# ----------------------------------------------------------------------------------------------
#: tf_local_coefficients_direct (glsl/tf_sh_rotate.glsl, the fast library at l_max ≤ 2):
#: l_max → (multiply-adds, vec4 loads of tf_lighting.sh). Band 1: two 3-term vec3 sums (18);
#: band 2: the Q entries (9 + 3 + 6 + 3), u = Q z and w = Q x (6 × 9), the three quadratic forms
#: (3 × 9) and the scaled outputs (3 + 3 + 6): 114 more.
DIRECT_PATH = {0: (0, 1), 1: (18, 4), 2: (132, 9)}
#: tf_shade_split_sum_at and tf_prefiltered_lookup, besides the albedo's table reads and the
#: 3×3 (or 3) albedo × radiance: reflection (4), effective roughness (1), level blend (20),
#: texture coordinates (2), × √(4π) (3).
SPLIT_SUM_MADS = 30
#: TF_MOMENT: |m|² (3), v·m (3), the cosine (3), the albedo's new θ position (4).
MOMENT_MADS = 13
#: tf_shade_combined: (1 − w) × split sum (4); + w × SH sum without TF_SPLIT_ONLY (3).
BLEND_MADS = (4, 3)
#: tf_shade_lamps per lamp, besides the film reads and F × power: cos θi (3), the half vector
#: (9), n·h (3), D (6), Λ(cos θi) (7), the weight (5), v·h (3), the lerp position (2), the sum (3).
LAMP_MADS = 41
#: tf_shade_grid (TF_RADIANCE_GRID) in place of the SH sum, whatever l_max: r and e1 (6 + 6),
#: turned by Q (9 + 9), ρ (2), the azimuth's unit vector (4), the equirect position (4), e1·a1
#: and e1·a2 (4 + 3), the θo and ψ positions and weights (3 + 3 + 2), three vec3 mixes of the
#: four fetched nodes (18) and × strength (3); three vec4 loads of Q and the strength.
GRID_MADS, GRID_FETCHES, GRID_LOADS = 76, 4, 3
#: tf_shade_lamps once per pixel: α, α², cos θo, Λ(cos θo) (10), × multiple scattering (3), the
#: sum's product (3); with the split sum also the lamp weight (2).
LAMP_FIXED_MADS = (16, 2)


@dataclass(frozen=True)
class OperationCounts:
    """Per-pixel work of a variant (see :func:`operation_counts` for what is counted).

    ``stages``: the same counts per stage, (multiply-adds, texel fetches, uniform loads).
    """

    multiply_adds: int
    texel_fetches: int
    uniform_loads: int
    #: Floats read from the film's baked table (texture or uniform buffer).
    table_floats: int
    stages: dict = field(default_factory=dict)


def _table_reads(variant: Variant, fetches: int) -> tuple[int, int, int, int]:
    """(multiply-adds, texel fetches, uniform loads, floats) of ``fetches`` interpolated
    tf_table_fetch calls: 2 taps (4 with TF_VARY_THICKNESS), one multiply-add per float read."""
    taps = 4 if variant.vary_thickness else 2
    texels = fetches * taps
    return 3 * texels, 0 if variant.table_ubo else texels, texels if variant.table_ubo else 0, 3 * texels


def _sh_sum(variant: Variant) -> tuple[int, int, int, int]:
    """The SH half: rotation and sum (counted in the generated source from l = 3 on)."""
    l_max = int(variant.l_max)
    layers = 3 if variant.spectral else 1
    sum_mads = 9 if variant.spectral else 3
    if l_max > 2:
        src = banded_source(l_max)
        coefficients = src.count("tf_accumulate_value(")
        rx_terms = src.count("tf_rx(")
        mads = 3 * rx_terms + 12 * src.count("vec3 zc") + 4 * src.count("tf_cmul(")
        loads = src.count("tf_lighting.sh[") + rx_terms
    else:
        coefficients = (l_max + 1) * (l_max + 2) // 2
        mads, loads = DIRECT_PATH[l_max]
    t_mads, t_fetch, t_loads, floats = _table_reads(variant, coefficients * layers)
    return mads + t_mads + coefficients * sum_mads, t_fetch, loads + t_loads, floats


def _split_sum(variant: Variant) -> tuple[int, int, int, int]:
    """The split sum: 1 prefiltered fetch (+1 moment), the albedo's table reads."""
    layers = 3 if variant.spectral else 1
    t_mads, t_fetch, t_loads, floats = _table_reads(variant, layers)
    mads = SPLIT_SUM_MADS + (9 if variant.spectral else 3) + t_mads + BLEND_MADS[0]
    fetches = 1 + t_fetch
    if variant.moment:
        mads += MOMENT_MADS
        fetches += 1
    return mads, fetches, t_loads, floats


def _lamps(variant: Variant, lamp_count: int) -> tuple[int, int, int]:
    """The lamp loop over ``lamp_count`` lamps: film reads per lamp and F × power."""
    layers = 3 if variant.spectral else 1
    taps = 4 if variant.vary_thickness else 2
    film_texels = (lamp_count * layers + 1) * taps  # + the multiple-scattering factor once
    mads = LAMP_FIXED_MADS[0] + (LAMP_FIXED_MADS[1] if variant.split_sum else 0)
    mads += lamp_count * (LAMP_MADS + (9 if variant.spectral else 3)) + 3 * film_texels
    loads = 1 + 2 * lamp_count  # the count, direction and power of each
    if variant.film_ubo:
        return mads, 0, loads + film_texels
    return mads, film_texels, loads


def operation_counts(variant: Variant, lamp_count: int = policy.MAX_LAMPS) -> OperationCounts:
    """What one pixel of ``variant`` (the product's fast library) computes and reads.

    Conventions: a multiply-add is one scalar multiply, add or fused multiply-add (a vec3
    operation counts 3); an interpolated table read is the weighted sum of its taps, one
    multiply-add per float read; a texel fetch is one ``texelFetch``/``texture`` call (the
    prefiltered World's hardware-filtered lookup counts 1); a uniform load is one vec4 (or
    scalar) read from a uniform buffer. Table and film texels count as uniform loads in the
    ``TF_TABLE_UBO`` / ``TF_FILM_UBO`` variants.

    A grid variant reads its SH half from the outgoing-radiance grid (:data:`GRID_MADS`: four
    fetches, the same at every order; its floats count as table floats). Otherwise the SH half
    is counted in the generated source (:func:`banded_source`: each X(±90°) term 3,
    each z pair 12, each angle power 4, each coefficient's table read and 3×3 or 3 sum) from
    l = 3 on, from :data:`DIRECT_PATH` below; the split sum, the blend and the lamp loop (at
    ``lamp_count`` lamps, by default its bound policy.MAX_LAMPS) from their known counts. Not
    counted, the same few dozen operations in every variant: the view-aligned frame, its
    z-y-z angles, the table position, transcendental functions, the display transform.
    """
    variant = variant.normalised()
    stages = {}
    floats = 0
    if variant.grid:  # normalised: only with an SH half
        mads, fetches, loads, f = GRID_MADS, GRID_FETCHES, GRID_LOADS, 3 * GRID_FETCHES
        if variant.split_sum:
            mads += BLEND_MADS[1]
        stages["grid"] = (mads, fetches, loads)
        floats += f
    elif not variant.split_only:
        mads, fetches, loads, f = _sh_sum(variant)
        if variant.split_sum:
            mads += BLEND_MADS[1]
        stages["sh"] = (mads, fetches, loads)
        floats += f
    if variant.split_sum:
        mads, fetches, loads, f = _split_sum(variant)
        stages["split_sum"] = (mads, fetches, loads)
        floats += f
    if variant.lamps:
        stages["lamps"] = _lamps(variant, int(lamp_count))
    return OperationCounts(
        multiply_adds=sum(s[0] for s in stages.values()),
        texel_fetches=sum(s[1] for s in stages.values()),
        uniform_loads=sum(s[2] for s in stages.values()),
        table_floats=floats,
        stages=stages,
    )
