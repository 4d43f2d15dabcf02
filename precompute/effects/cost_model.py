"""The effect plan's costs: the per-pixel work of the shader variant that draws a material, and the
bake-time model.

:class:`ShaderCost` is the draw's own: the :class:`~precompute.shading.variant.Variant` that
:func:`~precompute.shading.variant.choose_variant` picks from the material's facts (as the add-on's
draw does), costed by :func:`precompute.shading.codegen.operation_counts` on the code that variant
runs. :func:`bake_time_breakdown` estimates a bake's seconds per stage: :func:`bake_features`
(units of work) times :data:`TIME_MODEL` (seconds per unit, fitted by ``benchmarks/plan.py
--calibrate``); :func:`estimate_u_degree` predicts the u-node search without running it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..bakes import kernel, planner
from ..materials.material import AUTO, Material
from ..shading import codegen, policy
from ..shading.variant import Variant

#: Bake-time model: seconds per unit of work of each stage of :func:`bake.bake` (see
#: :func:`bake_features` for the units). Fitted by ``benchmarks/plan.py --calibrate`` (non-
#: negative least squares on relative error) to the process CPU time of cold and warm bakes on
#: the 2-core machine of docs/effect-plan.md; CPU time is what an idle core would take (wall
#: time on a shared, loaded machine is longer).
TIME_MODEL = {
    "fixed": 3.97e-3,  # per bake: plan lookup, spectral quadrature, small arrays
    "reflectance": 2.47e-7,  # per thickness row × u point × wavelength × interface
    "kernel_views": 1.15e-3,  # cold microfacet kernel: per view angle
    "kernel_coeffs": 2.88e-5,  # … per view angle × full-basis coefficient (L+1)²
    "kernel_nodes": 0.0,  # … per view angle × u node (fit: 0, block-sparse since issue 16)
    "multiscatter": 1.72e-3,  # cold GGX albedo: per view angle (+ 32 for the average)
    "contract": 5.45e-10,  # per multiply-add (a floor at numpy's BLAS speed here)
    "sh_order": 6.4e-5,  # the automatic SH order: a table lookup (was an l = 16 kernel, 0.61 s)
}


# ----------------------------------------------------------------------------------------------
# Shader cost
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShaderCost:
    """Per-pixel work of the thin-film shader variant that draws a material.

    ``draw``: the :class:`~precompute.shading.variant.Variant` the add-on compiles for it;
    the counts are :func:`precompute.shading.codegen.operation_counts` of that variant (see there
    for what is counted): the SH half rotated and summed band by band as the generated code
    does (only the structurally non-zero X(±90°) entries), the split sum, the lamp loop. With K
    = (L+1)(L+2)/2 stored coefficients, C = 9 floats per coefficient (3×3 spectral) or 3 (per
    channel) and taps = 2 (1-D table, linear in θo) or 4 (2-D, bilinear in θo × thickness), the
    SH sum reads taps · K · C floats of the table.
    """

    draw: Variant
    channels: int
    taps: int
    floats_fetched: int  # floats read from the film's baked table
    texel_fetches: int  # texelFetch / texture calls (table, prefiltered World, film)
    uniform_loads: int  # vec4 or scalar reads from uniform buffers
    multiply_adds: int
    defines: tuple  # ((name, value), ...): the variant's switches (Variant.switches)
    stages: dict = field(default_factory=dict)  # stage → (multiply-adds, texel fetches, uniform loads)

    @property
    def l_max(self) -> int:
        """Highest SH band the draw evaluates for this material."""
        return int(self.draw.l_max)

    @property
    def variant(self) -> tuple:
        """(l_max, spectral, vary_thickness): the part of :attr:`draw` the table decides."""
        return (self.draw.l_max, self.draw.spectral, self.draw.vary_thickness)


def shader_cost(variant: Variant, lamp_count: int = policy.MAX_LAMPS) -> ShaderCost:
    """The :class:`ShaderCost` of a variant (its lamp loop at ``lamp_count`` lamps)."""
    variant = variant.normalised()
    counts = codegen.operation_counts(variant, lamp_count)
    return ShaderCost(
        draw=variant,
        channels=9 if variant.spectral else 3,
        taps=4 if variant.vary_thickness else 2,
        floats_fetched=counts.table_floats,
        texel_fetches=counts.texel_fetches,
        uniform_loads=counts.uniform_loads,
        multiply_adds=counts.multiply_adds,
        defines=variant.switches(),
        stages=dict(counts.stages),
    )


# ----------------------------------------------------------------------------------------------
# Bake-time model
# ----------------------------------------------------------------------------------------------
def _u_points_per_try(degree: int) -> int:
    """u values :func:`bake.choose_u_degree` evaluates per probe row for one degree: the nodes and
    the test points (the next degree's Chebyshev points at u ≥ U_TEST_MIN: all but the first
    interval's)."""
    intervals = len(kernel.U_EDGES) - 1
    return intervals * degree + (intervals - 1) * (degree + 1)


#: Thickness rows :func:`bake.choose_u_degree` probes at each degree of its search.
PROBE_ROWS = 4


def estimate_u_degree(material: Material) -> tuple[int, tuple, str]:
    """(degree, degrees tried, reason): what :func:`bake.choose_u_degree` will settle on.

    The search climbs the ladder from its bottom. The estimate is a fit to measured choices:
    the smallest ladder degree ≥ 6 + OPD / 300 nm (OPD = the round-trip optical path at the
    thickest film), within two ladder steps of the measured degree for single films of
    50–3000 nm on dielectrics and gold (most often within one).
    """
    ladder = planner.U_DEGREE_LADDER
    if not material.layers:
        return ladder[0], (), "no film: one Fresnel evaluation at the first ladder degree"
    opd = planner.optical_path_nm(material)
    target = 6.0 + opd / 300.0
    degree = next((d for d in ladder if d >= target), ladder[-1])
    tried = tuple(d for d in ladder if d <= degree)
    return (
        degree,
        tried,
        f"optical path {opd:.0f} nm → ≈ {degree} nodes/interval (ladder {tried[0]}…{degree})",
    )


def bake_features(
    material: Material,
    p: planner.Plan,
    degree: int,
    tried: tuple,
    wavelengths: int,
    *,
    kernel_cold: bool = True,
    order_kernel_cold: bool = True,
) -> dict:
    """Units of work of each stage of :func:`bake.bake`, keyed like :data:`TIME_MODEL`.

    With T thickness rows, W wavelength nodes (grid + emission lines), n layers, A view angles,
    L the SH order, K = (L+1)(L+2)/2, U = 8·degree u nodes:

    - reflectance: [Σ over the degrees tried d of P · (8d + 7(d+1)) + T · 8·d_chosen] · W · (n + 1)
      — :func:`bake.choose_u_degree`'s search on P = min(T, 4) probe rows (nodes and test
      points), then the chosen nodes on every row; per interface (both polarisations);
    - kernel_views, kernel_coeffs, kernel_nodes (cold kernel only): A, A · (L+1)² and A · U;
    - multiscatter (cold only, when multiple scattering is on): A + 32 GGX albedo views;
    - contract: T·U·W·9 + A·K·U·T·9 (+ T·A·(L+1)·W·9 with a diffuse base);
    - sh_order: 1 when the SH order is automatic and not yet planned for this roughness (a table
      lookup since issue 16: the feature is kept so older calibrations still read).
    """
    t, a, l_max = p.thickness_samples, p.view_samples, p.sh_order
    k = (l_max + 1) * (l_max + 2) // 2
    u = degree * (len(kernel.U_EDGES) - 1)
    interfaces = len(material.layers) + 1
    if not material.layers:
        refl = t * wavelengths * u
    else:
        probe = min(t, PROBE_ROWS)
        refl = (sum(probe * _u_points_per_try(d) for d in tried) + t * u) * wavelengths * interfaces
    contract = t * u * wavelengths * 9 + a * k * u * t * 9
    if material.base_color is not None:
        contract += t * a * (l_max + 1) * wavelengths * 9
    multiscatter = material.multiscatter != "none" and material.roughness > 0.0
    return {
        "fixed": 1.0,
        "reflectance": float(refl),
        "kernel_views": float(a) if kernel_cold else 0.0,
        "kernel_coeffs": float(a * (l_max + 1) ** 2) if kernel_cold else 0.0,
        "kernel_nodes": float(a * u) if kernel_cold else 0.0,
        "multiscatter": float(a + 32) if (kernel_cold and multiscatter) else 0.0,
        "contract": float(contract),
        "sh_order": 1.0 if (order_kernel_cold and material.quality.sh_order == AUTO) else 0.0,
    }


def bake_time_breakdown(*args, **kwargs) -> dict:
    """Estimated seconds per stage (and "total"): :func:`bake_features` × :data:`TIME_MODEL`."""
    features = bake_features(*args, **kwargs)
    out = {
        "fixed": TIME_MODEL["fixed"],
        "reflectance": features["reflectance"] * TIME_MODEL["reflectance"],
        "kernel": sum(features[n] * TIME_MODEL[n] for n in ("kernel_views", "kernel_coeffs", "kernel_nodes")),
        "multiscatter": features["multiscatter"] * TIME_MODEL["multiscatter"],
        "contract": features["contract"] * TIME_MODEL["contract"],
        "sh_order": features["sh_order"] * TIME_MODEL["sh_order"],
    }
    out["total"] = sum(out.values())
    return out
