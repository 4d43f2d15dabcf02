"""SH projection benchmark and HDRI irradiance-accuracy report.

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.sh_projection                  # timings → docs/benchmark-sh.md
    .venv/bin/python -m benchmarks.sh_projection --irradiance-doc # errors  → docs/sh-irradiance.md
    .venv/bin/python -m benchmarks.sh_projection --all            # both

Timings: :func:`precompute.sh.project_equirect` of a 2048×1024 RGB HDRI (Blender's
``studio.exr`` studiolight, 1024×512, upsampled 2× by pixel repetition) at l_max 2, 4, 8, and
:func:`precompute.sh.rotation` at l_max 8; median of ≥ 5 runs of ``time.perf_counter``.

Irradiance: for every studiolight, brute-force E(n) = Σ_pixels L max(0, n·ω) dω at 200
Fibonacci normals against the SH irradiance Σ Â_l L_lm Y_lm(n) at l_max 2 and 8
(Ramamoorthi & Hanrahan 2001). Shared with ``tests/test_sh_hdri.py``.
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import os
import platform
import statistics
import time

import numpy as np

from benchmarks.common import cpu_model
from precompute import hdri, sh

#: Rec.709 / sRGB luminance weights (Blender's default scene-linear space).
LUMINANCE_REC709 = np.array([0.2126, 0.7152, 0.0722])

#: Normals at which irradiance is compared (Fibonacci sphere): 200 samples spaced ~14° apart,
#: finer than the ~20° (π/l for l = 8) scale on which an l_max = 8 irradiance varies.
N_NORMALS = 200

#: Downsampling factor for the studiolights (1024×512 → 256×128). The brute-force reference
#: costs N_NORMALS × H × W; at full size the (200, 524288) cosine matrix alone is 0.8 GB. The
#: irradiance is a low-pass (cosine-lobe) integral, so the solid-angle-conserving box filter
#: changes it by ≤ 0.4 % (measured, sunrise.exr); and both sides of the comparison use the
#: same downsampled image, so the comparison isolates SH truncation error.
DOWNSAMPLE_FACTOR = 4

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


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
    coeffs, info = sh.project_equirect(image, l_max, return_info=True)
    approx = sh.evaluate(sh.irradiance_coefficients(coeffs), normals)
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


def point_light_truncation_error(l_max: int, nodes: int = 4000) -> tuple[float, float]:
    """SH-truncation error of the irradiance of one point light (a delta in radiance).

    E(n) = max(0, cos γ) versus its band-limited version Σ_l Â_l (2l+1)/(4π) P_l(cos γ), with
    cos γ on a ``nodes``-point Gauss–Legendre rule (the kink at cos γ = 0 limits it to ~1e-6).

    Returns
    -------
    (mean |ΔE| / mean E, max |ΔE| / max E) over the sphere.
    """
    x, w = np.polynomial.legendre.leggauss(nodes)
    exact = np.maximum(0.0, x)
    a_hat = sh.clamped_cosine_zh(l_max)
    l = np.arange(l_max + 1)
    approx = np.polynomial.legendre.legvander(x, l_max) @ (a_hat * (2 * l + 1) / (4.0 * np.pi))
    err = np.abs(approx - exact)
    return float(w @ err / (w @ exact)), float(err.max())


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


# ----------------------------------------------------------------------------------------------
# Timing
# ----------------------------------------------------------------------------------------------


def _median_time(func, runs: int = 7) -> float:
    func()  # warm-up (allocations, BLAS thread start)
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def benchmark_image() -> tuple[np.ndarray, str]:
    """A 2048×1024 RGB float32 HDRI: studio.exr upsampled 2×, or a synthetic one without bpy."""
    paths = [p for p in studiolight_paths() if os.path.basename(p) == "studio.exr"] or studiolight_paths()
    if paths:
        image = hdri.read_equirect(paths[0])
        while image.shape[1] < 2048:
            image = np.repeat(np.repeat(image, 2, axis=0), 2, axis=1)
        return image[:1024, :2048], f"{os.path.basename(paths[0])} upsampled to 2048×1024"
    rng = np.random.default_rng(0)
    return rng.lognormal(size=(1024, 2048, 3)).astype(np.float32), "synthetic log-normal 2048×1024"


def run_benchmark() -> str:
    """Time projection and rotation; return the markdown report."""
    image, source = benchmark_image()
    rng = np.random.default_rng(1)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    lines = [
        "# SH projection benchmark",
        "",
        "Generated by `.venv/bin/python -m benchmarks.sh_projection` (median of 7 runs after one",
        "warm-up, `time.perf_counter`).",
        "",
        f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}",
        f"- Python {platform.python_version()}, numpy {np.__version__}",
        f"- Image: {source}, {image.dtype}, {image.shape}",
        "",
        "| operation | time |",
        "|---|---:|",
    ]
    for l_max in (2, 4, 8):
        t = _median_time(lambda l_max=l_max: sh.project_equirect(image, l_max))
        lines.append(f"| `project_equirect` 2048×1024×3, l_max = {l_max} | {1e3 * t:.1f} ms |")
    t = _median_time(lambda: sh.rotation(8, rot), runs=21)
    lines.append(f"| `rotation(8, R)` (general R, Ivanic–Ruedenberg) | {1e3 * t:.2f} ms |")
    t = _median_time(lambda: sh.rotation_z(8, 0.7), runs=21)
    lines.append(f"| `rotation_z(8, α)` (z fast path) | {1e3 * t:.3f} ms |")
    lines += [
        "",
        "Projection is separable (per-row Legendre × per-column cos/sin(mφ), two contractions), so",
        "its cost is dominated by the O(H·W·(2 l_max+1)·C) column contraction (one batched matmul)",
        "and the float64 conversion of the image; it grows only slowly with l_max. NaN/Inf pixels",
        "are detected from the row sums, so a clean image pays no separate scan.",
        "",
    ]
    return "\n".join(lines)


def irradiance_doc() -> str:
    """Markdown report of SH-vs-brute-force irradiance on every studiolight."""
    rows = studiolight_irradiance_table()
    if not rows:
        return "# SH irradiance accuracy\n\nbpy studiolights not found; nothing measured.\n"
    by_concentration = sorted(rows, key=lambda r: -r["concentration"])
    worst8 = max(rows, key=lambda r: r[8]["mean_rel_worst_channel"])
    avg2 = np.mean([r[2]["mean_rel_lum"] for r in rows])
    avg8 = np.mean([r[8]["mean_rel_lum"] for r in rows])
    ranking = ", ".join(
        f"{r['map']} ({100 * r['concentration']:.0f} %: {100 * r[2]['mean_rel_lum']:.1f} % / "
        f"{100 * r[8]['mean_rel_lum']:.2f} %)"
        for r in by_concentration
    )
    named = {r["map"]: r for r in rows}
    pl2, pl8 = point_light_truncation_error(2), point_light_truncation_error(8)
    notes = []
    for name, what in (
        ("studio.exr", "two small spot lamps carry almost all the light"),
        ("sunrise.exr", "a low sun on the horizon"),
    ):
        if name in named:
            r = named[name]
            notes.append(
                f"  - {name}: {what}; {100 * r['concentration']:.0f} % of the power in 1 % of the"
                f" sphere; l ≤ 2 mean error {100 * r[2]['mean_rel_lum']:.1f} % (≈"
                f" {r[2]['mean_rel_lum'] / 0.01:.0f}× the paper's 1 %), l ≤ 8"
                f" {100 * r[8]['mean_rel_lum']:.2f} %."
            )
    return "\n".join(
        [
            "# SH irradiance accuracy on Blender's studiolights",
            "",
            "Generated by `.venv/bin/python -m benchmarks.sh_projection --irradiance-doc`; the same",
            "numbers are asserted (l ≤ 8) and printed by `tests/test_sh_hdri.py`",
            "(`pytest tests/test_sh_hdri.py -s`).",
            "",
            "## Method",
            "",
            "- Every `*.exr` in `<bpy>/5.2/datafiles/studiolights/world/`, read with",
            f"  `precompute.hdri.read_equirect` and downsampled ×{DOWNSAMPLE_FACTOR} (1024×512 → 256×128)",
            "  with the solid-angle-conserving box filter (`hdri.downsample`). Brute force at full size",
            "  would need a 200 × 524 288 cosine matrix; the downsampling changes the brute-force",
            "  irradiance by ≤ 0.4 % (sunrise.exr; < 0.15 % for the others) and both sides use the same",
            "  image, so only the SH truncation is measured.",
            f"- Reference: E(n) = Σ_pixels L max(0, n·ω) dω at {N_NORMALS} Fibonacci-sphere normals,",
            "  exact pixel solid angles (`hdri.irradiance_brute_force`).",
            "- SH: `project_equirect` → `irradiance_coefficients` (E_lm = Â_l L_lm) → `evaluate`.",
            "- Metrics: *mean* = mean_n |E_sh − E_bf| / mean_n E_bf on Rec.709 luminance;",
            "  *worst ch.* = the same per R, G, B channel, the largest of the three (the test gates",
            "  this at ≤ 2 % for l ≤ 8); *max rel* = max_n |E_sh − E_bf|(n) / E_bf(n), pointwise on",
            "  luminance (dominated by normals facing away from the lights, where E is small).",
            "- *power in top 1 %*: share of ∫ L_Y dω carried by the brightest 1 % of the sphere",
            "  (how concentrated the light is).",
            "",
            "## Results",
            "",
            format_irradiance_table(rows),
            "",
            "## Discussion",
            "",
            "- Ramamoorthi & Hanrahan (SIGGRAPH 2001) report, for 9 coefficients (l ≤ 2), an average",
            "  error under 1 % and a maximum under 5 % on their light probes (with a theoretical",
            f"  worst case of about 9 %). Here 9 coefficients give {100 * avg2:.1f} % on average over",
            "  the eight studiolights; only the broad-sky sunset.exr is near the paper's figure.",
            "- The error roughly follows how concentrated the light is (maps sorted by power in the top 1 %;",
            f"  l ≤ 2 / l ≤ 8 mean error): {ranking}.",
            "- Small bright lights do worst: the clamped cosine's bands l ≥ 3 (Â_4 = −π/24,",
            "  Â_6 = π/64, …) matter for a near-delta light. For one point light the truncated",
            f"  irradiance has a mean error of {100 * pl2[0]:.1f} % at l ≤ 2",
            f"  (max {100 * pl2[1]:.1f} % of the peak, the paper's ≈ 9 % bound) and",
            f"  {100 * pl8[0]:.1f} % at l ≤ 8 (max {100 * pl8[1]:.1f} %);",
            "  maps approach these limits as their power concentrates:",
            *notes,
            f"- With l ≤ 8 (81 coefficients) every map is within 2 % per channel (worst {worst8['map']},"
            f" {100 * worst8[8]['mean_rel_worst_channel']:.2f} %); the mean luminance error averages",
            f"  {100 * avg8:.2f} %.",
            "- The pointwise maximum relative error is large at l ≤ 2 (over 100 % for studio, sunrise,",
            "  night) because the truncated irradiance rings (and can dip below zero) on the side facing",
            "  away from a small bright source, where the true irradiance is small.",
            "",
        ]
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--irradiance-doc", action="store_true", help="write docs/sh-irradiance.md only")
    parser.add_argument("--all", action="store_true", help="write both docs")
    args = parser.parse_args(argv)
    targets = []
    if args.all or not args.irradiance_doc:
        targets.append(("benchmark-sh.md", run_benchmark))
    if args.all or args.irradiance_doc:
        targets.append(("sh-irradiance.md", irradiance_doc))
    for name, build in targets:
        text = build()
        path = os.path.join(ROOT, "docs", name)
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(text)
        print(text)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
