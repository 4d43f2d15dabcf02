"""The benchmark's configuration: resolutions, scenes, orders, the film and its roughness cases."""

from __future__ import annotations

from precompute.materials.material import Layer, Material
from precompute.shading import policy

EXTENSION_ID = "thinfilm_sh"
BASELINE_ID = "thinfilm_sh_baseline"

RESOLUTIONS = {"720p": (1280, 720), "1080p": (1920, 1080), "4K": (3840, 2160)}
OBJECT_COUNTS = (1, 10, 100)
TRIANGLES = (10_000, 100_000, 1_000_000, 2_000_000)
#: 4K only for these (objects, triangles): a Workbench frame takes 6-9 s there on llvmpipe.
CELLS_4K = ((10, 10_000), (10, 2_000_000))
#: The headline is l_max = 2 (bands l ≤ 2; docs/conventions.md: "SH order" is l_max).
HEADLINE_L = 2
SWEEP_L = (*range(1, 9), 10, 12)
#: The scene of the order sweep and of the split-sum comparison: (objects, triangles).
SWEEP_SCENE = (10, 100_000)
SPLIT_SUM_L = (2, 5, 8, 12)
#: Frames of the Python-time part (per scene, after 3 warm-up frames).
PYTHON_FRAMES = 25
#: Acceptance: ours ≤ 2× Workbench at order 3, 1080p.
RATIO_LIMIT = 2.0
HDRI = "studio"
#: The last full run's measurements (``--report-only`` rewrites the report from them); not in git.
RESULTS_JSON = "out/viewport-benchmark.json"

#: The film: 400 nm of n = 1.33 on glass, constant thickness, spectral.
FILM = Material(layers=(Layer(1.33, 400.0),), substrate=1.5)


def roughness_cases() -> dict[str, float]:
    """Roughness of the SH-only, combined (both halves) and split-sum-only films (policy.SH_BLEND)."""
    lo, hi = policy.SH_BLEND
    return {"sh": min(hi + 0.1, 1.0), "combined": 0.5 * (lo + hi), "split": max(lo - 0.05, 0.0)}


#: Roughness of the glossy, medium and rough films of :func:`automatic_orders` (issue 16).
AUTOMATIC_ROUGHNESS = {"glossy": 0.05, "medium": 0.3, "rough": 0.6}
