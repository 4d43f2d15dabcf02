"""Make the pictures of docs/user-guide.md: a walkthrough from an empty scene to a rendered bubble.

    .venv/bin/python scripts/make_user_guide_images.py        # → docs/images/guide-*.png

Every picture is the extension's headless render (``addon.headless.render.render_scene``, what
``blender -b file.blend --command thinfilm_sh render`` does) of a scene this script builds from
an empty file, one step of the guide's walkthrough each, at 320×240 on whatever OpenGL bpy
finds (Mesa llvmpipe here). The last one is made with the *Show Thin Film Overlay* preference
off: Blender's own drawing only.
"""

from __future__ import annotations

import pathlib
import sys
import tempfile
import time

REPO = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "scripts"))
sys.path.insert(0, str(REPO))  # precompute, for the PNG helpers

import make_reference_images as refs  # noqa: E402  (helpers: the extension, PNG writing)

SIZE = refs.DOCS_SIZE
OUT = REPO / "docs" / "images"

#: (file stem, what the step shows, the changes of the step to the bubble's material settings)
STEPS = (
    ("guide-1-bubble", "the Soap Film preset on a sphere", {}),
    (
        "guide-2-thickness",
        "Thickness Variation: 200-900 nm, finer noise",
        {
            "thickness_min_nm": 200.0,
            "thickness_max_nm": 900.0,
            "noise_scale": 3.0,
        },
    ),
    ("guide-3-rough", "Surface: roughness 0.35", {"roughness": 0.35}),
    ("guide-4-titanium", "the Anodized Titanium preset", {"preset": "ANODISED_TITANIUM"}),
)


def build_scene(changes: dict):
    """An empty file → a ground, a sphere with the Soap Film preset (plus ``changes``), the
    studio HDRI as the World, a camera: the walkthrough's scene."""
    scenes = refs.make_scenes_module()
    scene = scenes.new_file(SIZE)
    scenes.studio_world(scene, scenes.hdri_path("studio"))
    scenes.ground(scene, z=0.0)
    mesh = scenes.bm_to_mesh(scenes.uv_sphere("Bubble"), "Bubble")
    obj = scenes.add_object(scene, "Bubble", mesh)
    obj.location = (0.0, 0.0, 1.2)
    mat = scenes.film_material(
        "Bubble Film", "SOAP_FILM", thickness_source="NOISE", noise_scale=1.2, noise_seed=3
    )
    for key, value in changes.items():
        setattr(mat.thinfilm_sh, key, value)
    mesh.materials.append(mat)
    scenes.camera(scene, (0.0, -5.2, 1.5), (0.0, 0.0, 1.2), lens=50.0)
    return scene


def render(stem: str, tmp: pathlib.Path) -> dict:
    """Render the open scene headlessly and keep an 8-bit PNG in docs/images."""
    rgb, result = refs.headless_render(tmp / f"{stem}.png", SIZE, background=True)
    size = refs.save_png(OUT / f"{stem}.png", refs.srgb8(rgb))
    assert size < refs.DOCS_IMAGE_LIMIT, f"{stem}.png is {size} bytes"
    return result


def main() -> int:
    """Build and render every step, then the overlay-off picture."""
    refs.extension()
    prefs = refs.addon_module("addon.ui.prefs")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        for stem, what, changes in STEPS:
            start = time.perf_counter()
            build_scene(changes)
            result = render(stem, tmp)
            print(f"{stem}: {what}: {result['objects']} in {time.perf_counter() - start:.1f} s")
        build_scene({})
        if prefs.preferences() is None:  # registered from the repository: add its preferences
            import bpy

            bpy.context.preferences.addons.new().module = prefs.PACKAGE
        settings = prefs.preferences()
        settings.show_overlay = False
        try:
            result = render("guide-5-overlay-off", tmp)
        finally:
            settings.show_overlay = True
        print(f"guide-5-overlay-off: {result['messages']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
