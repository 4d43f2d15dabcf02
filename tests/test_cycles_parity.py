"""Our physics against Cycles' Principled BSDF thin film (same parameters, same meaning).

The brute-force spectral render (no SH: exact film reflectance in the microfacet BRDF,
integrated against the environment) must agree with a Cycles render of a Principled BSDF with
Thin Film Thickness / IOR, IOR and Roughness set to the same values. This pins the meaning of
every parameter: thickness in nm, film IOR, base IOR, α = roughness², film on the microfacets.
"""

import numpy as np
import pytest

from benchmarks import cycles_compare as cc
from precompute import hdri, render
from precompute.material import Layer, Material

pytestmark = pytest.mark.blender


@pytest.mark.parametrize(
    ("thickness", "film_ior", "base_ior", "roughness"), [(800.0, 1.33, 1.5, 0.3), (350.0, 1.8, 1.5, 0.5)]
)
def test_brute_force_render_matches_cycles_principled_thin_film(thickness, film_ior, base_ior, roughness):
    size, spp = 40, 128
    path = cc.studiolight("courtyard")
    ref = cc.cycles_render(path, thickness, film_ior, base_ior, roughness, samples=spp, size=size)
    image = hdri.read_equirect(path)
    while image.shape[1] > 512:
        image = hdri.downsample(image, 2)
    # Single scattering on our side, as Cycles' base IOR 1.5 compensation adds < 1 % here.
    material = Material(
        layers=(Layer(film_ior, thickness),),
        substrate=base_ior,
        roughness=roughness,
        colour_mode="per_channel",
        multiscatter="none",
    )
    view = render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG, supersample=2)
    ours = render.equirect_lookup(image, view.rays)
    ours[view.mask] = render.shade_reference(
        material, image, view.normals[view.mask], view.views[view.mask], n_theta=48, n_phi=48
    )
    ours = render.box_downsample(ours, 2)
    mask = cc.object_mask(render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG))
    de = cc.delta_e_2000(ours[mask], ref[mask], ref[mask])
    # Measured 1.47 (800 nm, r 0.3) and 2.38 (350 nm, n 1.8, r 0.5) mean ΔE2000 at these settings
    # (40 px, 128 spp, Cycles' fixed seed; its own noise at 128 spp is ≈ 0.7–0.9).
    # 3.0 would still catch any parameter read differently (e.g. α = roughness instead of
    # roughness² gives > 8, a thickness in µm gives > 15).
    assert float(np.mean(de)) <= 3.0, float(np.mean(de))
