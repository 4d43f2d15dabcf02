"""The shading rules (precompute/shading/policy.py) are written once and reach the GLSL only as
generated ``#define``s; the variant decisions (shading/variant.py) and the generated code's
operation counts (shading/codegen.py) follow them.

Pure Python: the GLSL is read as text (tests/drawing/test_gpu_draw.py compiles and runs it).
"""

import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from precompute.shading import codegen, policy, sh_rotation
from precompute.shading.variant import NOISE_BLENDER, NOISE_RAMP, NOISE_VALUE, Variant, choose_variant

REPO = Path(__file__).resolve().parents[2]  # tests/<feature>/this file
GLSL = REPO / "glsl"

#: Defines the shaders set for themselves: the library switch of the generated code, and the
#: glass buffers' geometric and further-layer passes (addon/gpu/shaders.py ``glass_shader_info``).
LIBRARY_DEFINES = {codegen.X90_GENERATED[0], "TF_GLASS_GEOMETRIC", "TF_GLASS_FURTHER"}


def code(text: str) -> str:
    """GLSL without its comments."""
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    return re.sub(r"//[^\n]*", " ", text)


def glsl_sources() -> dict:
    """Every chunk of glsl/ and the generated code, comments stripped."""
    sources = {p.name: code(p.read_text(encoding="utf-8")) for p in sorted(GLSL.glob("*.glsl"))}
    sources["generated"] = code(codegen.banded_source(codegen.MAX_L))
    return sources


def macro_name(name: str) -> str:
    return name.partition("(")[0]


def every_variant():
    fixed = ("l_max", "transmit", "refract", "noise_orco")
    switches = [f for f in Variant._fields if f not in fixed]  # the on/off ones
    for l_max, flags in itertools.product(
        (0, 2, 5, 12), itertools.product((False, True), repeat=len(switches))
    ):
        yield Variant(l_max, **dict(zip(switches, flags, strict=True))).normalised()
    for transmit in (1, 2):  # a transparent film's blend passes (TF_TRANSMIT), solid glass's TF_REFRACT
        for refract in (False, True):
            yield Variant(5, True, True, False, transmit=transmit, refract=refract).normalised()
    for noise in (NOISE_VALUE, NOISE_BLENDER, NOISE_RAMP):  # the noise sources per pixel (an int switch)
        for orco in (False, True):  # a Noise Texture at the positions or before a deformation
            yield Variant(5, True, True, False, thickness_noise=noise, noise_orco=orco).normalised()


def float_literals(text: str) -> list[float]:
    """The numbers written in GLSL code (ints and floats, identifiers and swizzles excluded)."""
    pattern = r"(?<![\w.])(\d+\.\d*|\.\d+|\d+)([eE][-+]?\d+)?(?![\w.])"
    return [float(m.group(0)) for m in re.finditer(pattern, text)]


# ----------------------------------------------------------------------------------------------
# (a) Every shading constant the GLSL uses comes from Python
# ----------------------------------------------------------------------------------------------
def test_every_tf_constant_the_glsl_uses_is_defined_by_policy_or_a_variant():
    sources = glsl_sources()
    used = set()
    defined_in_glsl = set()
    for text in sources.values():
        used |= set(re.findall(r"\bTF_[A-Z0-9_]+\b", text))
        defined_in_glsl |= set(re.findall(r"#define\s+(TF_[A-Z0-9_]+)", text))
        defined_in_glsl |= set(re.findall(r"\bconst\s+\w+\s+(TF_[A-Z0-9_]+)", text))
    from_policy = {macro_name(name) for name, _ in policy.glsl_defines()}
    from_variants = {name for v in every_variant() for name, _ in v.switches()}
    missing = used - defined_in_glsl - from_policy - from_variants - LIBRARY_DEFINES
    assert not missing, f"TF_ constants the GLSL uses but nothing defines: {sorted(missing)}"
    # …and the constants the GLSL defines itself are mathematics or counts derived from TF_L_MAX
    assert defined_in_glsl == {
        "TF_PI",
        "TF_HALF_PI",
        "TF_K_FULL",
        "TF_K_KEPT",
        "TF_BAND_MAX",
        "TF_K2",
        "TF_K20",
        "TF_SQRT_4PI",
    }
    # every rule the policy emits is read somewhere (no stale define)
    assert from_policy <= used, sorted(from_policy - used)
    # a variant's defines carry the rules
    assert set(policy.glsl_defines()) <= set(Variant(8, True, False, False).defines())


# ----------------------------------------------------------------------------------------------
# (b) None of the policy values is typed in glsl/
# ----------------------------------------------------------------------------------------------
def test_no_policy_value_is_typed_in_the_glsl():
    sources = {name: text for name, text in glsl_sources().items() if name != "generated"}
    names = {macro_name(name) for name, _ in policy.glsl_defines()}
    for file, text in sources.items():
        redefined = names & set(re.findall(r"#define\s+(TF_[A-Z0-9_]+)", text))
        assert not redefined, f"{file} defines {sorted(redefined)} itself"
    # the guards (small floats) never appear as numbers
    guards = [policy.MIN_COS, policy.MIN_ALPHA, policy.GIMBAL_SIN, policy.TANGENT_EPS, policy.X90_ZERO]
    guards += [policy.DIVISION_FLOOR, policy.MOMENT_EPS, policy.TIR_EPS, policy.AREA_MIN_AXIS]
    # …nor do the tuned bounds (a typed 100.0 for AREA_MAX_WIDTH was one, issue 35)
    guards += [policy.AREA_MAX_WIDTH, policy.AREA_UNIFORM_WIDTH, policy.HELPER_AXIS_MAX]
    for file, text in sources.items():
        typed = [x for x in float_literals(text) if any(np.isclose(x, g, rtol=1e-6, atol=0) for g in guards)]
        assert not typed, f"{file} types {typed}"
    # the integer rules are never compared against as numbers (preprocessor lines test TF_L_MAX)
    for file, text in sources.items():
        for line in text.splitlines():
            if line.strip().startswith("#"):
                continue
            for m in re.finditer(r"(?<![<>])[<>]=?\s*(\d+)(?![\w.])", line):
                assert int(m.group(1)) not in (policy.MAX_LAMPS, policy.LAMP_LEVEL), f"{file}: {line.strip()}"
    # the rules that are GLSL expressions are used through their macros
    split = sources["tf_split_sum.glsl"]
    (r_eff,) = [line for line in split.splitlines() if "r_eff =" in line]
    assert "TF_GRAZING(" in r_eff and "sqrt" not in r_eff and "pow" not in r_eff
    assert "TF_LADDER_POSITION(r)" in split and split.count("TF_LADDER_ROUGHNESS(") == 2
    assert "k < TF_MAX_LAMPS" in sources["tf_lamps.glsl"]


def test_the_emitted_expressions_are_what_the_shaders_were_written_with():
    """Bit-identical pictures: x^0.5 is ``sqrt``, x² a product (llvmpipe's pow differs)."""
    defines = dict(policy.glsl_defines())
    assert defines["TF_GRAZING(x)"] == "sqrt(x)"
    assert defines["TF_LADDER_ROUGHNESS(x)"] == "((x) * (x))"
    assert defines["TF_LADDER_POSITION(r)"] == "sqrt(r)"
    assert float(defines["TF_MIN_COS"]) == policy.MIN_COS == 1e-4
    assert float(defines["TF_GIMBAL_SIN"]) == 1e-7 and float(defines["TF_TANGENT_EPS"]) == 1e-6
    assert defines["TF_MAX_LAMPS"] == "8" and defines["TF_LAMP_LEVEL"] == "2"


# ----------------------------------------------------------------------------------------------
# (c) Changing a rule changes what the shaders get (and what numpy does)
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "constant, value, define, expected",
    [
        ("MIN_COS", 2e-4, "TF_MIN_COS", "0.0002"),
        ("MIN_ALPHA", 1e-3, "TF_MIN_ALPHA", "0.001"),
        ("GIMBAL_SIN", 1e-6, "TF_GIMBAL_SIN", "1e-06"),
        ("TANGENT_EPS", 1e-5, "TF_TANGENT_EPS", "1e-05"),
        ("MAX_LAMPS", 16, "TF_MAX_LAMPS", "16"),
        ("LAMP_LEVEL", 3, "TF_LAMP_LEVEL", "3"),
        ("GRAZING_EXPONENT", 0.25, "TF_GRAZING(x)", "pow(x, 0.25)"),
        ("GRAZING_EXPONENT", 1.0, "TF_GRAZING(x)", "(x)"),
        ("LEVEL_EXPONENT", 3, "TF_LADDER_ROUGHNESS(x)", "pow(x, 3.0)"),
        ("LEVEL_EXPONENT", 1, "TF_LADDER_POSITION(r)", "(r)"),
    ],
)
def test_sabotaged_policy_changes_the_emitted_define(monkeypatch, constant, value, define, expected):
    before = dict(Variant(5, True, False, False).defines())[define]
    monkeypatch.setattr(policy, constant, value)
    after = dict(policy.glsl_defines())[define]
    assert after == expected != before
    assert dict(Variant(5, True, False, False).defines())[define] == expected


def test_sabotaged_grazing_exponent_changes_numpy_too(monkeypatch):
    cos_o = np.array([0.25, 1.0])
    assert np.allclose(policy.effective_roughness(0.4, cos_o), [0.2, 0.4])
    monkeypatch.setattr(policy, "GRAZING_EXPONENT", 1.0)
    assert np.allclose(policy.effective_roughness(0.4, cos_o), [0.1, 0.4])


def test_every_tuning_link_names_a_section():
    """Each constant's one line of why links to its measurements in docs/tuning.md."""
    tuning = (REPO / "docs" / "tuning.md").read_text(encoding="utf-8")
    anchors = {
        re.sub(r"[^a-z0-9 -]", "", heading.strip().lower()).replace(" ", "-")
        for heading in re.findall(r"^## (.+)$", tuning, flags=re.M)
    }
    links = set()
    for path in (REPO / "precompute").rglob("*.py"):
        links |= set(re.findall(r"docs/tuning\.md#([a-z0-9-]+)", path.read_text(encoding="utf-8")))
    assert links and links <= anchors, sorted(links - anchors)
    for name in ("SH_BLEND", "WINDOW_WIDTH_PER_ROUGHNESS", "MOMENT_MIN_L", "MAX_LAMPS", "LAMP_LEVEL"):
        assert f"`policy.{name}" in tuning, name


# ----------------------------------------------------------------------------------------------
# Variants
# ----------------------------------------------------------------------------------------------
def facts(**overrides):
    base = dict(
        l_max=8,
        spectral=True,
        thickness_rows=17,
        has_thickness=True,
        display=True,
        prefiltered=True,
        sh_weight=0.35,
        lamp_count=3,
        film=True,
        film_ubo=False,
        table_ubo=False,
    )
    base.update(overrides)
    return base


def test_choose_variant_follows_the_draws_rules():
    v = choose_variant(**facts())
    assert v == Variant(8, True, True, True, split_sum=True, lamps=True)
    assert v.moment == (8 >= policy.MOMENT_MIN_L)
    # one thickness row, or no attribute: the 1-D variant
    assert not choose_variant(**facts(thickness_rows=1)).vary_thickness
    assert not choose_variant(**facts(has_thickness=False)).vary_thickness
    # the split sum needs a prefiltered World and an SH weight below 1; weight 0 compiles SH out
    assert not choose_variant(**facts(prefiltered=False)).split_sum
    assert not choose_variant(**facts(sh_weight=1.0)).split_sum
    glossy = choose_variant(**facts(sh_weight=0.0, l_max=2))
    assert glossy.split_only and glossy.moment  # split-only films always read the moment
    assert not choose_variant(**facts(l_max=2)).moment  # combined below MOMENT_MIN_L: not
    # the lamp loop needs lamps and a film table; the film's buffer only with the loop
    assert not choose_variant(**facts(lamp_count=0)).lamps
    assert not choose_variant(**facts(film=False, film_ubo=True)).film_ubo
    assert choose_variant(**facts(film_ubo=True)).film_ubo
    assert choose_variant(**facts(table_ubo=True)).table_ubo


def test_variant_switches_are_the_defines_the_shader_declares():
    v = Variant(
        12, True, True, True, split_sum=True, table_ubo=True, split_only=True, lamps=True, film_ubo=True
    )
    assert [name for name, _ in v.switches()] == [
        "TF_L_MAX",
        "TF_SPECTRAL",
        "TF_VARY_THICKNESS",
        "TF_DISPLAY_SRGB",
        "TF_SPLIT_SUM",
        "TF_SPLIT_ONLY",
        "TF_MOMENT",
        "TF_LAMPS",
        "TF_FILM_UBO",
        "TF_TABLE_UBO",
    ]
    assert dict(v.switches())["TF_L_MAX"] == "12"
    assert Variant(3, False, False, False).switches() == (("TF_L_MAX", "3"),)
    # normalised: flags that need another are cleared; equal variants hash alike
    odd = Variant(np.int64(4), 1, 0, 0, split_only=True, film_ubo=True).normalised()
    assert odd == Variant(4, True, False, False) and type(odd.l_max) is int
    assert len({Variant(2, True, False, False), Variant(2, True, False, False, False)}) == 1


# ----------------------------------------------------------------------------------------------
# Operation counts of the generated code
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("l_max", [3, 5, 8, 12])
def test_operation_counts_count_the_generated_terms(l_max):
    """The generated sum's rotation work equals the numpy blocks' non-zero entries; the table
    reads are taps × layers per coefficient."""
    nonzero = sum(
        int(np.sum(np.abs(b) > policy.X90_ZERO))
        for s in (1, -1)
        for b in sh_rotation.x_rotation_bands(l_max, s)[1:]
    )
    pairs = l_max * (l_max + 1) // 2
    k = (l_max + 1) * (l_max + 2) // 2
    for spectral, vary in itertools.product((False, True), repeat=2):
        c = codegen.operation_counts(Variant(l_max, spectral, vary, False))
        taps, layers = (4 if vary else 2), (3 if spectral else 1)
        rotation = 3 * nonzero + 12 * 3 * pairs + 4 * 3 * (l_max - 1)
        assert c.multiply_adds == rotation + 3 * taps * layers * k + (9 if spectral else 3) * k
        assert c.texel_fetches == taps * layers * k and c.table_floats == 3 * taps * layers * k
        assert c.uniform_loads == (l_max + 1) ** 2 + nonzero  # the World's SH and the X(±90°) entries


def test_operation_counts_move_reads_between_textures_and_buffers():
    texture = codegen.operation_counts(Variant(5, True, True, False, split_sum=True, lamps=True))
    buffers = codegen.operation_counts(
        Variant(5, True, True, False, split_sum=True, lamps=True, table_ubo=True, film_ubo=True)
    )
    assert buffers.multiply_adds == texture.multiply_adds
    # everything but the prefiltered World's one fetch moves to uniform loads
    assert buffers.texel_fetches == 1
    assert buffers.uniform_loads - texture.uniform_loads == texture.texel_fetches - buffers.texel_fetches
    # split only: no SH work; the moment adds a fetch
    glossy = codegen.operation_counts(Variant(12, True, False, False, split_sum=True, split_only=True))
    assert set(glossy.stages) == {"split_sum"} and glossy.texel_fetches == 1 + 1 + 3 * 2
    # the lamp loop scales with the lamp count
    one = codegen.operation_counts(Variant(2, False, False, False, lamps=True), lamp_count=1)
    two = codegen.operation_counts(Variant(2, False, False, False, lamps=True), lamp_count=2)
    assert two.multiply_adds - one.multiply_adds == codegen.LAMP_MADS + 3 + 3 * 2


def test_a_split_only_film_is_baked_at_order_0_with_the_same_albedo():
    """drawn_material: a glossy film without a diffuse base (drawn by the split sum alone, which
    reads entry 0) gets the automatic order 0, and its entry 0 is the l = 12 table's to float
    rounding; a blended or rough film, a diffuse base and an order set by hand are kept."""
    import dataclasses

    from precompute.bakes import bake
    from precompute.materials.material import Quality, preset

    quality = Quality(view_samples=8, thickness_samples=6, wavelength_count=32)
    glossy = dataclasses.replace(preset("soap_film"), quality=quality)
    assert policy.sh_weight(glossy.roughness) == 0.0
    drawn = policy.drawn_material(glossy)
    assert drawn.quality.sh_order == 0 and drawn.layers == glossy.layers
    full, zero = bake.bake(glossy), bake.bake(drawn)
    assert full.sh_order == 12 and zero.sh_order == 0 and zero.data.shape[2] == 1
    np.testing.assert_allclose(zero.data[:, :, 0], full.data[:, :, 0], rtol=0, atol=1e-12)
    assert np.abs(full.data[:, :, 1:]).max() > 1e-3  # the entries left out are not zero
    blended = glossy.with_(roughness=policy.SH_BLEND[0] + 0.01)
    hand = glossy.with_(quality=dataclasses.replace(quality, sh_order=4))
    diffuse = glossy.with_(base_color=(0.5, 0.5, 0.5))
    for kept in (blended, hand, diffuse):
        assert policy.drawn_material(kept) is kept
