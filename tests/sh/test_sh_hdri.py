"""HDRI I/O, downsampling and SH irradiance accuracy on Blender's studiolights.

The studiolights ship with the ``bpy`` wheel (``<bpy>/5.2/datafiles/studiolights/world``); the
directory is located with ``importlib.util.find_spec`` without importing bpy, and the
accuracy tests are skipped when it is absent.

Gate: for every map, the SH irradiance at l_max = 8 is within 2 % of the brute-force
irradiance, measured per R, G, B channel as mean_n |E_sh − E_bf| / mean_n E_bf over 200
Fibonacci normals (the worst of the three channels; per channel is stricter than luminance
for coloured maps such as sunrise/sunset). The l_max = 2 (9-coefficient) figures are printed
and written to docs/sh-irradiance.md but not gated. Run with ``-s`` to see the table.
"""

from __future__ import annotations

import functools
import os

import numpy as np
import pytest
from _sh_irradiance import (
    DOWNSAMPLE_FACTOR,
    N_NORMALS,
    format_irradiance_table,
    irradiance_errors,
    studiolight_irradiance_table,
    studiolight_paths,
)

from precompute.sh import projection
from precompute.world import hdri

#: Gate on the per-channel mean error at l_max = 8. A single point light has a 2.4 % mean
#: truncation error at l ≤ 8 (benchmarks.sh_projection.point_light_truncation_error); real maps
#: spread their power, and measure 0.2–1.5 %. 2 % is the requirement and leaves ≥ 0.46 % margin.
MAX_MEAN_REL_ERROR_L8 = 0.02

PATHS = studiolight_paths()
needs_studiolights = pytest.mark.skipif(not PATHS, reason="bpy studiolights not installed")


@functools.lru_cache(maxsize=1)
def _table() -> tuple[dict, ...]:
    return tuple(studiolight_irradiance_table(PATHS, l_maxes=(2, 8)))


def _row(name: str) -> dict:
    return next(r for r in _table() if r["map"] == name)


@needs_studiolights
def test_studiolights_found():
    """Blender's bundled studio lights are found (all eight), so the HDRI tests exercise every World an
    artist can pick."""
    names = {os.path.basename(p) for p in PATHS}
    # Blender 5.2 ships eight world studiolights; all of them must be exercised.
    assert {"city.exr", "forest.exr", "studio.exr", "sunrise.exr"} <= names
    assert len(names) >= 8


@needs_studiolights
@pytest.mark.parametrize("name", [os.path.basename(p) for p in PATHS])
def test_sh_irradiance_l8_within_two_percent(name):
    row = _row(name)
    r8 = row[8]
    print(
        f"\n{name}: l≤8 mean {100 * r8['mean_rel_lum']:.2f} %"
        f" (worst ch. {100 * r8['mean_rel_worst_channel']:.2f} %),"
        f" l≤2 mean {100 * row[2]['mean_rel_lum']:.2f} %"
    )
    assert r8["rejected_pixels"] == 0
    assert r8["mean_rel_worst_channel"] <= MAX_MEAN_REL_ERROR_L8
    # l ≤ 8 must improve on 9 coefficients for every map (truncation error falls with l).
    assert r8["mean_rel_lum"] < row[2]["mean_rel_lum"]


@needs_studiolights
def test_print_irradiance_table():
    """Prints the SH-vs-brute-force irradiance table for the docs and checks it has a row per HDRI."""
    table = format_irradiance_table(list(_table()))
    print(
        f"\nSH irradiance vs brute force ({N_NORMALS} normals, maps downsampled ×{DOWNSAMPLE_FACTOR}):\n"
        + table
    )
    assert table.count("\n") == len(_table()) + 1


@needs_studiolights
def test_downsampling_barely_changes_irradiance():
    """Downsampling an HDRI changes its irradiance by ≤ 1 % (measured 0.32 %): comparing on small
    maps is justified."""
    # Justifies comparing on 256×128 images: irradiance is a cosine-lobe (low-pass) integral,
    # and the solid-angle-weighted box filter conserves each block's power exactly. Measured
    # ≤ 0.32 % (sunrise.exr, sun near the horizon where row solid angles change fastest).
    path = next(p for p in PATHS if os.path.basename(p) == "sunrise.exr")
    full = hdri.read_equirect(path)
    small = hdri.downsample(full, DOWNSAMPLE_FACTOR)
    normals = hdri.fibonacci_sphere(50)
    e_full = hdri.irradiance_brute_force(full, normals)
    e_small = hdri.irradiance_brute_force(small, normals)
    assert np.mean(np.abs(e_small - e_full)) / np.mean(e_full) <= 0.01


# ----------------------------------------------------------------------------------------------
# read_equirect / downsample (no bpy needed)
# ----------------------------------------------------------------------------------------------


def _write_exr(path, channels: dict) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    # The binding replaces the dict's arrays with Channel objects: hand it a copy.
    OpenEXR.File(header, dict(channels)).write(str(path))


def test_read_equirect_rgba_drops_alpha(tmp_path):
    rng = np.random.default_rng(0)
    rgba = rng.random((8, 16, 4)).astype(np.float32)
    rgba[1, 2, 0] = np.nan  # NaN survives reading
    path = tmp_path / "rgba.exr"
    _write_exr(path, {"RGBA": rgba})
    img = hdri.read_equirect(path)
    assert img.dtype == np.float32 and img.shape == (8, 16, 3)
    assert np.isnan(img[1, 2, 0])
    np.testing.assert_array_equal(np.nan_to_num(img), np.nan_to_num(rgba[..., :3]))


def test_read_equirect_separate_channels(tmp_path):
    """An EXR with separate R, G, B (and extra) channels is read into the right RGB planes."""
    rng = np.random.default_rng(1)
    planes = {c: rng.random((4, 8)).astype(np.float32) for c in "RGB"}
    planes["Z"] = np.zeros((4, 8), np.float32)
    path = tmp_path / "sep.exr"
    _write_exr(path, planes)
    img = hdri.read_equirect(path)
    for i, c in enumerate("RGB"):
        np.testing.assert_array_equal(img[..., i], planes[c])


def test_read_equirect_errors(tmp_path):
    """Missing files, non-EXR files and EXRs without RGB are refused with the reason named."""
    with pytest.raises(FileNotFoundError, match="path"):
        hdri.read_equirect(tmp_path / "missing.exr")
    text = tmp_path / "not.exr"
    text.write_text("hello")
    with pytest.raises(ValueError, match="not an OpenEXR"):
        hdri.read_equirect(text)
    depth = tmp_path / "depth.exr"
    _write_exr(depth, {"Z": np.zeros((4, 8), np.float32)})
    with pytest.raises(ValueError, match="R, G, B"):
        hdri.read_equirect(depth)


def test_downsample_conserves_power_per_block():
    rng = np.random.default_rng(2)
    img = rng.lognormal(size=(64, 128, 3))
    small = hdri.downsample(img, 4)
    assert small.shape == (16, 32, 3)
    d_big = hdri.equirect_solid_angles(64, 128)[..., None]
    d_small = hdri.equirect_solid_angles(16, 32)[..., None]
    power_big = (img * d_big).reshape(16, 4, 32, 4, 3).sum(axis=(1, 3))
    # Exact up to rounding: Σ L dω over each 4×4 block equals L_out dω_out.
    np.testing.assert_allclose(small * d_small, power_big, rtol=1e-12)
    # Hence the l = 0 coefficient (Y_00 ∫ L dω) is unchanged to rounding, for any image.
    delta = projection.project_equirect(small, 2)[0] - projection.project_equirect(img, 2)[0]
    assert np.max(np.abs(delta)) <= 1e-12
    # A plain (unweighted) box average would not conserve it: the filter is doing real work.
    plain = img.reshape(16, 4, 32, 4, 3).mean(axis=(1, 3))
    assert (
        np.max(np.abs(projection.project_equirect(plain, 0)[0] - projection.project_equirect(img, 0)[0]))
        > 1e-4
    )


def test_downsample_bad_input():
    """Downsampling refuses factors that do not divide the image and bad shapes, with the argument named."""
    with pytest.raises(ValueError, match="factor"):
        hdri.downsample(np.zeros((6, 12, 3)), 4)
    with pytest.raises(ValueError, match="factor"):
        hdri.downsample(np.zeros((8, 16, 3)), 0)
    with pytest.raises(ValueError, match="image"):
        hdri.downsample(np.zeros(8), 2)


def test_irradiance_errors_on_uniform_map_are_tiny():
    # A constant map has E ≡ π·L exactly in SH (only l = 0); brute force integrates the clamped
    # cosine with the pixel rule, accurate to O(1/H²) ≈ 1e-4 at 64 rows.
    img = np.ones((64, 128, 3))
    r = irradiance_errors(img, 2, hdri.fibonacci_sphere(40))
    assert r["mean_rel_worst_channel"] <= 1e-3
