"""What the GPU frame benchmark draws and times: scenes, cases, frame sizes, rounds (no imports
beyond the standard library: every side of the benchmark reads them)."""

from __future__ import annotations

from pathlib import Path

#: The repository root (benchmarks/gpu_frame/ is two folders down).
ROOT = Path(__file__).resolve().parents[2]

#: Frame size of the timed frames and of the pictures that ``check`` compares.
RESOLUTION = (1920, 1080)
CHECK_SIZE = (480, 270)
#: The scenes: (objects, triangles), l_max values, film cases, World lamps (viewport/config.py's constants
#: are read in ``prepare``; these must agree with them and are checked there).
SCENES = {
    "sweep": {"layout": (10, 100_000), "l_max": (2, 5, 8, 12), "cases": ("sh", "combined", "split")},
    "grid": {"layout": (1, 1_000_000), "l_max": (4, 2), "cases": ("sh",)},
    # issue 16: glossy / medium / rough films (viewport.AUTOMATIC_ROUGHNESS) at their automatic
    # order, as the product draws them (medium and rough: SH half from the outgoing-radiance grid)
    # and, case "<film>-perpixel", with the per-pixel SH instead; lamps on only.
    "automatic": {"layout": (1, 1_000_000), "l_max": ("auto",), "cases": ("glossy", "medium", "rough")},
}
#: Scenes drawn with the World's lamps on only.
LAMPS_ON_ONLY = ("automatic",)
LAMPS = (True, False)
#: Scenes and orders whose films are also drawn with the table read from its texture (case
#: "<case>-tex"): what a hardware GPU draws (policy.TABLE_UBO_DEVICES), since ``prepare`` runs on
#: llvmpipe, which draws small tables from the uniform buffer.
TEXTURE_CASES_SCENES = ("sweep", "grid")
#: Sweep orders whose SH-only film (lamps on, table from the texture) is also drawn with the
#: generic rotation loops of :data:`REFERENCE_ROTATION` instead of the generated X(±90°) code
#: (case "sh-loops"; ``gpu.shaders.ShaderCache(reference_rotation=REFERENCE_ROTATION)``).
LOOP_CASES_L = (8, 12)
#: The reference rotation of the shading library (tests only, never shipped).
REFERENCE_ROTATION = ROOT / "tests" / "glsl" / "tf_sh_rotate_loops.glsl"
TEXTURE_CASES_L = (2, 4, 5, 8)
#: Warm-up frames per case and timed rounds per scene (every case once a round).
WARMUP = 5
ROUNDS = 40
#: Cases whose full-size picture ``measure --pictures`` writes as PNG (at most this many).
PNG_CASES = ("sweep-l5-sh-lamps", "sweep-l5-combined-lamps", "sweep-l5-split-lamps", "grid-l4-sh-lamps")
#: Arrays above this many bytes are stored as byte planes (compresses float data far better).
SHUFFLE_BYTES = 1 << 20
FORMAT_VERSION = 1
#: The acceptance figure for a GPU (issue: 1080p, 1 M triangles, l_max = 4).
FPS_TARGET = 240.0
DOC = "gpu-frame.md"


def case_id(scene: str, l_max: int, case: str, lamps: bool) -> str:
    return f"{scene}-l{l_max}-{case}-{'lamps' if lamps else 'nolamps'}"
