"""Per-pixel SH shading (the shader's numpy reference) against rotations and the ground truth."""

import math

import numpy as np
import pytest

from precompute.bakes import bake
from precompute.materials.material import Layer, Material, Quality
from precompute.output import image_io, render
from precompute.sh import harmonics, projection, rotations
from precompute.shading import frame as shading_frame
from precompute.shading import policy, sh_rotation, sh_sum, split_sum, table


def random_unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_view_aligned_frame_is_orthonormal_right_handed_and_stable():
    rng = np.random.default_rng(1)
    n = random_unit(rng, 200)
    v = random_unit(rng, 200)
    v[:5] = n[:5]  # v ∥ n
    v[5:10] = -n[5:10]
    n[10:12] = [[0, 0, 1], [0, 0, -1]]
    v[10:12] = [[0, 0, 1], [0, 0, -1]]
    f = shading_frame.view_aligned_frame(n, v)
    assert np.all(np.isfinite(f))
    assert np.allclose(f @ np.swapaxes(f, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(f), 1.0, atol=1e-12)
    assert np.allclose(f[:, 2], n)
    ok = slice(12, None)
    assert np.all(np.einsum("ni,ni->n", f[ok, 1], v[ok]) < 1e-12)  # view lies in the xz-plane
    assert np.all(np.einsum("ni,ni->n", f[ok, 0], v[ok]) >= -1e-12)  # with φ = 0


@pytest.mark.parametrize("l_max", [2, 5, 8])
def test_zyz_rotation_equals_general_rotation_including_poles(l_max):
    rng = np.random.default_rng(l_max)
    n = random_unit(rng, 40)
    n[:4] = [[0, 0, 1], [0, 0, -1], [1e-9, 0, 1], [0, -1e-9, -1]]
    v = random_unit(rng, 40)
    frames = shading_frame.view_aligned_frame(n, v)
    world = rng.normal(size=((l_max + 1) ** 2, 3))
    fast = sh_rotation.local_coefficients(world, frames, l_max)
    for p in range(frames.shape[0]):
        expected = rotations.rotation(l_max, frames[p]) @ world
        # Rows 2–3 tilt 1e-9 off the pole, below GIMBAL_SIN: treated as the pole, they err by
        # O(tilt · l) ≈ 1e-8; every other frame, exact poles included, agrees to rounding.
        tol = 1e-7 if p in (2, 3) else 1e-10
        assert np.max(np.abs(fast[p] - expected)) <= tol


def test_local_coefficients_describe_the_rotated_function():
    # f_local(d) must equal f_world(frameᵀ d): evaluate both at random directions.
    rng = np.random.default_rng(7)
    l_max = 6
    world = rng.normal(size=((l_max + 1) ** 2, 1))
    frame = shading_frame.view_aligned_frame(random_unit(rng, 1), random_unit(rng, 1))[0]
    local = sh_rotation.local_coefficients(world, frame[None], l_max)[0]
    d = random_unit(rng, 50)
    assert np.allclose(
        harmonics.basis(l_max, d) @ local, harmonics.basis(l_max, d @ frame) @ world, atol=1e-10
    )


def test_constant_environment_gives_the_directional_albedo_everywhere():
    material = Material(
        layers=(Layer(1.33, 420.0),), roughness=0.5, quality=Quality(sh_order=4, view_samples=33)
    )
    result = bake.bake(material)
    world = np.zeros((25, 3))
    world[0] = math.sqrt(4 * math.pi)  # radiance 1 everywhere
    rng = np.random.default_rng(3)
    n = random_unit(rng, 300)
    v = random_unit(rng, 300)
    v = np.where(np.sum(n * v, -1, keepdims=True) < 0, -v, v)
    out = sh_sum.shade_sh(result, world, n, v)
    cos_o = np.sum(n * v, -1)
    albedo = table.lookup(result.data, cos_o)[:, 0] @ np.full(3, math.sqrt(4 * math.pi))
    # Rotating a constant changes nothing: the result is the l = 0 albedo at θo, to rounding.
    assert np.allclose(out, np.maximum(albedo, 0), atol=1e-12)


def test_sh_render_converges_to_ground_truth_for_a_rough_film():
    # Rough lobe + smooth environment: SH at l = 8 should approach the brute-force render.
    material = Material(
        layers=(Layer(1.33, 380.0),),
        roughness=0.8,
        multiscatter="none",
        quality=Quality(sh_order=8, view_samples=32),
    )
    result = bake.bake(material)
    h, w = 64, 128
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = 2 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    d = np.stack(
        np.broadcast_arrays(
            np.sin(theta)[:, None] * np.cos(phi),
            np.sin(theta)[:, None] * np.sin(phi),
            np.cos(theta)[:, None] + 0 * phi,
        ),
        -1,
    )
    image = np.stack(
        [1 + 0.8 * d[..., 2], 1 + 0.5 * d[..., 0], 1 - 0.3 * d[..., 1]], -1
    )  # band-limited, l ≤ 1
    coeffs = projection.project_equirect(image, 8)
    rng = np.random.default_rng(5)
    n = random_unit(rng, 12)
    v = shading_frame.view_aligned_frame(n, random_unit(rng, 12))[:, 0] * 0.6 + n * 0.8
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    fast = sh_sum.shade_sh(result, coeffs, n, v)
    truth = render.shade_reference(material, image, n, v)
    # l ≤ 1 lighting is represented exactly, so only the table's θo interpolation (32 samples),
    # the 4097-sample u tabulation and quadrature remain: measured ≤ 0.4 % of the value.
    assert np.allclose(fast, truth, rtol=1e-2, atol=1e-3)


def test_images_write(tmp_path):
    """PNG and EXR writers produce valid files; an EXR reads back the written values (float32)."""
    img = np.linspace(0, 1, 4 * 5 * 3).reshape(4, 5, 3)
    image_io.write_png(tmp_path / "a.png", image_io.srgb_encode(img))
    assert (tmp_path / "a.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image_io.write_exr(tmp_path / "a.exr", img)
    from precompute.world import hdri

    assert np.allclose(hdri.read_equirect(tmp_path / "a.exr"), img, atol=1e-7)


def test_hdr_sun_of_1e5_stays_finite_and_firefly_free():
    from precompute.world import prefilter

    h, w = 64, 128
    image = np.full((h, w, 3), 0.2)
    image[10, 40] = 1e5  # a one-pixel sun, 5·10⁵ × the sky
    material = Material(
        layers=(Layer(1.33, 450.0),), roughness=0.3, quality=Quality(sh_order=8, view_samples=16)
    )
    result = bake.bake(material)
    coeffs = projection.project_equirect(image, 8) * policy.lighting_window(8, 0.3)[:, None]
    rng = np.random.default_rng(11)
    n = random_unit(rng, 400)
    v = shading_frame.view_aligned_frame(n, random_unit(rng, 400))[:, 0] * 0.5 + n
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    pre = prefilter.prefilter(image)
    outputs = {
        "sh": sh_sum.shade_sh(result, coeffs, n, v),
        "split": split_sum.shade_split_sum(result, pre, n, v),
        "reference": render.shade_reference(material, image, n[:40], v[:40], n_theta=32, n_phi=32),
    }
    for name, out in outputs.items():
        assert np.all(np.isfinite(out)) and np.all(out >= 0), name
    # No fireflies from the prefilter: the lobe's weight per steradian is pdf(l)(n·l)/N with
    # pdf(l) = D(h)/4 ≤ 1/(4πα²) (n = v) and N = ∫ pdf (n·l) dl, so a sun of energy E (1e5 × its
    # pixel's solid angle) adds at most E/(4πα² N) to a texel of a level of roughness √α, and
    # never more than its own radiance. Factor 4: a sample reads the mip level whose texel is
    # at most its footprint (LOD_BIAS 0, lod rounded down → up to 4× smaller in solid angle),
    # so a one-pixel sun is concentrated up to 4× over the smooth bound; a firefly (a sample
    # reading the sun unfiltered at level 0) would exceed it by orders of magnitude.
    from precompute import brdf

    sun_energy = 1e5 * (2 * np.pi / w) * (np.pi / h) * np.sin(np.pi * 10.5 / h)
    for r, level in zip(pre.roughness, pre.levels, strict=True):
        assert np.isfinite(level).all()
        if r > 0:
            alpha = r**2
            hh, ww = brdf.ggx_importance_grid(alpha, 64, 8)
            norm = np.sum(ww * np.maximum(2 * hh[:, 2] ** 2 - 1, 0))
            bound = min(4 * sun_energy / (4 * np.pi * alpha**2 * norm), 1e5)
            assert level.max() < bound + 0.2, (r, level.max(), bound)
    assert pre.rejected_pixels == 0
    nan_image = image.copy()
    nan_image[5, 5] = np.nan
    assert prefilter.prefilter(nan_image).rejected_pixels == 1
