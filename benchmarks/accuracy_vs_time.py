"""Accuracy against cost: SH tables of every resolution vs a brute-force spectral render.

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.accuracy_vs_time           # → docs/accuracy-vs-time.{md,png}
    .venv/bin/python -m benchmarks.accuracy_vs_time --quick   # smoke run (< 1 min), prints only

Every configuration changes ONE knob of the default (auto) plan: SH order 1–12, wavelength
count, view-angle (θo) samples, thickness samples (2-D tables), the half-vector quadrature of
the kernel, storage precision (float32 vs half), and the colour mode (3×3 spectral — the
default —, Cycles' per-channel film, and a three-wavelength "RGB film" as real-time engines do).
Each is baked and shaded with :func:`precompute.output.render.shade_sh` (what the GLSL does per pixel)
on a 40×40 sphere under Blender's ``studio`` and ``courtyard`` HDRIs, and compared with
:func:`precompute.output.render.shade_reference` (no SH: the exact spectral BRDF integrated against
the environment map by half-vector quadrature) in CIEDE2000 after a common exposure
normalisation (the reference's 95th-percentile luminance over the sphere → 0.8).

See ``docs/accuracy-vs-time.md`` for the method, the per-pixel cost formula and results.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from precompute.bakes import bake, planner
from precompute.bakes import kernel as bake_kernel
from precompute.colour.colour_difference import delta_e_2000
from precompute.commands import cli
from precompute.effects import plan_text, plans
from precompute.materials.material import AUTO, Layer, Material, Quality
from precompute.output import render
from precompute.shading import sh_sum
from precompute.tables import table_io
from precompute.world import hdri

from . import common

# ----------------------------------------------------------------------------------------------
# Scenes
# ----------------------------------------------------------------------------------------------
FILMS = {
    "soap": {"film": 1.33, "substrate": 1.0, "label": "soap film (1.33 in air)"},
    "oil": {"film": 1.47, "substrate": 1.33, "label": "oil (1.47) on water (1.33)"},
}
ROUGHNESSES = (0.15, 0.35, 0.6, 0.9)
THICKNESSES = (150.0, 400.0, 900.0)
HDRIS = ("studio", "courtyard")
#: Thickness axis of the 2-D tables: chosen so that 150/400/900 nm fall between rows for
#: every tested row count (a render exactly on a row would hide the interpolation error).
THICKNESS_RANGE = (90.0, 1010.0)
#: Wavelengths of the ground truth's spectral quadrature (auto would give 48 here).
REFERENCE_WAVELENGTHS = 256
SPHERE = 40
HDRI_DOWNSAMPLE = 4  # 1024×512 → 256×128
#: Three-wavelength "RGB film" (as many real-time engines): R, G, B film reflectance at one λ each.
RGB3_NM = (630.0, 532.0, 465.0)


@dataclass(frozen=True)
class Scene:
    film: str
    thickness: float
    roughness: float
    hdri: str

    @property
    def key(self):
        return (self.film, self.thickness, self.roughness, self.hdri)

    def material(self, **changes) -> Material:
        f = FILMS[self.film]
        m = Material(
            layers=(Layer(f["film"], self.thickness),),
            substrate=f["substrate"],
            roughness=self.roughness,
            multiscatter="none",  # the ground truth (render.shade_reference) is single scattering
        )
        return m.with_(**changes) if changes else m


def all_scenes() -> list[Scene]:
    """Every roughness × thickness with both films; the HDRI alternates so each roughness and
    each film sees both maps (24 scenes)."""
    out = []
    for ri, r in enumerate(ROUGHNESSES):
        for di, d in enumerate(THICKNESSES):
            for fi, film in enumerate(FILMS):
                out.append(Scene(film, d, r, HDRIS[(ri + di + fi) % 2]))
    return out


def quick_scenes() -> list[Scene]:
    return [Scene("soap", 400.0, 0.35, "courtyard"), Scene("oil", 900.0, 0.9, "studio")]


# ----------------------------------------------------------------------------------------------
# Configurations
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Config:
    name: str
    group: str
    sh_order: object = None  # None → the auto plan's value
    wavelengths: object = None
    views: object = None
    thickness_samples: object = None  # None → 1-D table (constant thickness); int or AUTO → 2-D
    quadrature: tuple | None = None  # (n_theta, n_phi) of the kernel's half-vector rule
    precision: str = "float"
    colour: str = "spectral"  # "spectral" | "per_channel" | "rgb3"
    multiscatter: str = "none"


def all_configs() -> list[Config]:
    c = [Config("default (auto plan)", "default")]
    c += [Config(f"SH order {l}", "SH order", sh_order=l) for l in (*range(1, 9), 10, 12)]
    c += [Config(f"{w} wavelengths", "wavelengths", wavelengths=w) for w in (6, 12, 24, 96)]
    c += [Config(f"{a} view angles", "θo samples", views=a) for a in (4, 8, 16, 32, 64)]
    c += [Config("2-D, auto thickness rows", "thickness rows", thickness_samples=AUTO)]
    c += [
        Config(f"2-D, {t} thickness rows", "thickness rows", thickness_samples=t) for t in (5, 9, 17, 33, 65)
    ]
    c += [
        Config(f"quadrature {nt}×{nphi}", "quadrature", quadrature=(nt, nphi))
        for nt, nphi in ((12, 6), (24, 12), (48, 24), (192, 96))
    ]
    c += [Config("half-precision table", "precision", precision="half")]
    c += [Config("2-D auto, half precision", "precision", thickness_samples=AUTO, precision="half")]
    c += [Config("per-channel (Cycles) film", "colour mode", colour="per_channel")]
    c += [Config("3-wavelength RGB film", "colour mode", colour="rgb3")]
    c += [Config('multiscatter "film" (Material default)', "multiscatter", multiscatter="film")]
    return c


def quick_configs() -> list[Config]:
    names = {
        "default (auto plan)",
        "SH order 2",
        "2-D, 9 thickness rows",
        "half-precision table",
        "3-wavelength RGB film",
    }
    return [c for c in all_configs() if c.name in names]


def rgb3_quadrature(count, colour_space, illuminant, colour_mode):
    """Three nodes, one per output channel, G[j, k, c] = δ_jk δ_kc: R_k = R(λ_k) × light_k."""
    return np.array(RGB3_NM), np.eye(3)[:, :, None] * np.eye(3)[None, :, :]


@contextlib.contextmanager
def patched(module, **values):
    """Temporarily replace module attributes (the benchmark's variants; precompute/ is untouched)."""
    old = {k: getattr(module, k) for k in values}
    for k, v in values.items():
        setattr(module, k, v)
    try:
        yield
    finally:
        for k, v in old.items():
            setattr(module, k, v)


def config_material(cfg: Config, scene: Scene) -> Material:
    """The material baked for ``cfg``: the scene's auto plan pinned, with one knob changed."""
    base = scene.material()
    two_d = cfg.thickness_samples is not None
    if two_d:
        base = base.with_(thickness_range_nm=THICKNESS_RANGE)
    p = planner.plan(base)
    q = Quality(
        sh_order=cfg.sh_order if cfg.sh_order is not None else p.sh_order,
        view_samples=cfg.views if cfg.views is not None else p.view_samples,
        thickness_samples=(p.thickness_samples if cfg.thickness_samples == AUTO else cfg.thickness_samples)
        if two_d
        else AUTO,
        wavelength_count=cfg.wavelengths if cfg.wavelengths is not None else p.wavelength_count,
    )
    mode = "per_channel" if cfg.colour in ("per_channel", "rgb3") else "spectral"
    return base.with_(quality=q, colour_mode=mode, multiscatter=cfg.multiscatter)


def bake_config(cfg: Config, scene: Scene, cold_start: bool = True):
    """(result, first-bake seconds, warm seconds).

    With ``cold_start`` the kernel caches (and any u-degree hint) are cleared first, so the first
    bake is a cold one; otherwise whatever earlier scenes left in the caches is reused.
    """
    m = config_material(cfg, scene)
    patches = {}
    if cfg.colour == "rgb3":
        patches["spectral_quadrature"] = rgb3_quadrature
    if cfg.quadrature is not None:
        original = bake_kernel.microfacet_kernel
        nt, nphi = cfg.quadrature

        def kernel(roughness, l_max, views, degree, _o=original, _nt=nt, _np=nphi):
            return _o(roughness, l_max, views, degree, _nt, _np)

        patches["microfacet_kernel"] = kernel
    if cold_start:
        common.clear_bake_caches()
    with patched(bake, **patches):
        cold, result = common.time_once(lambda: bake.bake(m))
        warm, result = common.time_once(lambda: bake.bake(m))
    if cfg.precision == "half":
        result = dataclasses.replace(result, data=half_round_trip(result))
    return result, cold, warm


_HALF_CHECKED = []


def half_round_trip(result) -> np.ndarray:
    """The table as stored in half: ``astype(float16)``; checked once against a real EXR round trip."""
    data = result.data.astype(np.float16).astype(np.float64)
    if not _HALF_CHECKED:
        with tempfile.TemporaryDirectory() as tmp:
            path = table_io.write_table(
                os.path.join(tmp, "t.exr"), result.data, result.attributes(), precision="half"
            )
            back = table_io.read_table(path).data
        assert np.array_equal(back, data), "table_io half round trip differs from astype(float16)"
        _HALF_CHECKED.append(True)
    return data


# ----------------------------------------------------------------------------------------------
# Per-pixel cost model
# ----------------------------------------------------------------------------------------------
def shader_cost(l_max: int, channels_per_coeff: int, taps: int) -> tuple[int, int]:
    """(floats fetched, multiply-adds) per pixel for ``render.shade_sh``'s algorithm.

    K = (L+1)(L+2)/2 kept coefficients; C = 9 (3×3) or 3 (per channel); taps = 2 (θo) or 4 (θo × d).
    Rotation: two fixed x-rotations, dense per band, 3 colour channels: 6 Σ_l (2l+1)²;
    three z-rotations: 4 MADs per (l, m ≥ 1) pair per channel, 3 channels: 18 L(L+1), plus the
    cos mθ / sin mθ recurrence, 4 per m per rotation: 12 L. Table: taps·K·C MADs for the
    interpolation weights, K·C for M_i · L_i.
    """
    k = (l_max + 1) * (l_max + 2) // 2
    fetched = taps * k * channels_per_coeff
    x_rot = 6 * sum((2 * l + 1) ** 2 for l in range(l_max + 1))
    z_rot = 18 * l_max * (l_max + 1) + 12 * l_max
    mads = x_rot + z_rot + fetched + k * channels_per_coeff
    return fetched, mads


# ----------------------------------------------------------------------------------------------
# The run
# ----------------------------------------------------------------------------------------------
class Environments:
    """Downsampled HDRIs and their SH projections (cached)."""

    def __init__(self):
        self.images = {}
        self.coeffs = {}

    def image(self, name: str) -> np.ndarray:
        if name not in self.images:
            full = hdri.read_equirect(cli.studiolight(name))
            self.images[name] = hdri.downsample(full, HDRI_DOWNSAMPLE)
        return self.images[name]

    def sh(self, name: str, l_max: int, roughness: float) -> np.ndarray:
        key = (name, l_max, roughness)
        if key not in self.coeffs:
            _, c = render.prepare_environment(
                self.image(name), l_max, max_width=self.image(name).shape[1], roughness=roughness
            )
            self.coeffs[key] = c
        return self.coeffs[key]


def run(scenes: list[Scene], configs: list[Config], sphere: int = SPHERE) -> dict:
    t_start = time.perf_counter()
    envs = Environments()
    view = render.sphere_view(sphere, sphere)
    normals, views = view.normals[view.mask], view.views[view.mask]
    references, ref_times = {}, []
    for s in scenes:
        ref_m = s.material(quality=Quality(wavelength_count=REFERENCE_WAVELENGTHS))
        t, img = common.time_once(
            lambda ref_m=ref_m, s=s: render.shade_reference(ref_m, envs.image(s.hdri), normals, views)
        )
        references[s.key] = img
        ref_times.append(t)
        print(f"reference {s.key}: {t:.1f} s")
    t_refs = time.perf_counter() - t_start

    rows = []
    for cfg in configs:
        per_scene, cold, warm, de_all, shade_times = [], [], [], [], []
        timed_cold = {}
        for i, s in enumerate(scenes):  # cold bakes are timed on the first scene of each roughness
            timed_cold.setdefault(s.roughness, i)
        for i, s in enumerate(scenes):
            is_cold = timed_cold[s.roughness] == i
            result, tc, tw = bake_config(cfg, s, cold_start=is_cold)
            if is_cold:
                cold.append(tc)
            warm.append(tw)
            coeffs = envs.sh(s.hdri, result.sh_order, s.roughness)
            thickness = s.thickness if cfg.thickness_samples is not None else None
            ts, img = common.time_once(
                lambda result=result, coeffs=coeffs, thickness=thickness: sh_sum.shade_sh(
                    result, coeffs, normals, views, thickness
                )
            )
            shade_times.append(ts)
            de = delta_e_2000(img, references[s.key])
            de_all.append(de)
            per_scene.append(
                {
                    "scene": s,
                    "mean": float(de.mean()),
                    "p95": float(np.percentile(de, 95)),
                    "l_max": result.sh_order,
                    "shape": result.data.shape,
                }
            )
        pooled = np.concatenate(de_all)
        first = per_scene[0]
        c_per = 3 if cfg.colour in ("per_channel", "rgb3") else 9
        taps = 4 if cfg.thickness_samples is not None else 2
        shapes = [p["shape"] for p in per_scene]
        sizes = [int(np.prod(sh)) for sh in shapes]
        orders = sorted({p["l_max"] for p in per_scene})
        costs = [shader_cost(p["l_max"], c_per, taps) for p in per_scene]
        row = {
            "cfg": cfg,
            "mean": float(pooled.mean()),
            "p95": float(np.percentile(pooled, 95)),
            "by_roughness": {
                r: float(np.mean([p["mean"] for p in per_scene if p["scene"].roughness == r]))
                for r in sorted({p["scene"].roughness for p in per_scene})
            },
            "by_hdri": {
                h: float(np.mean([p["mean"] for p in per_scene if p["scene"].hdri == h]))
                for h in sorted({p["scene"].hdri for p in per_scene})
            },
            "cold": statistics.median(cold),
            "warm": statistics.median(warm),
            "shade": statistics.median(shade_times),
            "bytes32": statistics.mean(sizes) * 4,
            "bytes16": statistics.mean(sizes) * 2,
            "fetched": statistics.mean(c[0] for c in costs),
            "mads": statistics.mean(c[1] for c in costs),
            "orders": orders,
            "example_shape": first["shape"],
            "per_scene": per_scene,
        }
        rows.append(row)
        print(
            f"{cfg.name:32s} ΔE mean {row['mean']:6.2f} p95 {row['p95']:6.2f}  MADs {row['mads']:6.0f}"
            f"  cold {common.fmt_seconds(row['cold'])} warm {common.fmt_seconds(row['warm'])}"
        )
    return {
        "rows": rows,
        "scenes": scenes,
        "pixels": int(view.mask.sum()),
        "sphere": sphere,
        "ref_time": statistics.median(ref_times),
        "ref_total": t_refs,
        "total": time.perf_counter() - t_start,
        "image_shape": next(iter(envs.images.values())).shape,
    }


# ----------------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------------
def pareto(points):
    """Indices of the non-dominated points (lower x and lower y are better)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], float("inf")
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def plot(res: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["rows"]
    groups = list(dict.fromkeys(r["cfg"].group for r in rows))
    colours = dict(zip(groups, plt.rcParams["axes.prop_cycle"].by_key()["color"] * 3, strict=False))
    fig, axes = plt.subplots(1, 2, figsize=(14, 6), sharey=True)
    for ax, key, label in (
        (axes[0], "mads", "per-pixel shader work (multiply-adds, cost model; mean over scenes)"),
        (axes[1], "cold", "bake time, cold kernel (s, median over scenes)"),
    ):
        pts = [(r[key], r["mean"]) for r in rows]
        for g in groups:
            sel = [i for i, r in enumerate(rows) if r["cfg"].group == g]
            ax.scatter(
                [pts[i][0] for i in sel], [pts[i][1] for i in sel], color=colours[g], label=g, s=36, zorder=3
            )
        front = pareto(pts)
        ax.step(
            [pts[i][0] for i in front],
            [pts[i][1] for i in front],
            where="post",
            color="k",
            lw=1,
            alpha=0.6,
            label="Pareto front",
            zorder=2,
        )
        base_y = next(r["mean"] for r in rows if r["cfg"].group == "default")
        for i, r in enumerate(
            rows
        ):  # label the front and the clearly worse points; the cluster stays unlabelled
            if i in front or r["mean"] > base_y + 0.5 or r["cfg"].group == "default":
                ax.annotate(
                    r["cfg"].name, pts[i], fontsize=7, xytext=(4, 3), textcoords="offset points", alpha=0.85
                )
        ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("mean ΔE2000 vs brute-force spectral render")
    axes[0].legend(fontsize=8, loc="upper right")
    fig.suptitle(
        f"SH tables: accuracy vs cost ({len(res['scenes'])} scenes: 2 films × 3 thicknesses × 4 roughnesses,"
        " studio/courtyard HDRIs)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def report(res: dict, command: str) -> str:
    rows = res["rows"]
    by_name = {r["cfg"].name: r for r in rows}
    base = by_name["default (auto plan)"]
    roughs = sorted(base["by_roughness"])
    lines = [
        "# Accuracy vs cost of the baked SH tables",
        "",
        f"Generated by `{command}` (from the repository root); writes this file and",
        "`docs/accuracy-vs-time.png`. `--quick` runs a smoke subset and writes nothing.",
        f"This run took {res['total']:.0f} s ({res['ref_total']:.0f} s of it for the reference renders).",
        "",
        "## Machine",
        "",
        *common.machine_lines(),
        "",
        "## Method",
        "",
        f"- **Scenes** ({len(res['scenes'])}): roughness {{{', '.join(f'{r:g}' for r in ROUGHNESSES)}}} ×",
        f"  thickness {{{', '.join(f'{d:g}' for d in THICKNESSES)}}} nm × two films — "
        + "; ".join(f"{k}: {v['label']}" for k, v in FILMS.items())
        + " — each under one of Blender's",
        "  `studio` / `courtyard` studiolights (found by `cli.studiolight`), alternating so that every",
        "  roughness and every film sees both maps. HDRIs are downsampled ×4 (1024×512 → 256×128) with",
        "  the solid-angle-conserving `hdri.downsample`; the SH projection and the reference use the",
        "  same downsampled image, so only the table/SH approximation is measured.",
        f"- **Image**: `render.sphere_view({res['sphere']}, {res['sphere']})`, {res['pixels']} sphere pixels",
        "  (background excluded).",
        "- **Ground truth**: `render.shade_reference` — no SH: per pixel the exact microfacet BRDF with",
        f"  the film's reflectance ({REFERENCE_WAVELENGTHS}-wavelength spectral quadrature, 3×3 spectral"
        " colour),",
        "  integrated against the equirect map with a 128×128 GGX-importance half-vector rule;",
        f"  {common.fmt_seconds(res['ref_time'])} per scene (median); computed once per (material, HDRI).",
        "- **Test**: `bake.bake` of the configuration, then `render.shade_sh` (the GLSL's numpy twin:",
        "  view-aligned frame, zyz SH rotation of the World's SH windowed by `render.lighting_window`,",
        "  linear table lookup, Σ M_i L_i).",
        "- **Configurations**: the default is each scene's `planner.plan` (all auto: SH order from the",
        "  lobe-truncation rule — see the *SH order* column —, 32 view angles below roughness 0.5 and",
        "  16 above, 48 wavelengths, 96×48 half-vector nodes, float32,",
        "  3×3 spectral, a 1-D table because the scene's thickness is constant). Every other row",
        "  changes one knob with the rest of that plan pinned:",
        "  - *SH order* 1–8, 10 and 12; *wavelengths*: the spectral quadrature's node count;",
        "    *view angles*: θo rows.",
        f"  - *2-D, N thickness rows*: the table spans {THICKNESS_RANGE[0]:g}–{THICKNESS_RANGE[1]:g} nm"
        " (chosen so",
        "    150/400/900 nm fall between rows for every N) and is interpolated at the scene's",
        '    thickness; "auto" is `bake.auto_thickness_samples` (8 per fringe at 360 nm: 56 rows for',
        "    the soap film, 62 for oil).",
        "  - *quadrature n_θ×n_φ*: the kernel's half-vector rule (default 96×48), by wrapping",
        "    `bake.microfacet_kernel` for the duration of the bake.",
        "  - *half precision*: the table rounded to IEEE half (`astype(float16)`; checked once to be",
        '    identical to a `table_io.write_table(..., precision="half")` / `read_table` round trip).',
        '  - *per-channel (Cycles)*: `colour_mode="per_channel"` — the film\'s RGB reflectance multiplies',
        "    light channel k (diagonal, 3 numbers per coefficient).",
        f"  - *3-wavelength RGB film*: the film evaluated at {', '.join(f'{w:g}' for w in RGB3_NM)} nm only,",
        "    one wavelength per output channel (G[j, k, c] = δ_jk δ_kc, white-preserving), by replacing",
        "    `bake.spectral_quadrature` during the bake; stored per channel.",
        "  - The ground truth is 'full spectral'.",
        '  - Every configuration bakes with `multiscatter="none"`: `render.shade_reference` integrates',
        '    single scattering only, so the Material default (`"film"`, Kulla–Conty energy compensation)',
        '    would add a difference that is not an approximation error. The row *multiscatter "film"*',
        "    shows that default against the same single-scattering truth, for scale.",
        "- **ΔE2000**: both images multiplied by one factor s = 0.8 / (95th percentile of the",
        "  reference's Rec.709 luminance over the sphere), then scene-linear Rec.709 → XYZ",
        "  (`colour.RGB_to_XYZ`, D65) → Lab (`colour.XYZ_to_Lab`, D65 white) and",
        '  `colour.delta_E(..., method="CIE 2000")` per pixel. *mean* = over all pixels of all scenes;',
        "  *p95* = 95th percentile over the same pooled pixels; *r = x* columns: mean over the scenes of",
        "  that roughness.",
        "- **Bake time**: *cold* = `bake.bake` after clearing the kernel caches (and any u-degree hint),",
        "  timed on the first scene of each roughness (4 bakes; the other scenes reuse the cache, to keep",
        "  the run short), median; *warm* = the immediately repeated bake of the same material (kernel",
        "  cached), median over all scenes. The plan is pinned, so the auto SH-order search (~50 ms)",
        "  is not included. The run sets `OPENBLAS_NUM_THREADS=1` (it re-executes itself unless the",
        "  variable is set or `--default-blas-threads` is given): on this shared 2-core machine a",
        "  second BLAS thread made cold-bake times scatter by 10× between identical kernels",
        "  (see bake-speed.md), which would have swamped the differences between configurations.",
        "- **Table size** and **per-pixel work**: means over the scenes (the auto plan's SH order and",
        "  view count depend on roughness, so they differ between scenes); *table (example)* is the",
        "  first scene's (roughness 0.15).",
        "",
        "### Per-pixel shader work (cost model)",
        "",
        "With L the SH order, K = (L+1)(L+2)/2 stored coefficients (m ≥ 0), C = 9 floats per",
        "coefficient (3×3 spectral) or 3 (per-channel, 3-wavelength), and taps = 2 (1-D table,",
        "linear in θo) or 4 (2-D, bilinear in θo × thickness):",
        "",
        "- floats fetched = taps · K · C",
        "- multiply-adds = 6 Σ_{l=0..L} (2l+1)² (two fixed ±90° x-rotations, dense per band, 3 colour",
        "  channels) + 18 L(L+1) + 12 L (three z-rotations: 4 per (l, m ≥ 1) pair per channel, and",
        "  the cos mθ / sin mθ recurrence) + taps · K · C (interpolation) + K · C (Σ M_i · L_i).",
        "",
        "E.g. "
        + "; ".join(
            f"L = {l}, {'2-D' if taps == 4 else '1-D'}, C = {c}: {shader_cost(l, c, taps)[0]} floats,"
            f" {shader_cost(l, c, taps)[1]} MADs"
            for l, c, taps in ((8, 9, 2), (8, 9, 4), (8, 3, 2), (4, 9, 2), (2, 9, 2))
        )
        + ".",
        "",
        "## Results",
        "",
        "| configuration | SH order | table (example) | float32 | half | floats fetched | MADs/pixel | cold"
        " bake | warm bake | ΔE mean | ΔE p95 | " + " | ".join(f"r = {r:g}" for r in roughs) + " |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|" + "---:|" * len(roughs),
    ]
    for r in rows:
        orders = "/".join(map(str, r["orders"]))
        lines.append(
            f"| {r['cfg'].name} | {orders} | {tuple(r['example_shape'])} |"
            f" {plan_text.fmt_bytes(int(r['bytes32']))}"
            f" | {plan_text.fmt_bytes(int(r['bytes16']))} | {r['fetched']:.0f} | {r['mads']:.0f}"
            f" | {common.fmt_seconds(r['cold'])} | {common.fmt_seconds(r['warm'])} | **{r['mean']:.2f}** |"
            f" {r['p95']:.2f} | " + " | ".join(f"{r['by_roughness'][x]:.2f}" for x in roughs) + " |"
        )
    lines += [
        "",
        "*SH order* lists the orders used across the scenes (the auto plan picks fewer bands for rougher",
        "lobes); costs and sizes are means over the scenes.",
        "",
        "### Default plan, per scene",
        "",
        "| film | thickness | roughness | HDRI | SH order | ΔE mean | ΔE p95 |",
        "|---|---:|---:|---|---:|---:|---:|",
    ]
    for p in sorted(
        base["per_scene"], key=lambda p: (p["scene"].roughness, p["scene"].thickness, p["scene"].film)
    ):
        s = p["scene"]
        lines.append(
            f"| {s.film} | {s.thickness:g} nm | {s.roughness:g} | {s.hdri} | {p['l_max']} | {p['mean']:.2f} |"
            f" {p['p95']:.2f} |"
        )
    lines += ["", "![accuracy vs cost](accuracy-vs-time.png)", "", "## What this shows", ""]
    lines += what_this_shows(res)
    return "\n".join(lines) + "\n"


def what_this_shows(res: dict) -> list[str]:
    rows = res["rows"]
    by = {r["cfg"].name: r for r in rows}
    base = by["default (auto plan)"]
    roughs = sorted(base["by_roughness"])
    out = []
    out.append(
        f"- Default plan: mean ΔE2000 {base['mean']:.2f} (p95 {base['p95']:.2f}) over all scenes; by"
        " roughness "
        + ", ".join(f"{r:g}: {base['by_roughness'][r]:.2f}" for r in roughs)
        + "; by HDRI "
        + ", ".join(f"{h}: {v:.2f}" for h, v in base["by_hdri"].items())
        + (
            " (studio's light comes from two small lamps, which a band-limited lighting SH blurs most)."
            if base["by_hdri"].get("studio", 0) > base["by_hdri"].get("courtyard", 1e9)
            else "."
        )
        + (
            " (DESIGN's estimate for roughness 0.15 vs Cycles was ΔE ≈ 9–18; here the comparison is"
            " against our own brute-force render, and roughness 0.15 gives"
            f" {base['by_roughness'][0.15]:.1f}.)"
            if 0.15 in base["by_roughness"]
            else ""
        )
        + " The error is dominated by the SH truncation of the glossy lobe and of the lighting:"
        " every other knob at its default is far below it."
    )
    top = plans.MAX_ORDER
    if f"SH order {top}" in by and max(base["orders"]) == top and min(base["orders"]) < top:
        l8 = by[f"SH order {top}"]
        diff = [x for x in roughs if abs(l8["by_roughness"][x] - base["by_roughness"][x]) > 0.05]
        if diff:
            out.append(
                f"- The auto SH order (lobe-truncation target 10 %) picks fewer than {top} bands for the"
                f" roughest lobes; forcing {top} there changes mean ΔE "
                + ", ".join(
                    f"at r = {x:g} from {base['by_roughness'][x]:.2f} to {l8['by_roughness'][x]:.2f}"
                    for x in diff
                )
                + f" (all scenes: {base['mean']:.2f} → {l8['mean']:.2f})."
            )
    sh_rows = [by[f"SH order {l}"] for l in (*range(1, 9), 10, 12) if f"SH order {l}" in by]
    if sh_rows:
        out.append(
            "- SH order (mean ΔE, MADs/pixel): "
            + ", ".join(f"L={r['cfg'].sh_order}: {r['mean']:.2f} ({r['mads']:.0f})" for r in sh_rows)
            + "."
        )
        if all(f"SH order {l}" in by for l in (2, 4, 8, 12)):
            out[-1] += (
                " Per roughness at L = 2 / 4 / 8 / 12: "
                + "; ".join(
                    f"r={x:g}: "
                    + " / ".join(f"{by[f'SH order {l}']['by_roughness'][x]:.2f}" for l in (2, 4, 8, 12))
                    for x in roughs
                )
                + "."
            )
    wl = [by[n] for n in ("6 wavelengths", "12 wavelengths", "24 wavelengths", "96 wavelengths") if n in by]
    if wl:
        out.append(
            "- Wavelengths (mean ΔE): "
            + ", ".join(f"{r['cfg'].name.split()[0]}: {r['mean']:.2f}" for r in wl)
            + f", default 48: {base['mean']:.2f}. Only the table's bake time changes (the shader cost is"
            " independent of the wavelength count)."
        )
    va = [r for r in rows if r["cfg"].group == "θo samples"]
    if va:
        out.append(
            "- View angles (mean ΔE): "
            + ", ".join(f"{r['cfg'].name.split()[0]}: {r['mean']:.2f}" for r in va)
            + "."
        )
    tr = [r for r in rows if r["cfg"].group == "thickness rows"]
    if tr:
        out.append(
            "- Thickness rows (2-D table, mean ΔE; 4 bilinear taps): "
            + ", ".join(f"{r['cfg'].name.split(', ')[1]}: {r['mean']:.2f}" for r in tr)
            + f" vs the exact-thickness 1-D table {base['mean']:.2f}."
        )
    qd = [r for r in rows if r["cfg"].group == "quadrature"]
    if qd:
        out.append(
            "- Kernel quadrature (mean ΔE, cold bake): "
            + ", ".join(
                f"{r['cfg'].name.split()[1]}: {r['mean']:.2f}, {common.fmt_seconds(r['cold'])}" for r in qd
            )
            + f"; default 96×48: {base['mean']:.2f}, {common.fmt_seconds(base['cold'])}."
        )
    if "half-precision table" in by:
        h = by["half-precision table"]
        out.append(
            f"- Half precision: mean ΔE {h['mean']:.3f} vs {base['mean']:.3f} in float32 (half the bytes);"
            + (
                f" 2-D auto table {by['2-D auto, half precision']['mean']:.3f} vs"
                f" {by['2-D, auto thickness rows']['mean']:.3f}."
                if "2-D auto, half precision" in by and "2-D, auto thickness rows" in by
                else ""
            )
        )
    if "per-channel (Cycles) film" in by and "3-wavelength RGB film" in by:
        pc, r3 = by["per-channel (Cycles) film"], by["3-wavelength RGB film"]
        out.append(
            f"- Colour modes (mean / p95 ΔE): 3×3 spectral {base['mean']:.2f} / {base['p95']:.2f};"
            f" per-channel (Cycles) {pc['mean']:.2f} / {pc['p95']:.2f}; three-wavelength RGB film"
            f" {r3['mean']:.2f} / {r3['p95']:.2f}, at a third of the fetches of 3×3"
            f" ({pc['fetched']:.0f} vs {base['fetched']:.0f} floats). Per roughness, the colour-mode error"
            " is visible on top of the SH error mainly where the SH error is small (rough lobes): "
            + "; ".join(
                f"r={x:g}: {base['by_roughness'][x]:.2f} / {pc['by_roughness'][x]:.2f} /"
                f" {r3['by_roughness'][x]:.2f}"
                for x in roughs
            )
            + " (spectral / per-channel / RGB)."
        )
    for key, label in (("mads", "per-pixel work"), ("cold", "cold bake time")):
        front = pareto([(r[key], r["mean"]) for r in rows])
        out.append(
            f"- Pareto front in mean ΔE vs {label} (plot): "
            + " → ".join(f"{rows[i]['cfg'].name} ({rows[i]['mean']:.2f})" for i in front)
            + "."
        )
    if 'multiscatter "film" (Material default)' in by:
        ms = by['multiscatter "film" (Material default)']
        out.append(
            f"- Multiple-scattering compensation (the Material default) against the single-scattering truth:"
            f" mean ΔE {ms['mean']:.2f} vs {base['mean']:.2f} without; by roughness "
            + ", ".join(f"{x:g}: {ms['by_roughness'][x]:.2f}" for x in roughs)
            + ". This is the energy the compensation adds, not an error of the table."
        )
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke run (< 1 min); prints, writes nothing")
    parser.add_argument(
        "--default-blas-threads",
        action="store_true",
        help="keep OpenBLAS's default thread count (by default the run re-executes itself with"
        " OPENBLAS_NUM_THREADS=1 so that bake times on a shared machine are comparable)",
    )
    args = parser.parse_args(argv)
    if not args.default_blas_threads and "OPENBLAS_NUM_THREADS" not in os.environ:
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
        cmd = [sys.executable, "-m", "benchmarks.accuracy_vs_time", *(sys.argv[1:] if argv is None else argv)]
        os.execve(sys.executable, cmd, env)
    start = time.perf_counter()
    planner.plan(Material())  # load CMF tables etc. before any timing
    if args.quick:
        res = run(quick_scenes(), quick_configs(), sphere=16)
        print(report(res, ".venv/bin/python -m benchmarks.accuracy_vs_time --quick"))
        print(f"quick run: {time.perf_counter() - start:.1f} s (nothing written)")
        return
    res = run(all_scenes(), all_configs())
    plot(res, os.path.join(common.ROOT, "docs", "accuracy-vs-time.png"))
    text = report(res, ".venv/bin/python -m benchmarks.accuracy_vs_time")
    path = common.write_doc("accuracy-vs-time.md", text)
    print(text)
    print(f"wrote {path} and accuracy-vs-time.png in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
