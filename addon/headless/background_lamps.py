"""The World's lamps as sun lights for EEVEE's background pass, so that it lights like Cycles.

EEVEE lights a surface from the World by a low-order expansion of it (its sphere probe's
spherical harmonics) plus at most one sun it extracts from the World's brightest pixels (World →
Settings → *Sun Threshold*). Under a studio HDRI whose lamps sit near the horizon at several
azimuths (bpy's ``studio.exr``: eight clusters at 3–30° elevation), the extracted sun is the
lamps' mean direction, high in the sky, carrying all their power: EEVEE lit the benchmark's
checker ground 5.1× brighter than Cycles; with the sun extraction off, the expansion's band 1
still lights an upward surface with a quarter of a lamp on the horizon: 1.8×.
(docs/transparent-films-cycles.md).

For the headless frame's EEVEE background pass (:func:`.background.render_background`), while
the pass renders and restored after it (:func:`world_lamps_as_suns`):

- the World's radiance seen by anything but the camera is scaled down to at most
  ``policy.BACKGROUND_LAMP_THRESHOLD`` × its mean luminance, L · min(1, T / Y(L)) (nodes before
  the World's Background shader: *RGB to BW*, *Math*, *Light Path → Is Camera Ray*), so the
  camera still sees the World unchanged;
- what was taken off, ∫ L (1 − min(1, T / Y(L))) dω, becomes at most ``policy.MAX_LAMPS`` sun
  lights: the pixels above T grouped by :func:`precompute.world.lamps.extract`'s spherical k-means,
  each sun carrying its group's power (RGB) as its irradiance, along its power-weighted mean
  direction, with the angle of a disc of its group's solid angle; they cast shadows (the
  camera-invisible films still cast theirs);
- EEVEE's own sun extraction is turned off (*Sun Threshold* raised above any radiance);
- solid glass casts an opaque shadow, and the lights' light through and off it is traced and
  put back after the render (:mod:`.caustics`), where every light can be (suns, and point, spot
  and area lights outside the glass's bounds); else the shadow a
  straight shadow ray through glass carries, 1 − F(θ) through each face (:func:`glass_shadows`;
  EEVEE's opaque shadow alone measured worse against Cycles, docs/transparent-films.md#figures).

The sum keeps the World's power (the suns take exactly what the World lost:
tests/headless/test_background_lamps.py). It applies
where the World is a Background shader (its Color any node or a constant, its Strength a
constant) into the World Output; other Worlds are left as they are (EEVEE's own lighting).
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from ...precompute.shading.policy import BACKGROUND_LAMP_THRESHOLD, MAX_LAMPS
from ...precompute.world import hdri
from ...precompute.world.lamps import extract
from ...precompute.world.prefilter import LUMINANCE
from ..world.world_key import world_uses_nodes

#: The World's Sun Threshold while the suns stand in for its lamps: above any radiance.
NO_SUN_THRESHOLD = 1e30


def suns_of(panorama, threshold: float = BACKGROUND_LAMP_THRESHOLD, max_lamps: int = MAX_LAMPS):
    """(clamp T, suns): the World's panorama (H, W, 3, top row first, world frame, radiance)
    split at T = ``threshold`` × its mean luminance; each sun (direction (3,) towards the light,
    irradiance (3,) RGB, angle in radians) carries what the clamp L · min(1, T / Y(L)) takes off
    the pixels nearest its direction. No suns where nothing exceeds T."""
    img = np.asarray(panorama, dtype=np.float64)[..., :3]
    img = np.where(np.isfinite(img), img, 0.0)
    y = img @ np.asarray(LUMINANCE)
    omega = hdri.equirect_solid_angles(*img.shape[:2])
    mean = float(np.sum(np.maximum(y, 0.0) * omega)) / (4.0 * np.pi)
    t = float(threshold) * mean
    if not mean > 0.0:
        return t, []
    lamps, _ = extract(img, threshold=float(threshold), max_lamps=max_lamps)
    if lamps.count == 0:
        return t, []
    over = y > t
    dirs = hdri.equirect_directions(*img.shape[:2])[over]
    share = 1.0 - t / y[over]
    removed = img[over] * share[:, None] * omega[over][:, None]
    label = np.argmax(dirs @ lamps.directions.T, axis=1)
    suns = []
    for k in range(lamps.count):
        sel = label == k
        if not np.any(sel):
            continue
        power = removed[sel].sum(axis=0)
        weight = removed[sel] @ np.asarray(LUMINANCE)
        d = (weight[:, None] * dirs[sel]).sum(axis=0)
        norm = float(np.linalg.norm(d))
        if not norm > 0.0 or not float(power.max()) > 0.0:
            continue
        solid = float(np.sum(omega[over][sel]))
        suns.append((d / norm, power, 2.0 * math.sqrt(min(solid, 2.0 * np.pi) / np.pi)))
    return t, suns


def _background_node(world):
    """The World's Background shader feeding its active output, with a constant Strength, or None."""
    tree = world.node_tree if world is not None and world_uses_nodes(world) else None
    if tree is None:
        return None
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_WORLD" and n.target in ("ALL", "EEVEE")]
    active = [n for n in outputs if n.is_active_output] or outputs
    if not active or not active[0].inputs["Surface"].is_linked:
        return None
    node = active[0].inputs["Surface"].links[0].from_node
    if node.type != "BACKGROUND" or node.inputs["Strength"].is_linked:
        return None
    return node


def _clamp_nodes(tree, background, limit: float) -> list:
    """Insert L · max(Is Camera Ray, min(1, limit / Y(L))) before ``background``'s Color; the
    nodes added (to remove)."""
    colour = background.inputs["Color"]
    source = colour.links[0].from_socket if colour.is_linked else None
    nodes = []

    def new(kind, **values):
        node = tree.nodes.new(kind)
        for name, value in values.items():
            setattr(node, name, value)
        nodes.append(node)
        return node

    if source is None:
        rgb = new("ShaderNodeRGB")
        rgb.outputs[0].default_value = tuple(colour.default_value)
        source = rgb.outputs[0]
    grey = new("ShaderNodeRGBToBW")
    ratio = new("ShaderNodeMath", operation="DIVIDE")
    ratio.inputs[0].default_value = float(limit)
    cap = new("ShaderNodeMath", operation="MINIMUM")
    cap.inputs[1].default_value = 1.0
    path = new("ShaderNodeLightPath")
    keep = new("ShaderNodeMath", operation="MAXIMUM")
    scale = new("ShaderNodeVectorMath", operation="SCALE")
    links = tree.links
    links.new(source, grey.inputs[0])
    links.new(grey.outputs[0], ratio.inputs[1])
    links.new(ratio.outputs[0], cap.inputs[0])
    links.new(cap.outputs[0], keep.inputs[0])
    links.new(path.outputs["Is Camera Ray"], keep.inputs[1])
    links.new(source, scale.inputs[0])
    links.new(keep.outputs[0], scale.inputs["Scale"])
    links.new(scale.outputs[0], colour)
    return nodes


def _add_sun(bpy, scene, index: int, direction, irradiance, angle: float):
    from mathutils import Vector

    strength = float(np.max(irradiance))
    light = bpy.data.lights.new(f"thinfilm_world_lamp_{index}", "SUN")
    light.energy = strength
    light.color = tuple(float(c) for c in np.asarray(irradiance) / strength)
    light.angle = float(angle)
    light.use_shadow = True
    obj = bpy.data.objects.new(light.name, light)
    scene.collection.objects.link(obj)
    obj.rotation_euler = Vector(tuple(-float(c) for c in direction)).to_track_quat("-Z", "Y").to_euler()
    return obj, light


@contextlib.contextmanager
def world_lamps_as_suns(scene, panorama):
    """While inside: the World's lamps lit as sun lights for EEVEE (see the module); yields the
    number of suns (0: the World left as it is). ``panorama``: the World's radiance (H, W, 3),
    top row first, in the world frame and at its strength (``WorldLighting.background``)."""
    import bpy

    world = scene.world
    background = _background_node(world)
    if background is None or panorama is None:
        yield 0
        return
    limit, suns = suns_of(panorama)
    if not suns:
        yield 0
        return
    strength = float(background.inputs["Strength"].default_value)
    tree = world.node_tree
    colour = background.inputs["Color"]
    source = colour.links[0].from_socket if colour.is_linked else None
    saved_threshold = world.sun_threshold
    nodes, added = [], []
    try:
        nodes = _clamp_nodes(tree, background, limit / max(strength, 1e-30))
        world.sun_threshold = NO_SUN_THRESHOLD
        for k, (direction, irradiance, angle) in enumerate(suns):
            added.append(_add_sun(bpy, scene, k, direction, irradiance, angle))
        yield len(suns)
    finally:
        for obj, light in added:
            scene.collection.objects.unlink(obj)
            bpy.data.objects.remove(obj)
            bpy.data.lights.remove(light)
        if added:
            bpy.context.view_layer.update()
        for node in nodes:
            tree.nodes.remove(node)
        if source is not None:
            tree.links.new(source, colour)
        world.sun_threshold = saved_threshold


def _dark_material(bpy, name: str, transparent_shadow: bool):
    """A new material ``name`` whose nodes are a black diffuse BSDF and the output: (material,
    its node tree, the output node, the diffuse node)."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # before Blender 5.0
        mat.use_nodes = True
    mat.use_transparent_shadow = transparent_shadow
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    dark = tree.nodes.new("ShaderNodeBsdfDiffuse")
    dark.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    return mat, tree, out, dark


def _glass_shadow_material(bpy, eta: float):
    """A material whose shadow lets through 1 − F(θ) at each of its faces: F the Fresnel reflectance
    at relative index ``eta`` of the light's incidence θ on the face (EEVEE's shadow pass sees along
    the light: its Incoming is the light's direction), the same index on faces seen from inside
    (the light goes straight through: across parallel faces this is the refracted ray's loss).
    Transparent shadows (``use_transparent_shadow``): a shadow map texel is let through with
    probability 1 − F per face, converged over the render's samples."""
    mat, tree, out, dark = _dark_material(bpy, f"thinfilm_glass_shadow_{eta:.4f}", True)
    clear = tree.nodes.new("ShaderNodeBsdfTransparent")
    mix = tree.nodes.new("ShaderNodeMixShader")
    fresnel = tree.nodes.new("ShaderNodeFresnel")
    side = tree.nodes.new("ShaderNodeNewGeometry")
    index = tree.nodes.new("ShaderNodeMix")  # the Fresnel node takes 1/IOR on back faces: undo it
    index.data_type = "FLOAT"
    index.inputs["A"].default_value = float(eta)
    index.inputs["B"].default_value = 1.0 / float(eta)
    links = tree.links
    links.new(side.outputs["Backfacing"], index.inputs["Factor"])
    links.new(index.outputs["Result"], fresnel.inputs["IOR"])
    links.new(fresnel.outputs[0], mix.inputs[0])
    links.new(clear.outputs[0], mix.inputs[1])
    links.new(dark.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], out.inputs["Surface"])
    return mat


def _opaque_shadow_material(bpy):
    """A material whose shadow is opaque: black diffuse, no transparent shadow."""
    mat, tree, out, dark = _dark_material(bpy, "thinfilm_glass_shadow_opaque", False)
    tree.links.new(dark.outputs[0], out.inputs["Surface"])
    return mat


@contextlib.contextmanager
def glass_shadows(glass, opaque: bool = False):
    """While inside: the solid glass objects ``glass`` ({object name: relative index η}) cast the
    shadow a lamp's light sees through glass as Cycles' next-event estimation lights it from a
    straight shadow ray: 1 − F(θ) through each face (:func:`_glass_shadow_material` on every
    material slot, linked to the object); their materials restored after. For EEVEE's background
    pass, where the objects are hidden from the camera: the suns of :func:`world_lamps_as_suns`
    are shadowed, the World's smooth part (EEVEE's probe, unshadowed) still lights what is
    under the glass. ``opaque``: an opaque shadow instead, where the light through the glass is
    traced (:mod:`.caustics`)."""
    import bpy

    made, saved = {}, []
    try:
        for name, eta in sorted(dict(glass).items()):
            obj = bpy.data.objects.get(name)
            if obj is None or not eta > 0.0 or not obj.material_slots:
                continue
            key = "opaque" if opaque else round(float(eta), 4)
            if key not in made:
                made[key] = _opaque_shadow_material(bpy) if opaque else _glass_shadow_material(bpy, key)
            for slot in obj.material_slots:
                link = slot.link
                slot.link = "OBJECT"
                saved.append((slot, link, slot.material))
                slot.material = made[key]
        yield len(saved)
    finally:
        for slot, link, material in reversed(saved):
            slot.material = material
            slot.link = link
        for mat in made.values():
            bpy.data.materials.remove(mat)
