"""Effect plan: what a material (and a scene) needs simulated, what that costs, and why.

A :class:`MaterialPlan` states, for one :class:`~precompute.materials.material.Material`, which effects
are switched on and therefore which code runs and which table dimensions exist:

==================  ==========================================================================
effect              on when … / what it switches on
==================  ==========================================================================
interference        a layer with thickness > 0 (or a varying top layer). Off: the bare
                    substrate — Fresnel only (bake's no-layer path).
stack               ≥ 2 layers thicker than 0: Rouard's transfer recursion
                    (:func:`precompute.optics.stack.stack_reflectance`). Off with one film:
                    Airy's closed form (:mod:`precompute.optics.airy`, or Glassner's eq. 4).
conductor           the substrate absorbs (k > 0 somewhere in 360–830 nm): complex Fresnel at
                    the substrate; Cycles-parity multiscatter takes F_avg = 1.
dispersion          some medium's index depends on λ (Cauchy with B or C ≠ 0, Sellmeier,
                    tabulated, metals). Off: every medium is a :class:`ConstantIndex` and no
                    dispersion model is evaluated.
thickness_axis      the top layer's thickness varies: a 2-D table (T > 1 rows), the
                    ``TF_VARY_THICKNESS`` shader variant and a per-vertex thickness attribute
                    (4 table taps per pixel instead of 2). Off: a 1-D table (T = 1).
illuminant_lines    a fluorescent illuminant (FL1–FL12): one extra wavelength node per emission
                    line (Composite Model) besides the grid.
diffuse_base        a base colour under the film: the diffuse kernel and the film's
                    transmission are added to the m = 0 coefficients (no extra table size).
multiscatter        Kulla–Conty energy compensation (roughness > 0 and multiscatter ≠ "none").
==================  ==========================================================================

It also carries the resolved :class:`precompute.bakes.planner.Plan` (SH order from roughness, view
angles, thickness rows, wavelengths), the table's shape and bytes, an estimated bake time
(:data:`.cost_model.TIME_MODEL`), the per-pixel shader cost and shader variant defines, and a reason for
every choice. The shader cost is the draw's own: the
:class:`~precompute.shading.variant.Variant` that :func:`~precompute.shading.variant.choose_variant`
picks from the material's facts (as the add-on's draw does), costed by
:func:`precompute.shading.codegen.operation_counts` on the code that variant runs.
:func:`scene_plan` combines the materials of a scene: identical materials share one table (same
:func:`precompute.tables.table_io.content_key` as the add-on's cache), shared microfacet kernels are cold
only once, cached tables cost nothing. Its World order is the one drawn: the add-on projects the
World to l = MAX_ORDER and windows it to each material's l_max, so the highest l_max among the
scene's materials; the World's own content order (:func:`world_content_order`) is reported beside
it. :func:`.plan_text.format_plan` prints either plan for people.

Nothing here bakes: :func:`material_plan` resolves :func:`precompute.bakes.planner.plan` (whose
automatic SH order is read from a table, :data:`precompute.bakes.sh_order.ORDER_BREAKPOINTS`) and
evaluates each medium's index at three wavelengths: ≈ 1 ms, fit for the main thread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..bakes import planner, quadrature
from ..colour.film_colour import FILM_SAMPLES
from ..materials.material import MAX_SH_ORDER, Material
from ..optics.dispersion import is_dispersive
from ..shading import policy
from ..shading.variant import Variant, choose_variant, fits_uniform_buffer
from .cost_model import ShaderCost, bake_time_breakdown, estimate_u_degree, shader_cost

EFFECTS = (
    "interference",
    "stack",
    "conductor",
    "dispersion",
    "thickness_axis",
    "illuminant_lines",
    "diffuse_base",
    "multiscatter",
)

#: Highest SH order a table or the World can have (material.MAX_SH_ORDER, the shaders' MAX_L).
MAX_ORDER = MAX_SH_ORDER
#: The World's content order is the smallest l whose band-energy tail Σ_{l' > l} |c_l'|² is below
#: this fraction of the total energy (see :func:`world_content_order`).
WORLD_TAIL = 0.01
#: Wavelengths at which a medium is checked for absorption (the spectral grid's ends and middle).
_PROBE_NM = np.array([360.0, 550.0, 830.0])


def _shading_words(variant: Variant, weight: float) -> str:
    """How the variant shades, in words, for the plan's reasons."""
    if variant.grid:  # the SH half from the outgoing-radiance grid: 4 fetches at any order
        path = f"split sum × {1 - weight:.2f} + grid × {weight:.2f}" if variant.split_sum else "radiance grid"
    elif not variant.split_sum:
        path = "SH only"
    elif variant.split_only:
        path = "split sum only (SH weight 0)"
    else:
        path = f"split sum × {1.0 - weight:.2f} + SH × {weight:.2f}"
    if variant.split_sum:
        path += ", albedo at the dominant direction" if variant.moment else ", albedo at the view angle"
    if variant.lamps:
        path += f", lamp loop (≤ {policy.MAX_LAMPS} lamps)"
    return path


# ----------------------------------------------------------------------------------------------
# Material plan
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MaterialPlan:
    """What one material needs: effects, resolved quality, table, costs and the reasons."""

    material: Material  # bake.table_material of the material planned: what its table uses
    key: str  # bake.table_key(material): equal keys share one table
    effects: dict  # name → bool, the names of EFFECTS in order
    plan: planner.Plan
    wavelength_nodes: int  # grid + emission lines
    line_count: int
    u_degree: int  # estimated Chebyshev nodes per interval
    u_tried: tuple  # degrees the bake is expected to try
    table_shape: tuple
    table_bytes: int  # float32, as baked and stored
    texture_bytes: int  # RGBA32F texture on the GPU (layers × T × A × 16)
    bake_seconds: float  # estimated, cold kernels (a first bake in a session)
    bake_breakdown: dict
    shader: ShaderCost
    reasons: dict = field(default_factory=dict)

    @property
    def kernel_key(self) -> tuple:
        """The :func:`bake.microfacet_kernel` cache entry the bake will use."""
        return (
            round(float(self.material.roughness), 9),
            self.plan.sh_order,
            self.plan.view_samples,
            self.u_degree,
        )

    def bake_time(self, *, kernel_cold: bool, order_kernel_cold: bool) -> dict:
        """Estimated seconds per stage of this material's bake (and "total"), with the microfacet
        kernel and the SH order's kernel cold or warm (:func:`.cost_model.bake_time_breakdown`)."""
        return bake_time_breakdown(
            self.material,
            self.plan,
            self.u_degree,
            self.u_tried,
            self.wavelength_nodes,
            kernel_cold=kernel_cold,
            order_kernel_cold=order_kernel_cold,
        )

    def to_dict(self) -> dict:
        """JSON-ready summary (for ``--json`` outputs)."""
        return {
            "key": self.key,
            "effects": dict(self.effects),
            "sh_order": self.plan.sh_order,
            "view_samples": self.plan.view_samples,
            "thickness_samples": self.plan.thickness_samples,
            "wavelength_count": self.plan.wavelength_count,
            "wavelength_nodes": self.wavelength_nodes,
            "u_degree": self.u_degree,
            "table_shape": list(self.table_shape),
            "table_bytes": self.table_bytes,
            "texture_bytes": self.texture_bytes,
            "bake_seconds": self.bake_seconds,
            "bake_breakdown": dict(self.bake_breakdown),
            "shader": {
                "variant": self.shader.draw._asdict(),
                "defines": dict(self.shader.defines),
                "floats_fetched": self.shader.floats_fetched,
                "texel_fetches": self.shader.texel_fetches,
                "uniform_loads": self.shader.uniform_loads,
                "multiply_adds": self.shader.multiply_adds,
            },
            "reasons": dict(self.reasons),
        }


def _medium_names(material: Material) -> list[str]:
    return ["ambient"] + [f"layer {i + 1}" for i in range(len(material.layers))] + ["substrate"]


def _kind(model) -> str:
    name = type(model).__name__
    return {
        "ConstantIndex": "constant",
        "CauchyIndex": "Cauchy",
        "SellmeierIndex": "Sellmeier",
        "TabulatedIndex": "tabulated",
        "TabulatedMetal": "tabulated metal",
    }.get(name, name)


def _film_effects(material: Material, reasons: dict) -> tuple[bool, bool]:
    """(interference, stack) with their reasons."""
    layers = material.layers
    thick = [
        i for i, layer in enumerate(layers) if float(layer.thickness_nm) > 0.0 or (i == 0 and material.varies)
    ]
    if not layers:
        reasons["interference"] = "no film layers: the bare substrate, Fresnel only (bake's no-layer path)"
        reasons["stack"] = "no film"
        return False, False
    if not thick:
        reasons["interference"] = (
            f"every layer is 0 nm thick: optically the bare substrate, so the bake drops the "
            f"{len(layers)} layer(s) and takes the bare-interface path"
        )
        reasons["stack"] = "no layer thicker than 0 nm"
        return False, False
    top = f"top {float(layers[0].thickness_nm):g} nm"
    if material.varies:
        lo, hi = material.thickness_range_nm
        top = f"top layer varying {lo:g}–{hi:g} nm"
    reasons["interference"] = (
        f"{len(thick)} film layer(s) thicker than 0 nm ({top}): wave optics per wavelength"
    )
    zeros = len(layers) - len(thick)
    zero_note = (
        f"; {zeros} layer(s) of 0 nm are still evaluated by the bake (reflectance_sweep keeps them)"
        if zeros
        else ""
    )
    if len(thick) >= 2:
        reasons["stack"] = (
            f"{len(thick)} layers → transfer recursion (optics.stack.stack_reflectance), "
            f"{len(layers) + 1} interfaces per evaluation{zero_note}"
        )
        return True, True
    if material.model == "glassner2000":
        reasons["stack"] = "single film, model glassner2000 → Glassner (2000) eq. 4 closed form"
    else:
        reasons["stack"] = "single film → Airy closed form (optics.airy), never the general stack code"
    if zeros:
        # Needed: one film. The bake still dispatches all N ≥ 2 media to the stack recursion.
        reasons["stack"] += zero_note + " (through the stack recursion)"
    return True, False


def material_plan(
    material: Material,
    *,
    kernel_cold: bool = True,
    order_kernel_cold: bool | None = None,
    prefiltered: bool = True,
    world_lamps: bool = False,
    table_ubo: bool = False,
) -> MaterialPlan:
    """The :class:`MaterialPlan` of ``material`` (no bake; see the module docstring).

    ``kernel_cold``: whether the bake will have to compute its microfacet kernel (True for the
    first bake of a roughness/order/view count in a session). ``order_kernel_cold``: whether the
    automatic SH order's kernel is new (default: same as ``kernel_cold``).

    The draw's facts that are not the material's, for its shader variant: ``prefiltered``, the
    World has a prefiltered panorama (the split sum runs; the add-on's viewport always has one);
    ``world_lamps``, the World has lamps and the material shades them (its "World Lamps" on; never
    under a diffuse base); ``table_ubo``, the device draws tables from uniform buffers
    (policy.TABLE_UBO_DEVICES: software rasterisers; default a GPU).
    """
    if order_kernel_cold is None:
        order_kernel_cold = kernel_cold
    material = planner.table_material(material)  # what the table uses: an unused value costs nothing
    p = planner.plan(material)
    reasons: dict[str, str] = {}
    interference, stack = _film_effects(material, reasons)

    indices = material.indices()
    names = _medium_names(material)
    substrate = np.asarray(indices[-1].index(_PROBE_NM))
    conductor = bool(np.any(substrate.imag > 0.0))
    n550 = substrate[1]
    if conductor:
        reasons["conductor"] = (
            f"absorbing substrate ({_kind(indices[-1])}, N = {n550.real:.3g} + {n550.imag:.3g}i at 550 nm): "
            "complex Fresnel at the substrate"
        )
    else:
        reasons["conductor"] = f"dielectric substrate (n = {n550.real:.4g} at 550 nm)"

    dispersive = [f"{n} ({_kind(m)})" for n, m in zip(names, indices, strict=True) if is_dispersive(m)]
    dispersion = bool(dispersive)
    if dispersion:
        reasons["dispersion"] = (
            "index depends on λ for " + ", ".join(dispersive) + ": evaluated per wavelength"
        )
    else:
        reasons["dispersion"] = "every medium has a constant index: no dispersion model is evaluated"

    thickness_axis = material.varies
    if thickness_axis:
        lo, hi = material.thickness_range_nm
        reasons["thickness_axis"] = (
            f"top layer varies {lo:g}–{hi:g} nm: 2-D table with {p.thickness_samples} rows, "
            "shader TF_VARY_THICKNESS (4 taps) and a per-vertex thickness attribute (read per pixel "
            "from a thickness map or the Noise source where one drives it)"
        )
    else:
        reasons["thickness_axis"] = "constant thickness: 1-D table (T = 1), 2 taps per coefficient"

    illuminant_lines = quadrature.is_line_spectrum(material.illuminant)
    line_count = 0
    if illuminant_lines:
        line_count = len(quadrature._illuminant_composite(material.illuminant).spike_wavelengths_nm)
        reasons["illuminant_lines"] = (
            f"{material.illuminant} has {line_count} emission lines: one wavelength node at each "
            f"(Composite Model) besides the {p.wavelength_count}-sample grid"
        )
    else:
        reasons["illuminant_lines"] = f"illuminant {material.illuminant} is smooth: the wavelength grid only"

    diffuse_base = material.base_color is not None
    if diffuse_base:
        rgb = ", ".join(f"{v:.3g}" for v in material.base_color)
        reasons["diffuse_base"] = (
            f"diffuse base ({rgb}) under the film: diffuse kernel and film transmission added to the "
            "m = 0 coefficients (table size unchanged)"
        )
    else:
        reasons["diffuse_base"] = "no diffuse base: specular film only"

    multiscatter = material.multiscatter != "none" and material.roughness > 0.0
    if multiscatter:
        reasons["multiscatter"] = (
            f"multiscatter {material.multiscatter!r} at roughness {material.roughness:g}: "
            "Kulla–Conty energy compensation per view angle"
        )
    else:
        why = "roughness 0" if material.roughness <= 0.0 else "multiscatter 'none'"
        reasons["multiscatter"] = f"off ({why})"

    effects = {
        "interference": interference,
        "stack": stack,
        "conductor": conductor,
        "dispersion": dispersion,
        "thickness_axis": thickness_axis,
        "illuminant_lines": illuminant_lines,
        "diffuse_base": diffuse_base,
        "multiscatter": multiscatter,
    }
    for name, reason in p.reasons.items():
        reasons[name] = reason

    spectral = material.colour_mode == "spectral"
    k = (p.sh_order + 1) * (p.sh_order + 2) // 2
    shape = (
        (p.thickness_samples, p.view_samples, k, 3, 3)
        if spectral
        else (p.thickness_samples, p.view_samples, k, 3)
    )
    table_bytes = 4 * math.prod(shape)
    layers = 3 * k if spectral else k
    texture_bytes = layers * p.thickness_samples * p.view_samples * 16
    reasons["colour_mode"] = (
        "spectral: a 3×3 matrix per coefficient (9 floats, TF_SPECTRAL)"
        if spectral
        else "per_channel (Cycles' film model): 3 floats per coefficient"
    )

    degree, tried, degree_reason = estimate_u_degree(material)
    reasons["u_nodes"] = degree_reason
    w_nodes = p.wavelength_count + line_count
    breakdown = bake_time_breakdown(
        material, p, degree, tried, w_nodes, kernel_cold=kernel_cold, order_kernel_cold=order_kernel_cold
    )
    parts = ", ".join(f"{name} {sec:.2g} s" for name, sec in breakdown.items() if name != "total" and sec > 0)
    reasons["bake_time"] = f"≈ {breakdown['total']:.2g} s ({parts})"

    weight = policy.sh_weight(material.roughness)
    film = world_lamps and material.base_color is None
    draw = choose_variant(
        l_max=p.sh_order,
        spectral=spectral,
        thickness_rows=p.thickness_samples,
        has_thickness=thickness_axis,
        display=False,
        prefiltered=prefiltered,
        sh_weight=weight,
        lamp_count=policy.MAX_LAMPS if film else 0,
        film=film,
        film_ubo=fits_uniform_buffer(4 if spectral else 2, p.thickness_samples, FILM_SAMPLES),
        table_ubo=table_ubo and fits_uniform_buffer(layers, p.thickness_samples, p.view_samples),
        grid=True,  # policy.uses_grid decides: constant thickness, l_max ≥ GRID_MIN_L
    )
    cost = shader_cost(draw)
    stages = ", ".join(f"{name} {n[0]}" for name, n in cost.stages.items())
    reasons["shader"] = (
        f"l_max {p.sh_order} from the table, roughness {material.roughness:g} → "
        f"{_shading_words(draw, weight)}; {cost.taps} taps × {cost.channels} floats per table read, "
        f"{cost.floats_fetched} floats fetched, {cost.texel_fetches} texel fetches, "
        f"{cost.uniform_loads} uniform loads, {cost.multiply_adds} multiply-adds per pixel ({stages})"
    )
    return MaterialPlan(
        material=material,
        key=planner.table_key(material),
        effects=effects,
        plan=p,
        wavelength_nodes=w_nodes,
        line_count=line_count,
        u_degree=degree,
        u_tried=tried,
        table_shape=shape,
        table_bytes=table_bytes,
        texture_bytes=texture_bytes,
        bake_seconds=breakdown["total"],
        bake_breakdown=breakdown,
        shader=cost,
        reasons=reasons,
    )


# ----------------------------------------------------------------------------------------------
# Scene plan
# ----------------------------------------------------------------------------------------------
def band_energies(coeffs) -> np.ndarray:
    """Σ_m Σ_rgb c_lm² per band l of SH coefficients ((L+1)², C)."""
    c = np.asarray(coeffs, dtype=np.float64)
    if c.ndim == 1:
        c = c[:, None]
    l_avail = math.isqrt(c.shape[0]) - 1
    if (l_avail + 1) ** 2 != c.shape[0]:
        raise ValueError(f"world_coeffs must have (L+1)² rows, got {c.shape[0]}")
    return np.array([float(np.sum(c[l * l : (l + 1) ** 2] ** 2)) for l in range(l_avail + 1)])


def world_tails(coeffs) -> np.ndarray:
    """Fraction of the World's energy above each band: tails[L] = Σ_{l > L} E_l / Σ_l E_l."""
    energy = band_energies(coeffs)
    total = float(energy.sum())
    if total <= 0.0:
        return np.zeros(energy.size)
    return np.array([float(energy[l + 1 :].sum()) / total for l in range(energy.size)])


def world_content_order(coeffs, tail: float = WORLD_TAIL) -> tuple[int, float]:
    """(L, tail fraction above L): the smallest L ≤ MAX_ORDER with Σ_{l > L} E_l < ``tail`` · Σ_l E_l.

    E_l are the World's unwindowed band energies (all coefficients given, usually up to MAX_ORDER);
    energy above the highest given band is unknown and not counted, so a World that still has
    ≥ ``tail`` of its energy in its top band gets that band. A black World needs L = 0.
    """
    tails = world_tails(coeffs)
    top = min(MAX_ORDER, tails.size - 1)
    for l_max in range(top + 1):
        if tails[l_max] < tail:
            return l_max, float(tails[l_max])
    return top, float(tails[top])


@dataclass(frozen=True)
class ScenePlan:
    """The plan of every visible thin-film material of a scene."""

    materials: dict  # name → MaterialPlan (sorted by name)
    tables: dict  # content key → names sharing that table (first = the one baked)
    variants: dict  # Variant → names drawn with that shader variant (display off)
    table_bytes: int  # unique tables, float32
    texture_bytes: int  # unique tables on the GPU
    bake_seconds: float  # estimated, unique tables not cached, kernels shared
    bake_seconds_each: dict  # name → estimated seconds in this scene (0 for a shared/cached table)
    cached: frozenset  # keys whose table is already in memory or on disk
    world_order: int | None  # the highest l_max the draw windows the World to (None: no material)
    world_content_order: int | None  # the World's own (:func:`world_content_order`), for reference
    reasons: dict

    @property
    def empty(self) -> bool:
        """True when the plan has no material."""
        return not self.materials


def scene_plan(
    materials: dict,
    world_coeffs=None,
    *,
    cached=(),
    kernels_cold: bool = True,
) -> ScenePlan:
    """Plan a scene: ``materials`` maps names of materials used by VISIBLE objects to descriptions.

    ``world_coeffs``: the World's SH ((L+1)², 3), e.g. ``addon.world.world.world_sh(scene).coeffs``.
    ``cached``: content keys whose tables are already in memory or on disk (bake time 0).
    ``kernels_cold``: whether microfacet kernels start uncached (a new session).

    Unique tables are keyed by :func:`table_io.content_key` (the add-on's ``description_key``);
    a microfacet kernel shared by several tables is charged to the first only. World order: the
    one drawn, the highest l_max among the materials (the add-on projects the World to
    MAX_ORDER and windows it to each material's l_max); the World's content order
    (:func:`world_content_order`) is reported beside it.
    """
    cached = frozenset(cached)
    plans: dict[str, MaterialPlan] = {}
    tables: dict[str, list[str]] = {}
    variants: dict[tuple, list[str]] = {}
    seen_kernels: set = set()
    seen_order_kernels: set = set()
    each: dict[str, float] = {}
    for name in sorted(materials):
        mp = material_plan(materials[name], kernel_cold=kernels_cold)
        plans[name] = mp
        variants.setdefault(mp.shader.draw, []).append(name)
        if mp.key in tables:
            tables[mp.key].append(name)
            each[name] = 0.0
            continue
        tables[mp.key] = [name]
        if mp.key in cached:
            each[name] = 0.0
            continue
        kernel_cold = kernels_cold and mp.kernel_key not in seen_kernels
        order_cold = kernels_cold and float(mp.material.roughness) not in seen_order_kernels
        seen_kernels.add(mp.kernel_key)
        seen_order_kernels.add(float(mp.material.roughness))
        each[name] = mp.bake_time(kernel_cold=kernel_cold, order_kernel_cold=order_cold)["total"]
    unique = [plans[names[0]] for names in tables.values()]
    reasons: dict[str, str] = {}
    if not plans:
        reasons["scene"] = "no visible object uses an enabled thin-film material: nothing is baked or drawn"
    else:
        shared = [names for names in tables.values() if len(names) > 1]
        reasons["scene"] = (
            f"{len(plans)} material(s) on visible objects → {len(tables)} table(s)"
            + (
                "; shared: " + "; ".join(" = ".join(n) for n in shared)
                if shared
                else "; no two materials are equal"
            )
            + f"; {len(variants)} shader variant(s)"
        )
        if cached & set(tables):
            reasons["cache"] = f"{len(cached & set(tables))} table(s) already cached: not baked again"
    need = max((mp.plan.sh_order for mp in plans.values()), default=0)
    world_order = need if plans else None  # the draw windows the World to each material's l_max
    content = None
    if world_coeffs is not None:
        content, rest = world_content_order(world_coeffs)
        tails = world_tails(world_coeffs)
        if content > 0 and tails[content - 1] >= WORLD_TAIL and content == min(MAX_ORDER, tails.size - 1):
            why = (
                f"World energy above l = {content - 1} is {100 * tails[content - 1]:.2g} %"
                f" (≥ {100 * WORLD_TAIL:g} %) → content order {content}, the highest stored"
            )
        else:
            why = (
                f"World energy above l = {content} is {100 * rest:.2g} % (< {100 * WORLD_TAIL:g} %)"
                f" → content order {content}"
            )
        if plans:
            reasons["world"] = (
                f"{why}; the draw windows the World's SH (projected to l = {MAX_ORDER}) to each"
                f" material's l_max → World SH order {need}, the materials' highest"
            )
        else:
            reasons["world"] = f"{why}; no material draws it"
    elif plans:
        reasons["world"] = f"no World coefficients given: the materials' highest order, {need}"
    return ScenePlan(
        materials=plans,
        tables={key: tuple(names) for key, names in tables.items()},
        variants={key: tuple(names) for key, names in variants.items()},
        table_bytes=sum(mp.table_bytes for mp in unique),
        texture_bytes=sum(mp.texture_bytes for mp in unique),
        bake_seconds=sum(each.values()),
        bake_seconds_each=each,
        cached=cached,
        world_order=world_order,
        world_content_order=content,
        reasons=reasons,
    )
