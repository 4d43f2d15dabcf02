"""The exact specular paths through a benchmark scene's solid glass, per pixel: a study tool.

Builds a scene of benchmarks/transparent_films.py (``--scene``: glass, cube, wineglass, lamps),
then traces camera rays through the glass object's mesh with ``bpy``'s BVH tree: the smooth
normal interpolated over each triangle from its corner normals, as Cycles shades it, Cycles'
correction of that normal and its path ends (``precompute.shading.glass.glass_exit.valid_normal``:
a direction on the wrong side of the face ends the branch), unpolarised Fresnel at every face
(no film, no roughness). Every branch is followed, R (reflected) and T (refracted), up to
``--depth`` faces or a weight under 1e-4; where a path leaves, the World's panorama is read along
it, or, heading down to the ground within 20 m, the ground: the colour of ``--ref``'s Cycles
picture where that ground point is seen beside the glass (a ``--dump`` file of
transparent_films), else ``--ground``.

What it is for: where the headless frame and Cycles differ over solid glass, which paths carry
the light (the far wall's branches, the wine glass's rim and foot were found so,
docs/transparent-films.md). It is the smooth glass without its film: compare shapes and
directions, not the film's colours.

    .venv/bin/python scripts/glass_paths.py --scene wineglass --pixel 90,68 --pixel 83,117
    .venv/bin/python scripts/glass_paths.py --scene glass --block 160 176 20 30 --ref DUMP.npz

``--pixel ROW,COL``: each path of the pixel's centre ray, the strongest first, with its faces
(point, cosine, Fresnel). ``--block R0 R1 C0 C1``: 2 × 2 rays a pixel over the block, its mean
and median luminance and the share of each path's first six faces.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "scripts")]

import _cycles_scenes as cc  # noqa: E402

from precompute.shading.glass import glass_exit  # noqa: E402
from precompute.shading.glass.refract import refract  # noqa: E402
from precompute.shading.transmit import fresnel_dielectric  # noqa: E402
from precompute.world import hdri  # noqa: E402

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: A branch is dropped below this weight.
MIN_WEIGHT = 1e-4


class Scene:
    """The built scene: the glass mesh in world space (addon/headless/caustics.py's ``_GlassMesh``:
    its BVH tree and corner normals), the camera and the World's panorama."""

    def __init__(self, name: str, ref=None, ground=0.3):
        import bpy
        import thinfilm_headless
        from mathutils import Vector

        from benchmarks import transparent_films as tf

        blend = tf.build(name, pathlib.Path(tempfile.mkdtemp()) / f"{name}.blend", tf.SIZE, 16)
        bpy.ops.wm.open_mainfile(filepath=str(blend))
        thinfilm_headless.register_extension()
        from thinfilm_sh.addon.headless.caustics import _GlassMesh  # the caustics' own glass mesh

        scene = bpy.context.scene
        obj = next(o for o in scene.objects if o.type == "MESH" and "film" in o.data.materials)
        self.mesh = _GlassMesh(obj, bpy.context.evaluated_depsgraph_get())
        self.vector = Vector
        self.camera = scene.camera
        self.size = scene.render.resolution_x
        self.eta = float(obj.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value)
        self.panorama = hdri.read_equirect(cc.studiolight_path(tf.HDRI))
        self.ref = None if ref is None else np.load(ref)
        self.ground = float(ground)

    def ray(self, row: float, col: float):
        """The camera ray through image point (row, col), in pixels from the top left corner."""
        t = math.tan(self.camera.data.angle / 2.0)
        x, y = col / self.size * 2.0 - 1.0, 1.0 - row / self.size * 2.0
        d = self.camera.matrix_world.to_3x3() @ self.vector((x * t, y * t, -1.0))
        return np.array(list(self.camera.location)), np.array(list(d.normalized()))

    def seen(self, o, d) -> tuple[str, np.ndarray]:
        """What a ray that has left the glass sees: ("ground", colour) or ("world", radiance)."""
        if d[2] < 0.0 and (o[2] + 1.0) / -d[2] < 20.0:
            q = o + (o[2] + 1.0) / -d[2] * d
            return "ground", self.ground_colour(q)
        return "world", hdri.equirect_lookup(self.panorama, d[None])[0]

    def ground_colour(self, q) -> np.ndarray:
        """The reference picture's colour where ground point ``q`` is seen beside the glass."""
        if self.ref is not None:
            rel = np.array(self.camera.matrix_world.inverted() @ self.vector(q))
            t = math.tan(self.camera.data.angle / 2.0)
            col = int((rel[0] / (-rel[2] * t) + 1.0) / 2.0 * self.size)
            row = int((1.0 - rel[1] / (-rel[2] * t)) / 2.0 * self.size)
            if 0 <= row < self.size and 0 <= col < self.size and self.ref["delta_e"][row, col] == 0.0:
                return np.asarray(self.ref["cycles"][row, col], dtype=np.float64)
        return np.full(3, self.ground)

    def paths(self, o, d, depth: int) -> list:
        """Every branch of the ray o + s d: (weight, "RT…" path, what it sees, direction,
        radiance, faces ((point, cosine, Fresnel), …)), the path cut at ``depth`` faces ("|")."""
        out = []
        stack = [(o, d, 1.0, "", ())]
        while stack:
            o, d, w, path, faces = stack.pop()
            hit = self.mesh.bvh.ray_cast(self.vector(o + 1e-5 * d), self.vector(d))
            if hit[0] is None:
                kind, radiance = self.seen(o, d)
                out.append((w, path, kind, d, radiance, faces))
                continue
            if len(path) >= depth or w < MIN_WEIGHT:
                out.append((w, path + "|", "end", d, np.zeros(3), faces))
                continue
            p, g = np.array(list(hit[0])), np.array(list(hit[1]))
            entering = d @ g < 0.0
            g = g if entering else -g  # the face's normal on the ray's side
            n = self.mesh.normals_at([hit[2]], p[None])[0] * (1.0 if entering else -1.0)
            n = glass_exit.valid_normal(g[None], -d[None], n[None])[0]
            eta = self.eta if entering else 1.0 / self.eta
            cos_i = float(np.clip(-(d @ n), 0.0, 1.0))
            fresnel = float(fresnel_dielectric(cos_i, eta))
            faces_here = faces + ((p, cos_i, fresnel),)
            mirrored = d + 2.0 * cos_i * n
            if mirrored @ g > 0.0:  # Cycles ends a mirror that dips below the face
                stack.append((p, mirrored / np.linalg.norm(mirrored), w * fresnel, path + "R", faces_here))
            through = refract(d[None], n[None], 1.0 / eta)[0]  # GLSL's refract: n₁ / n₂
            if fresnel < 1.0 and through @ g < 0.0:  # and a refraction that does not cross it
                through = through / np.linalg.norm(through)
                stack.append((p, through, w * (1.0 - fresnel), path + "T", faces_here))
        return out


def show_pixel(scene: Scene, row: int, col: int, depth: int, count: int = 8) -> None:
    o, d = scene.ray(row + 0.5, col + 0.5)
    paths = scene.paths(o, d, depth)
    total = sum(w * (radiance @ LUMINANCE) for w, _p, _k, _d, radiance, _f in paths)
    print(f"pixel {row},{col}: luminance {total:.4f} over {len(paths)} paths")
    for w, path, kind, direction, radiance, faces in sorted(paths, key=lambda x: -x[0] * (x[4] @ LUMINANCE))[
        :count
    ]:
        y = radiance @ LUMINANCE
        print(
            f"  {path:16s} {kind:6s} weight {w:.4f} × {y:9.3f} = {w * y:.4f},",
            f"leaving {np.round(direction, 3)}",
        )
        for p, cos_i, fresnel in faces:
            print(f"      at {np.round(p, 3)} cos {cos_i:.3f} Fresnel {fresnel:.3f}")


def show_block(scene: Scene, rows: tuple, cols: tuple, depth: int) -> None:
    picture = np.zeros((rows[1] - rows[0], cols[1] - cols[0]))
    shares: dict = {}
    for i, row in enumerate(range(*rows)):
        for j, col in enumerate(range(*cols)):
            for dy in (0.25, 0.75):
                for dx in (0.25, 0.75):
                    for w, path, _k, _d, radiance, _f in scene.paths(*scene.ray(row + dy, col + dx), depth):
                        y = w * (radiance @ LUMINANCE) / 4.0
                        picture[i, j] += y
                        shares[path[:6]] = shares.get(path[:6], 0.0) + y
    print(
        f"rows {rows[0]}–{rows[1]}, columns {cols[0]}–{cols[1]}: mean luminance {picture.mean():.4f},"
        f" median {np.median(picture):.4f}"
    )
    for path, y in sorted(shares.items(), key=lambda kv: -kv[1])[:10]:
        print(f"  {path or '(none)':8s} {y / picture.size:.4f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="wineglass", choices=("glass", "cube", "wineglass", "lamps"))
    parser.add_argument("--pixel", action="append", default=[], help="ROW,COL (repeatable)")
    parser.add_argument("--block", nargs=4, type=int, metavar=("R0", "R1", "C0", "C1"))
    parser.add_argument("--depth", type=int, default=16, help="faces followed per path")
    parser.add_argument("--ref", help="a transparent_films --dump file: the ground's colours")
    parser.add_argument("--ground", type=float, default=0.3, help="the ground's radiance elsewhere")
    args = parser.parse_args(argv)
    if not args.pixel and not args.block:
        parser.error("give --pixel or --block")
    scene = Scene(args.scene, args.ref, args.ground)
    for pixel in args.pixel:
        row, col = (int(v) for v in pixel.split(","))
        show_pixel(scene, row, col, args.depth)
    if args.block:
        r0, r1, c0, c1 = args.block
        show_block(scene, (r0, r1), (c0, c1), args.depth)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
