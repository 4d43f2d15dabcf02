"""SH irradiance against brute force on Blender's studiolights: shared by the test and the report.

For every studiolight (found in the bpy wheel without importing bpy), brute-force
E(n) = Σ_pixels L max(0, n·ω) dω at 200 Fibonacci normals against the SH irradiance
Σ Â_l L_lm Y_lm(n) (Ramamoorthi & Hanrahan 2001). Used by tests/sh/test_sh_hdri.py (the gate at
l_max = 8) and ``benchmarks.sh_projection --irradiance-doc`` (docs/sh-irradiance.md). It lives in
tests/ because the tests never import benchmarks/.
"""

from __future__ import annotations

import glob
import importlib.util
import os

import numpy as np

from precompute.colour.colour_difference import LUMINANCE_REC709
from precompute.sh import harmonics, projection, zonal
from precompute.world import hdri

#: Normals at which irradiance is compared (Fibonacci sphere): 200 samples spaced ~14° apart,
#: finer than the ~20° (π/l for l = 8) scale on which an l_max = 8 irradiance varies.
N_NORMALS = 200

#: Downsampling factor for the studiolights (1024×512 → 256×128). The brute-force reference
#: costs N_NORMALS × H × W; at full size the (200, 524288) cosine matrix alone is 0.8 GB. The
#: irradiance is a low-pass (cosine-lobe) integral, so the solid-angle-conserving box filter
#: changes it by ≤ 0.4 % (measured, sunrise.exr); and both sides of the comparison use the
#: same downsampled image, so the comparison isolates SH truncation error.
DOWNSAMPLE_FACTOR = 4


def studiolight_dir() -> str | None:
    """``<bpy>/5.2/datafiles/studiolights/world`` found without importing bpy, or None."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    for base in spec.submodule_search_locations:
        preferred = os.path.join(base, "5.2", "datafiles", "studiolights", "world")
        if os.path.isdir(preferred):
            return preferred
        others = sorted(glob.glob(os.path.join(base, "*", "datafiles", "studiolights", "world")))
        if others:
            return others[-1]
    return None


def studiolight_paths() -> list[str]:
    """All ``*.exr`` studiolight worlds, sorted by name (empty if bpy is absent)."""
    folder = studiolight_dir()
    return sorted(glob.glob(os.path.join(folder, "*.exr"))) if folder else []


def irradiance_errors(image: np.ndarray, l_max: int, normals: np.ndarray) -> dict:
    """Compare SH irradiance at band ``l_max`` with brute force on ``image`` (H, W, 3).

    Returns
    -------
    dict
        ``mean_rel_lum``: mean_n |ΔE_Y| / mean_n E_Y (Rec.709 luminance Y);
        ``max_rel_lum``: max_n |ΔE_Y(n)| / E_Y(n) (pointwise; large where E is small);
        ``max_abs_over_mean_lum``: max_n |ΔE_Y| / mean_n E_Y;
        ``mean_rel_channels``: per-channel mean_n |ΔE_c| / mean_n E_c, shape (3,);
        ``mean_rel_worst_channel``: the largest of those (the test's gate);
        ``rejected_pixels``: NaN/Inf pixels skipped by the projection.
    """
    brute = hdri.irradiance_brute_force(np.nan_to_num(image, nan=0.0, posinf=0.0, neginf=0.0), normals)
    coeffs, info = projection.project_equirect(image, l_max, return_info=True)
    approx = harmonics.evaluate(zonal.irradiance_coefficients(coeffs), normals)
    diff = np.abs(approx - brute)
    lum_diff = np.abs((approx - brute) @ LUMINANCE_REC709)
    lum = brute @ LUMINANCE_REC709
    per_channel = diff.mean(axis=0) / brute.mean(axis=0)
    return {
        "mean_rel_lum": float(lum_diff.mean() / lum.mean()),
        "max_rel_lum": float(np.max(lum_diff / lum)),
        "max_abs_over_mean_lum": float(lum_diff.max() / lum.mean()),
        "mean_rel_channels": per_channel,
        "mean_rel_worst_channel": float(per_channel.max()),
        "rejected_pixels": info["rejected_pixels"],
    }


def power_concentration(image: np.ndarray, sphere_fraction: float = 0.01) -> float:
    """Share of ∫ L_Y dω carried by the brightest ``sphere_fraction`` of the sphere's solid angle.

    Near 1 for a map lit by a few small bright sources (a sun, spot lamps), small for broad
    sky light; this, not the peak pixel value, predicts how much the SH truncation hurts.
    """
    lum = np.nan_to_num(image @ LUMINANCE_REC709, nan=0.0, posinf=0.0, neginf=0.0).reshape(-1)
    d_omega = hdri.equirect_solid_angles(*image.shape[:2]).reshape(-1)
    order = np.argsort(lum)[::-1]
    cum_omega = np.cumsum(d_omega[order])
    cum_power = np.cumsum(lum[order] * d_omega[order])
    cut = min(int(np.searchsorted(cum_omega, sphere_fraction * 4.0 * np.pi)), lum.size - 1)
    return float(cum_power[cut] / cum_power[-1])


def studiolight_irradiance_table(paths: list[str] | None = None, l_maxes=(2, 8)) -> list[dict]:
    """Per-map irradiance errors for each studiolight at each band limit in ``l_maxes``."""
    paths = studiolight_paths() if paths is None else paths
    normals = hdri.fibonacci_sphere(N_NORMALS)
    rows = []
    for path in paths:
        full = hdri.read_equirect(path)
        image = hdri.downsample(full, DOWNSAMPLE_FACTOR)
        row = {
            "map": os.path.basename(path),
            "size": f"{full.shape[1]}×{full.shape[0]}",
            "concentration": power_concentration(full),
        }
        for l_max in l_maxes:
            row[l_max] = irradiance_errors(image, l_max, normals)
        rows.append(row)
    return rows


def format_irradiance_table(rows: list[dict], l_maxes=(2, 8)) -> str:
    """Markdown table of :func:`studiolight_irradiance_table` (percentages)."""
    head = "| map | power in top 1 % |"
    rule = "|---|---:|"
    for l_max in l_maxes:
        head += f" l≤{l_max} mean | l≤{l_max} worst ch. | l≤{l_max} max rel |"
        rule += "---:|---:|---:|"
    lines = [head, rule]
    for row in rows:
        line = f"| {row['map']} | {100 * row['concentration']:.0f} % |"
        for l_max in l_maxes:
            r = row[l_max]
            line += (
                f" {100 * r['mean_rel_lum']:.2f} % | {100 * r['mean_rel_worst_channel']:.2f} % |"
                f" {100 * r['max_rel_lum']:.1f} % |"
            )
        lines.append(line)
    return "\n".join(lines)
