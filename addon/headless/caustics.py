"""Solid glass's shadow and caustics in EEVEE's background pass, from the sun lamps.

While the pass renders, solid glass casts EEVEE's opaque shadow (:func:`.background_lamps.glass_shadows`
with ``opaque``); :func:`light_caustics` then traces each light's light through the glass objects'
real meshes (``precompute/optics/caustics.py``: photons, caustic cells, irradiance) and returns
the radiance it brings to what the pass's camera sees: the pass's diffuse colour × irradiance / π.
The rays are Blender's: ``mathutils.bvhtree`` over each glass object's evaluated mesh (its
corner normals interpolated at the hit) and over the other mesh instances the render shows (thin
films, which the pass lets the light through, left out).

Cycles finds a caustic from the diffuse surface it lands on and, by its *Filter Glossy*
(``scene.cycles.blur_glossy``, 1 by default), draws the glass rough on those paths, the rougher
the more grazing the light lands: each sun's photons are traced smooth first, for where and how
steeply each lands, then again meeting the glass at GGX microfacets of that roughness, and
their light is averaged into a density (:mod:`precompute.optics.facets`);
with the filter off the caustic is the smooth glass's, sharp.

Suns (the World's lamps are suns, :mod:`.background_lamps`) send parallel photons; point, spot
and area lights send them from their centre or their area's cells
(:mod:`precompute.optics.sources`). :func:`applies` says whether every light the render sees can
be traced so: a point, spot or area light inside a glass object's bounds cannot, and then the
pass keeps the straight shadow through glass (1 − F per face) and no caustics.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from ...precompute.optics import caustics, facets, sources
from ...precompute.shading import lights as light_shading
from ...precompute.shading.policy import CAUSTIC_GRID, CAUSTIC_SMOOTH
from ...precompute.shading.transmit import back_reflectance, white_reflectance


def _lights(scene) -> list:
    """The light objects the render sees, with power."""
    return [
        obj for obj in scene.objects if obj.type == "LIGHT" and not obj.hide_render and obj.data.energy > 0.0
    ]


def _bounds(obj) -> tuple[np.ndarray, float]:
    """(centre, radius) of the sphere about ``obj``'s world-space bounding box."""
    m = np.array(obj.matrix_world, dtype=np.float64)
    corners = np.array([tuple(c) for c in obj.bound_box], dtype=np.float64) @ m[:3, :3].T + m[:3, 3]
    centre = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
    return centre, float(np.max(np.linalg.norm(corners - centre, axis=-1)))


def _finite_lights(scene) -> light_shading.Lights:
    """The point, spot and area lights the render sees, as the diffuse ground sees them
    (:func:`..drawing.lights.light_row` without the glossy visibility and Specular factor)."""
    from ..drawing.lights import light_row

    rows = [
        light_row(obj, obj.matrix_world, glossy=False) for obj in _lights(scene) if obj.data.type != "SUN"
    ]
    return light_shading.Lights.from_rows([row for row in rows if row is not None])


def applies(scene, glass=()) -> bool:
    """Whether photons can stand for every light the render sees: suns, and point, spot and
    area lights whose points the photons leave from (:func:`precompute.optics.sources.emitters`)
    all lie outside the bounds of each of the ``glass`` objects (names)."""
    spheres = [_bounds(scene.objects[name]) for name in glass if name in scene.objects]
    lights = _finite_lights(scene)
    return all(
        sources.outside_sphere(emitter.position, centre, radius)
        for k in range(lights.count)
        for emitter in sources.emitters(lights, k)
        for centre, radius in spheres
    )


def glass_optics(items, messages=None) -> dict:
    """{object name: :class:`~precompute.optics.caustics.GlassOptics`} of the solid glass draw
    items: their relative index and film, from outside (the film table's first thickness row)
    and from inside (Cycles' back-face film where it applies, as the draw's glints). A film
    that cannot be tabulated leaves the bare glass, with a line in ``messages``."""
    from ...precompute.shading.lamps import thickness_lerp
    from ..bakes import tables
    from ..gpu.glass_buffers import solid_glass

    out = {}
    for item in solid_glass(items):
        name = item.name.split("/")[0]
        if name in out:
            continue
        eta = float(item.wall[1])
        film = _film_table(item, tables, messages)
        if film is None:
            out[name] = caustics.plain_glass(eta)
            continue
        back = back_film(item)

        def front(c, film=film):
            c = np.asarray(c, dtype=np.float64)
            return white_reflectance(film, thickness_lerp(film, None, c.shape[0]), c)

        def inside(c, film=film, back=back, eta=eta):
            c = np.asarray(c, dtype=np.float64)
            return back_reflectance(film, thickness_lerp(film, None, c.shape[0]), c, eta, table=back)

        out[name] = caustics.GlassOptics(eta, front, inside)
    return out


def _description(item):
    """The material description of a draw item (``object/material``), or None."""
    import bpy

    from ..materials.description import description

    material = bpy.data.materials.get(str(getattr(item, "name", "")).split("/", 1)[-1])
    return description(material) if material is not None else None


def back_film(item):
    """Cycles' back-face film of a solid glass draw item, from its Blender material
    (:func:`precompute.shading.transmit.cycles_back_table`), or None."""
    from ...precompute.shading.transmit import cycles_back_table

    desc = _description(item)
    return cycles_back_table(desc) if desc is not None else None


def _film_table(item, tables, messages=None):
    desc = _description(item)
    if desc is None:
        return None
    try:
        return tables.get_film(desc, None)
    except Exception as exc:  # a film that cannot be tabulated: the bare dielectric
        if messages is not None:
            messages.append(f"caustics: {item.name}: film not tabulated ({exc}); traced as bare glass")
        return None


class _GlassMesh:
    """One glass object's evaluated mesh in world space: a BVH of its triangles and their corner
    normals, for rays that meet it (the normal interpolated at the hit)."""

    def __init__(self, obj, depsgraph):
        from mathutils.bvhtree import BVHTree

        from ..gpu.mesh import mesh_arrays

        evaluated = obj.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            arrays = mesh_arrays(mesh)
        finally:
            evaluated.to_mesh_clear()
        if arrays is None:
            raise ValueError(f"{obj.name}: no faces")
        positions, normals, triangles, _ = arrays
        m = np.array(obj.matrix_world, dtype=np.float64)
        p = positions.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        nm = np.linalg.inv(m[:3, :3]).T
        n = normals.astype(np.float64) @ nm.T
        n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
        self.tris = triangles.reshape(-1, 3)
        self.points, self.normals = p, n
        self.bvh = BVHTree.FromPolygons(p.tolist(), self.tris.tolist(), all_triangles=True)
        lo, hi = p.min(axis=0), p.max(axis=0)
        self.centre = 0.5 * (lo + hi)
        self.radius = float(np.max(np.linalg.norm(p - self.centre, axis=-1)))

    def normals_at(self, index, points) -> np.ndarray:
        """The corner normals (M, 3) interpolated at ``points`` (M, 3) on triangles ``index`` (M,)."""
        tri = self.tris[np.asarray(index, dtype=np.int64)]
        a, b, c = (self.points[tri[:, k]] for k in range(3))
        v0, v1, v2 = b - a, c - a, np.asarray(points, dtype=np.float64) - a
        d00, d01, d11 = (v0 * v0).sum(-1), (v0 * v1).sum(-1), (v1 * v1).sum(-1)
        d20, d21 = (v2 * v0).sum(-1), (v2 * v1).sum(-1)
        den = d00 * d11 - d01 * d01
        ok = np.abs(den) > 1e-300
        den = np.where(ok, den, 1.0)
        v = np.where(ok, (d11 * d20 - d01 * d21) / den, 0.0)
        w = np.where(ok, (d00 * d21 - d01 * d20) / den, 0.0)
        n = (1.0 - v - w)[:, None] * self.normals[tri[:, 0]]
        n += v[:, None] * self.normals[tri[:, 1]] + w[:, None] * self.normals[tri[:, 2]]
        return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)


class _Receivers:
    """Everything else the light can land on: one BVH of the evaluated mesh instances the render
    shows, but the glass and ``exclude`` (thin films), and each triangle's object."""

    def __init__(self, depsgraph, exclude: set):
        from mathutils.bvhtree import BVHTree

        points, tris, owner, self.names = [], [], [], []
        base = 0
        for inst in depsgraph.object_instances:
            obj = inst.object
            original = obj.original if obj.original is not None else obj
            if obj.type != "MESH" or original.name in exclude or original.hide_render:
                continue
            mesh = obj.to_mesh()
            try:
                mesh.calc_loop_triangles()
                co = np.empty(3 * len(mesh.vertices), dtype=np.float64)
                mesh.vertices.foreach_get("co", co)
                tri = np.empty(3 * len(mesh.loop_triangles), dtype=np.int64)
                mesh.loop_triangles.foreach_get("vertices", tri)
            finally:
                obj.to_mesh_clear()
            if tri.size == 0:
                continue
            m = np.array(inst.matrix_world, dtype=np.float64)
            points.append(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
            tris.append(tri.reshape(-1, 3) + base)
            base += len(points[-1])
            owner.append(np.full(len(tri) // 3, len(self.names)))
            self.names.append(original.name)
        self.owner = np.concatenate(owner) if owner else np.zeros(0, dtype=np.int64)
        self.bvh = None
        if points:
            joined = np.concatenate(points).tolist(), np.concatenate(tris).tolist()
            self.bvh = BVHTree.FromPolygons(*joined, all_triangles=True)


def _casts(meshes: list, receivers: _Receivers):
    """(cast_outside, cast_inside) for :func:`precompute.optics.caustics.trace` over the glass
    ``meshes`` and the ``receivers``."""

    def first(bvh, o, d, normals=None):
        index = np.full(len(o), -1)
        dist = np.full(len(o), np.inf)
        if bvh is None:
            return index, dist
        cast = bvh.ray_cast
        for i, (origin, direction) in enumerate(zip(o.tolist(), d.tolist(), strict=True)):
            _loc, normal, k, t = cast(origin, direction)
            if k is not None:
                index[i], dist[i] = k, t
                if normals is not None:
                    normals[i] = normal
        return index, dist

    def outside(o, d):
        m = len(o)
        normals = np.zeros((m, 3))  # a receiver's face normal, for the landing cosine
        rec_index, nearest = first(receivers.bvh, o, d, normals)
        glass, tri = np.full(m, -1), np.full(m, -1)
        for g, mesh in enumerate(meshes):
            index, dist = first(mesh.bvh, o, d)
            closer = dist < nearest
            glass[closer], tri[closer], nearest[closer] = g, index[closer], dist[closer]
        points = o + np.where(np.isfinite(nearest), nearest, 0.0)[:, None] * d
        for g, mesh in enumerate(meshes):
            sel = glass == g
            if np.any(sel):
                normals[sel] = mesh.normals_at(tri[sel], points[sel])
        rec = np.full(m, -1)
        landed = (glass < 0) & (rec_index >= 0)
        rec[landed] = receivers.owner[rec_index[landed]]
        return glass, rec, points, normals

    def inside(g, o, d):
        mesh = meshes[g]
        index, dist = first(mesh.bvh, o, d)
        hit = index >= 0
        points = o + np.where(hit, dist, 0.0)[:, None] * d
        normals = np.zeros_like(points)
        if np.any(hit):
            normals[hit] = mesh.normals_at(index[hit], points[hit])
        return hit, points, normals

    return outside, inside


def filter_glossy(scene) -> float:
    """The scene's Cycles *Filter Glossy* (``cycles.blur_glossy``; Blender's default 1 where the
    scene has no Cycles settings), the roughness Cycles gives glass on its caustic paths."""
    settings = getattr(scene, "cycles", None)
    value = getattr(settings, "blur_glossy", 1.0) if settings is not None else 1.0
    return max(float(value), 0.0)


def pass_camera(scene, depsgraph, width: int, height: int) -> caustics.Camera:
    """The scene camera as the pass renders it now (its overscan applied), ``width`` × ``height``."""
    cam = scene.camera
    render = scene.render
    proj = cam.calc_matrix_camera(
        depsgraph, x=int(width), y=int(height), scale_x=render.pixel_aspect_x, scale_y=render.pixel_aspect_y
    )
    view = cam.matrix_world.inverted()
    return caustics.Camera(
        np.array(view, dtype=np.float64),
        np.array(proj, dtype=np.float64),
        int(width),
        int(height),
        ortho=cam.data.type == "ORTHO",
    )


def _glass_meshes(scene, glass: dict, depsgraph, messages) -> tuple[list, list]:
    """(names, :class:`_GlassMesh` es) of the glass objects that are meshes with faces."""
    names, meshes = [], []
    for name in sorted(glass):
        obj = scene.objects.get(name)
        if obj is None or obj.type != "MESH":
            continue
        try:
            meshes.append(_GlassMesh(obj, depsgraph))
        except ValueError as exc:
            if messages is not None:
                messages.append(f"caustics: {exc}")
            continue
        names.append(name)
    return names, meshes


def _sun_photons(suns, meshes):
    """(origins, direction, power, grid, glass index, towards the light, seed) of each sun's
    parallel photons at each glass mesh: a grid over its bounding sphere per direction of the
    sun's disc (:func:`precompute.optics.caustics.photon_grid`), the sun's irradiance over it."""
    from mathutils import Vector

    for s, sun in enumerate(suns):
        centre = np.array(sun.matrix_world.to_3x3() @ Vector((0.0, 0.0, 1.0)))
        irradiance = float(sun.data.energy) * np.array(sun.data.color, dtype=np.float64)
        directions = caustics.disc_directions(centre, float(sun.data.angle))
        for (k, towards), (m, mesh) in itertools.product(enumerate(directions), enumerate(meshes)):
            origins, direction, area = caustics.photon_grid(mesh.centre, mesh.radius, towards, CAUSTIC_GRID)
            power = np.broadcast_to(irradiance * area / len(directions), origins.shape)
            yield origins, direction, power, CAUSTIC_GRID, m, centre, (s, k, m)


def _point_photons(lights, meshes, first_seed: int):
    """The same for point, spot and area lights (``lights``, a
    :class:`precompute.shading.lights.Lights`): photons from each of their points
    (:func:`precompute.optics.sources.emitters`; an area light's cells on half the grid per axis)
    over each glass mesh's bounding sphere, each with the light's intensity that way."""
    for k in range(lights.count):
        for e, emitter in enumerate(sources.emitters(lights, k)):
            grid = CAUSTIC_GRID if emitter.area == 0.0 else CAUSTIC_GRID // 2
            for m, mesh in enumerate(meshes):
                if not sources.outside_sphere(emitter.position, mesh.centre, mesh.radius):
                    continue  # applies() keeps such scenes out
                origins, direction, omega = sources.point_photons(
                    emitter.position, mesh.centre, mesh.radius, grid
                )
                power = sources.emitted(lights, k, emitter, direction, omega)
                towards = emitter.position - mesh.centre
                towards = towards / np.linalg.norm(towards)
                yield origins, direction, power, grid, m, towards, (first_seed + k, e, m)


def light_caustics(scene, glass: dict, depth, normals, albedo, skip=(), messages=None) -> np.ndarray:
    """The radiance (H, W, 3) that the scene's lights bring through (and off) the solid glass
    ``glass`` ({object name: GlassOptics}) to the pass's pixels: ``depth`` (H, W, along the
    camera axis, ``inf`` where nothing), world ``normals`` (H, W, 3) and diffuse colour ``albedo``
    (H, W, 3) from the pass; ``skip``: objects the light goes through (thin films). Suns send
    parallel photons, point, spot and area lights photons from points (:func:`applies` has
    checked that they lie outside the glass). Called while the pass's camera is set up (its
    overscan)."""
    import bpy

    t0 = time.perf_counter()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    h, w = depth.shape
    camera = pass_camera(scene, depsgraph, w, h)
    names, meshes = _glass_meshes(scene, glass, depsgraph, messages)
    flux = np.zeros((h, w, 3))
    if not meshes:
        return flux
    optics = [glass[name] for name in names]
    receivers = _Receivers(depsgraph, set(names) | set(skip))
    if receivers.bvh is None:  # nothing for the light to land on
        return flux
    outside, inside = _casts(meshes, receivers)
    blur = filter_glossy(scene)
    rough = [np.zeros((h, w, 3)) for _ in meshes]
    photons = 0

    def shine(origins, direction, power, grid, m, towards, seed):
        """Trace one grid of photons at glass ``m`` and splat them (see the module)."""
        nonlocal flux, photons
        alpha = 0.0
        if blur > 0.0:  # each photon as rough as Cycles makes the glass from where it lands
            sharp = caustics.trace(origins, direction, power, optics, outside, inside, meshes[m].radius)
            alpha = facets.photon_roughness(sharp.landing, towards, blur)
        records = caustics.trace(
            origins, direction, power, optics, outside, inside, meshes[m].radius, alpha, seed=seed
        )
        if blur > 0.0:
            rough[m] += caustics.splat(records, grid, camera, depth, cells=False)
        else:
            flux += caustics.splat(records, grid, camera, depth)
        photons += len(origins)

    suns = [obj for obj in _lights(scene) if obj.data.type == "SUN"]
    others = _finite_lights(scene)
    for job in itertools.chain(_sun_photons(suns, meshes), _point_photons(others, meshes, len(suns))):
        shine(*job)
    for mesh, light in zip(meshes, rough, strict=True):
        if np.any(light):
            sigma = CAUSTIC_SMOOTH * caustics.projected_radius(camera, mesh.centre, mesh.radius)
            flux += caustics.smooth(light, depth, sigma)
    area = caustics.footprint(camera, depth, normals)
    radiance = np.where(np.isfinite(area)[..., None], albedo * flux / (np.pi * area[..., None]), 0.0)
    if messages is not None:
        messages.append(
            f"caustics: {len(suns)} suns, {others.count} other lights × {len(meshes)} glass objects, "
            f"{photons} photons, Filter Glossy {blur:g}, {time.perf_counter() - t0:.1f} s"
        )
    return radiance
