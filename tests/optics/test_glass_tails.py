"""The lamps in rough glass's tails (precompute/shading/glass/tails.py) against independent
references: a Monte Carlo of GGX facets at each face of a path (Snell's law through each tilted
facet, no small-angle algebra), and the GGX reflection lobe of precompute/brdf.py."""

import numpy as np
import pytest

from precompute import brdf
from precompute.shading.glass import refract, tails
from precompute.world.lamps import Lamps

ETA = 1.5
ALPHA = 1e-3
SAMPLES = 400_000


def _facets(normal, tangent, rng, count):
    """``count`` GGX facet normals (α = ALPHA) about the unit ``normal``, ``tangent`` the plane
    of incidence's axis on the face: slopes drawn as GGX distributes them (tan²θₘ = α² u / (1 − u))."""
    u = rng.random(count)
    phi = 2.0 * np.pi * rng.random(count)
    slope = ALPHA * np.sqrt(u / (1.0 - u))
    across = np.cross(normal, tangent)
    m = (
        normal[None]
        - (slope * np.cos(phi))[:, None] * tangent[None]
        - (slope * np.sin(phi))[:, None] * across[None]
    )
    return m / np.linalg.norm(m, axis=-1, keepdims=True)


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tail(deviation, width):
    """P(|deviation| > 8 × width) and GGX's slope marginal there, 1 − t / √(t² + a²)."""
    t = 8.0 * width
    return np.mean(np.abs(deviation) > t), 1.0 - t / np.hypot(t, width)


def _path(cos_outside, cos_exit, reflections, rng):
    """Rays through a prism in the x–z plane: in through a rough top face at cos θₒ, reflected
    ``reflections`` (0 or 1) times by a rough face, out through a rough face met at cos θₓ
    inside; (deviation in the plane, across it) of each from the smooth path, and the smooth
    path's cosines."""
    top = np.array([0.0, 0.0, 1.0])
    s = np.sqrt(1.0 - cos_outside**2)
    incident = np.array([s, 0.0, -cos_outside])
    inside = _unit(refract.refract(incident, top, 1.0 / ETA))
    d = np.broadcast_to(incident, (SAMPLES, 3))
    rough = _unit(refract.refract(d, _facets(top, np.array([1.0, 0.0, 0.0]), rng, SAMPLES), 1.0 / ETA))
    smooth = inside
    if reflections:  # a face below, at normal incidence to the ray: it sends it straight back
        wall = -inside  # the face's normal, facing the ray
        tangent = _unit(np.cross(wall, [0.0, 1.0, 0.0]))
        m = _facets(wall, tangent, rng, SAMPLES)
        rough = rough - 2.0 * np.sum(rough * m, -1, keepdims=True) * m
        smooth = smooth - 2.0 * (smooth @ wall) * wall
    # the exit face: its outward normal at angle acos(cos_exit) from the smooth ray, in the plane
    angle = np.arccos(cos_exit)
    side = _unit(np.cross([0.0, 1.0, 0.0], smooth))  # in the plane, perpendicular to the ray
    outward = np.cos(angle) * smooth + np.sin(angle) * side
    tangent = _unit(np.cross([0.0, 1.0, 0.0], outward))
    m = _facets(-outward, tangent, rng, SAMPLES)  # facing the ray
    out = refract.refract(rough, m, ETA)
    straight = _unit(refract.refract(smooth, -outward, ETA))
    ok = np.linalg.norm(out, axis=-1) > 0.5  # facets past the critical angle reflect: not this path
    out = _unit(out[ok])
    e1 = _unit(np.cross([0.0, 1.0, 0.0], straight))
    along = out @ straight
    return (out @ e1) / along, out[:, 1] / along, inside @ -top


@pytest.mark.parametrize(
    ("cos_outside", "cos_exit", "reflections"),
    [(1.0, 0.95, 0), (0.5, 0.9, 0), (0.27, 0.77, 0), (0.985, 0.985, 1)],
)
def test_the_spread_of_a_path_is_what_its_rough_faces_give(cos_outside, cos_exit, reflections):
    """Through three rough faces (or two), each facet drawn from GGX and the ray refracted or
    reflected by it exactly: the tails of the directions the path leaves in, in its plane and
    across it, are GGX's slope marginals of widths √(s α²) (path_spread), within Monte Carlo
    noise (≈ 3 %) and the model's neglect of a facet's cosine; the grazing case (cos θₒ 0.27, an
    exit 2.2° inside the critical angle: every earlier turn magnified 4×) is where the glow of a
    ball's rim comes from."""
    rng = np.random.default_rng(7)
    x, y, _cos_inside = _path(cos_outside, cos_exit, reflections, rng)
    spread = tails.path_spread([cos_outside], [cos_exit], ETA, reflections)[0]
    for deviation, s, name in ((x, spread[0], "in the plane"), (y, spread[1], "across")):
        measured, model = _tail(deviation, np.sqrt(s) * ALPHA)
        case = f"cos {cos_outside}, {cos_exit}, k {reflections} {name}"
        print(f"{case}: s {s:.3f}, tail {measured:.5f} vs {model:.5f}")
        assert measured == pytest.approx(model, rel=0.1)


def test_the_spread_is_wider_in_the_plane_near_the_critical_angle():
    """Leaving near the critical angle magnifies every earlier turn in the plane of incidence,
    not across it: the lobe is a streak across a ball's rim."""
    near, far = tails.path_spread([0.27, 0.27], [0.76, 0.99], ETA)
    assert near[0] > 10.0 * far[0] and near[0] > 10.0 * near[1]


def test_a_lamps_tail_is_ggxs_reflection_lobe():
    """With no lamp radius (GLASS_TAIL_CORE 0) and a single reflection's spread at normal
    incidence (s = 4 both ways), a lamp's radiance in the tails is the GGX reflection lobe D(h) /
    (4 v·h) × its power (precompute.brdf.D_ggx), away from its peak; and the lobe holds all the
    lamp's power."""
    import precompute.shading.glass.tails as module

    roughness = 0.05
    alpha = roughness**2
    out = np.array([[0.0, 0.0, 1.0]])
    angles = np.array([3.0, 6.0, 12.0, 24.0]) * alpha  # ψ, well outside the peak
    lamps = Lamps(np.stack([np.sin(angles), np.zeros(4), np.cos(angles)], -1), np.ones((4, 3)))
    spread = np.array([[4.0, 4.0]])
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(module, "GLASS_TAIL_CORE", 0.0)
        got = np.array(
            [
                tails.lamp_tails(
                    np.zeros((1, 3)), out, out, spread, roughness, Lamps(d[None], np.ones((1, 3)))
                )[0, 0]
                for d in lamps.directions
            ]
        )
        h = _unit(lamps.directions + out)
        expected = brdf.D_ggx(h[:, 2], alpha) / (4.0 * np.sum(h * out, -1))
        print("tail / GGX lobe:", np.round(got / expected, 4))
        np.testing.assert_allclose(got, expected, rtol=0.02)
        # the whole lobe: a grid of lamps over the sphere around the exit direction, ∫ dω = 1
        t = np.linspace(0.0, 60.0 * alpha, 1201)[1:]
        ring = np.array(
            [
                tails.lamp_tails(
                    np.zeros((1, 3)),
                    out,
                    out,
                    spread,
                    roughness,
                    Lamps(np.array([[np.sin(a), 0, np.cos(a)]]), np.ones((1, 3))),
                )[0, 0]
                for a in t
            ]
        )
        dt = t[1] - t[0]
        total = np.sum(ring * 2.0 * np.pi * np.sin(t)) * dt
        print(f"lobe within 60 α: {total:.4f} (GGX: {1 - 1 / (1 + (60 / 2) ** 2):.4f})")
        assert total == pytest.approx(1.0 - 1.0 / (1.0 + 30.0**2), abs=0.01)


def test_a_lamps_own_image_is_not_counted_twice():
    """Inside a lamp's radius the tails fade to nothing (the World's sharp level shows the lamp),
    and a lamp much larger than the lobe adds only the lobe's share outside it."""
    out = np.array([[0.0, 0.0, 1.0]])
    lamp = Lamps(np.array([[0.0, 0.0, 1.0]]), np.ones((1, 3)))
    assert tails.lamp_tails(np.zeros((1, 3)), out, out, np.array([[4.0, 4.0]]), 0.05, lamp)[0, 0] == 0.0
    lamp_off = Lamps(_unit(np.array([[0.2, 0.0, 1.0]])), np.ones((1, 3)))
    narrow = tails.lamp_tails(np.zeros((1, 3)), out, out, np.array([[4.0, 4.0]]), 0.05, lamp_off)[0, 0]
    wide = tails.lamp_tails(np.zeros((1, 3)), out, out, np.array([[400.0, 400.0]]), 0.05, lamp_off)[0, 0]
    assert 0.0 < narrow < wide
    # smooth glass, or a lamp behind the exit direction: nothing
    assert tails.lamp_tails(np.zeros((1, 3)), out, out, np.array([[4.0, 4.0]]), 0.0, lamp_off)[0, 0] == 0.0
    behind = Lamps(np.array([[0.0, 0.0, -1.0]]), np.ones((1, 3)))
    assert tails.lamp_tails(np.zeros((1, 3)), out, out, np.array([[4.0, 4.0]]), 0.05, behind)[0, 0] == 0.0
