"""The numpy mirror of the shader, listed once: which numpy function mirrors which GLSL function.

:data:`MIRROR` is the one list. ``tests/test_mirror.py`` checks that every numpy name imports and
that every GLSL function is defined in the chunk named (or in the generated code), and that
docs/ARCHITECTURE.md holds :func:`markdown_table` between its two ``mirror table`` markers
(``scripts/mirror_table.py`` writes it there). The per-pixel tests (tests/drawing/test_gpu_draw.py and
its neighbours) draw the GLSL on Mesa and compare it with these numpy functions.
"""

from __future__ import annotations

from typing import NamedTuple


class Mirror(NamedTuple):
    """One row: numpy functions (dotted, below ``precompute``) and the GLSL that mirrors them.

    ``chunk`` is a file of ``glsl/``, ``"generated"`` (:func:`.codegen.banded_source`) or
    ``"defines"`` (the ``#define`` lines a variant is compiled with); ``glsl`` the functions
    defined there (empty for defines). The notes are what the table says beside the names.
    """

    numpy: tuple[str, ...]
    chunk: str
    glsl: tuple[str, ...]
    numpy_note: str = ""
    glsl_note: str = ""


#: Every numpy function the shader mirrors, with its GLSL.
MIRROR = (
    Mirror(
        ("brdf.alpha_from_roughness", "brdf.D_ggx", "brdf.lambda_ggx", "brdf.G2_smith_height_correlated"),
        "tf_brdf.glsl",
        ("tf_alpha_from_roughness", "tf_d_ggx", "tf_lambda_ggx", "tf_ggx_view", "tf_ggx_weight"),
        glsl_note="GGX D and Smith written once, for the lamps and the lights",
    ),
    Mirror(
        ("shading.frame.view_aligned_frame", "shading.frame.zyz_from_frame"),
        "tf_frame.glsl",
        ("tf_view_aligned_frame", "tf_zyz_from_frame"),
    ),
    Mirror(
        ("shading.sh_rotation.local_coefficients",),
        "tf_sh_rotate.glsl",
        ("tf_local_coefficients_direct",),
        numpy_note="z-y-z, X(±90°) band blocks",
        glsl_note="l_max ≤ 2, straight from the frame rows; l_max ≥ 3: the generated `tf_banded_sum`",
    ),
    Mirror(
        ("shading.table.lerp_index", "shading.table.lookup", "shading.table.thickness_position"),
        "tf_table.glsl",
        ("tf_lerp_index", "tf_table_lerp", "tf_table_fetch"),
    ),
    Mirror(("shading.sh_sum.shade_sh",), "tf_shade.glsl", ("tf_shade_at",)),
    Mirror(
        ("materials.noise.value_noise",),
        "tf_noise.glsl",
        ("tf_noise_hash01", "tf_value_noise"),
        glsl_note="the Noise thickness source per pixel (`TF_THICKNESS_NOISE`)",
    ),
    Mirror(
        (
            "materials.perlin.NoiseSpec",
            "materials.perlin.noise_texture",
            "materials.perlin.fbm",
            "materials.perlin.perlin",
            "materials.perlin.hash3",
            "materials.perlin.hash4",
            "materials.ramp.lookup",
        ),
        "tf_perlin.glsl",
        (
            "tf_perlin_hash3",
            "tf_perlin_hash",
            "tf_perlin3",
            "tf_perlin",
            "tf_fbm",
            "tf_ramp",
            "tf_noise_texture",
        ),
        glsl_note="a Noise Texture per pixel (`TF_THICKNESS_PERLIN`): Blender Noise, a linked one, "
        "through a Color Ramp's table (`TF_THICKNESS_RAMP`)",
    ),
    Mirror(
        (
            "shading.split_sum.shade_split_sum",
            "shading.split_sum.shade_combined",
            "shading.split_sum.level_blend",
            "shading.split_sum.dominant_cosine",
        ),
        "tf_split_sum.glsl",
        ("tf_prefiltered_lookup", "tf_shade_split_sum_at", "tf_shade_combined"),
    ),
    Mirror(
        ("shading.lamps.shade", "shading.lamps.lit_pixels"),
        "tf_lamps.glsl",
        ("tf_shade_lamps", "tf_film_at", "tf_film_response", "tf_film_multiscatter"),
    ),
    Mirror(
        (
            "shading.transmit.wall",
            "shading.transmit.white_reflectance",
            "shading.transmit.shade",
            "shading.transmit.fresnel_dielectric",
            "shading.transmit.solid_exit",
        ),
        "tf_transmit.glsl",
        ("tf_wall", "tf_film_white", "tf_fresnel_dielectric", "tf_solid_exit"),
        numpy_note="a transparent film's T and S; [transparent-films.md](transparent-films.md)",
        glsl_note="`TF_TRANSMIT`",
    ),
    Mirror(
        ("shading.transmit.inside_path", "shading.transmit.inside_reflections", "shading.transmit.world_fit"),
        "tf_transmit.glsl",
        ("tf_inside_step", "tf_wall_rt"),
        numpy_note="a closed thin wall's reflections inside: the path on the sphere, each hit's "
        "wall at its own thickness",
        glsl_note="`TF_TRANSMIT` = 2 with `TF_SPLIT_SUM`; `tf_wall_inside`, `tf_inside_thickness` "
        "in `tf_main_frag.glsl`",
    ),
    Mirror(
        (
            "shading.glass.refract.exit_ray",
            "shading.glass.refract.march",
            "shading.glass.refract.seen",
            "shading.glass.refract.sharp",
            "shading.glass.refract.bilinear",
        ),
        "tf_refract.glsl",
        (
            "tf_solid_exit_ray",
            "tf_refract_march",
            "tf_behind_depth_at",
            "tf_behind_colour_at",
            "tf_behind_bilinear",
        ),
        numpy_note="solid glass refracting the scene behind: the ray through the glass, "
        "its screen-space march, the hit's depth and colour between texel centres (Catmull–Rom "
        "over one surface, else bilinear)",
        glsl_note="`TF_REFRACT`; `tf_refracted` in `tf_main_frag.glsl`",
    ),
    Mirror(
        (
            "shading.glass.glass_exit.glass_texel",
            "shading.glass.glass_exit.geometric_texel",
            "shading.glass.glass_exit.from_octahedral",
            "shading.glass.glass_exit.valid_normal",
            "shading.glass.glass_exit.mesh_exit",
            "shading.glass.glass_exit.branch_exit",
            "shading.glass.refract.inner_cosine",
            "shading.transmit.back_reflectance",
        ),
        "tf_glass_exit.glsl",
        (
            "tf_glass_decode",
            "tf_oct_decode",
            "tf_valid_normal",
            "tf_glass_face",
            "tf_glass_span",
            "tf_glass_outside",
            "tf_glass_face_near",
            "tf_glass_march",
            "tf_glass_enter",
            "tf_glass_follow",
            "tf_glass_refract_in",
            "tf_glass_exit",
            "tf_inner_cosine",
            "tf_glass_back_r",
        ),
        numpy_note="solid glass's exit through its real mesh (the glass buffers, two layers deep), "
        "total internal reflection, the film seen from inside, smooth-shaded faces met as Cycles "
        "meets them, a concave glass's further spans entered again, its far wall's mirror and inner "
        "reflection followed back through it",
        glsl_note="`TF_REFRACT` with the glass buffers; `tf_glass_glint` and `tf_glass_branch` in "
        "`tf_main_frag.glsl`",
    ),
    Mirror(
        ("shading.glass.tails.path_spread", "shading.glass.tails.lamp_tails"),
        "tf_glass_tails.glsl",
        ("tf_glass_spread", "tf_lamp_tails"),
        numpy_note="rough solid glass: how far a path spreads, and the World's lamps in its tails",
        glsl_note="`TF_REFRACT` with `TF_LAMPS`; read by `tf_refract_seen` in `tf_main_frag.glsl` for "
        "the refracted path and the glints",
    ),
    Mirror(
        ("shading.glass.probe.lookup",),
        "tf_probe.glsl",
        ("tf_probe_seen",),
        numpy_note="the scene around solid glass, seen from its centre, for paths that leave the picture",
        glsl_note="`TF_REFRACT`; read by `tf_refract_seen` and `tf_scene_mirror` in `tf_main_frag.glsl` "
        "where the march meets nothing",
    ),
    Mirror(
        ("shading.glass.glass_exit.octahedral",),
        "tf_glass_frag.glsl",
        ("tf_oct_encode",),
        numpy_note="a glass face's geometric normal in two floats",
        glsl_note="`TF_GLASS_GEOMETRIC`, the glass buffers' second pass",
    ),
    Mirror(
        ("shading.radiance_grid.lookup", "shading.radiance_grid.coordinates"),
        "tf_radiance_grid.glsl",
        ("tf_shade_grid",),
        numpy_note="the grid itself: `radiance_grid.build`, exact at its nodes; in the split-sum/SH "
        "hand-over `lobe_grid.build`, the exact film lobe integrated against the World's panorama",
        glsl_note="`TF_RADIANCE_GRID`: `tf_shade_at` reads the grid instead of the SH sum",
    ),
    Mirror(
        ("shading.lobe_grid.lookup_basis",),
        "tf_grid_basis.glsl",
        ("tf_grid_basis_node", "tf_shade_grid_basis"),
        numpy_note="the grid: `lobe_grid.build_basis`, film-free blocks weighted by hats over u "
        "(`lobe_grid.hat_weights`, `policy.GRID_HATS`)",
        glsl_note="`TF_RADIANCE_GRID` with `TF_VARY_THICKNESS`: a varying film's SH half in the hand-over",
    ),
    Mirror(
        (
            "shading.lights.shade",
            "shading.lights.light_samples",
            "shading.lights.area_lobe",
            "shading.lights.lobe_cells",
            "shading.lights.sample_weight",
            "shading.lights.spot_attenuation",
            "shading.lights.spread_attenuation",
        ),
        "tf_lights.glsl",
        (
            "tf_shade_lights",
            "tf_area_light",
            "tf_lobe_edges",
            "tf_light_sample",
            "tf_spot_attenuation",
            "tf_spread_attenuation",
        ),
    ),
    Mirror(
        ("colour.display_lut.shaper", "colour.display_lut.apply"),
        "tf_display.glsl",
        ("tf_display_shaper", "tf_display_lut_apply"),
        glsl_note="`TF_DISPLAY_LUT`",
    ),
    Mirror(
        ("shading.codegen.banded_source", "shading.codegen.operation_counts"),
        "generated",
        ("tf_banded_sum",),
        numpy_note="all generated GLSL, and the operation counts of the effect plan",
    ),
    Mirror(
        ("shading.policy.glsl_defines",),
        "defines",
        (),
        numpy_note="every shading rule, each with one line of why",
        glsl_note="the `TF_` rules: `TF_MIN_COS`, `TF_MAX_LAMPS`, `TF_AREA_MAX_WIDTH`, …",
    ),
    Mirror(
        ("shading.variant.Variant", "shading.variant.choose_variant"),
        "defines",
        (),
        glsl_note="the variant switches: `TF_L_MAX`, `TF_SPECTRAL`, `TF_SPLIT_SUM`, `TF_LAMPS`, "
        "`TF_LIGHTS`, `TF_TRANSMIT`, `TF_RADIANCE_GRID`, …",
    ),
)

#: The lines around the table in docs/ARCHITECTURE.md.
BEGIN = "<!-- mirror table: precompute/shading/mirror.py (scripts/mirror_table.py writes it) -->"
END = "<!-- end of the mirror table -->"


def _names(names) -> str:
    return ", ".join(f"`{name}`" for name in names)


def _with_note(text: str, note: str) -> str:
    return f"{text} ({note})" if note else text


def markdown_table(rows=MIRROR) -> str:
    """The mirror as the Markdown table docs/ARCHITECTURE.md shows (no trailing newline)."""
    lines = ["| numpy (below `precompute`) | GLSL |", "|---|---|"]
    for row in rows:
        if row.chunk == "defines":
            glsl = "the `#define`s"
        elif row.chunk == "generated":
            glsl = f"generated: {_names(row.glsl)}"
        else:
            glsl = f"`{row.chunk}`: {_names(row.glsl)}"
        lines.append(
            f"| {_with_note(_names(row.numpy), row.numpy_note)} | {_with_note(glsl, row.glsl_note)} |"
        )
    return "\n".join(lines)


def replace_table(text: str, rows=MIRROR) -> str:
    """``text`` (docs/ARCHITECTURE.md) with the lines between :data:`BEGIN` and :data:`END` replaced
    by :func:`markdown_table`; ``ValueError`` when a marker is missing."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        raise ValueError(f"the mirror table's markers are missing: {BEGIN!r} … {END!r}")
    return text[: start + len(BEGIN)] + "\n" + markdown_table(rows) + "\n" + text[end:]
