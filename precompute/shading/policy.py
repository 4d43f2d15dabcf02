"""Every shading rule, once: the constants and small decisions the shader and its numpy mirror share.

Each constant carries one line of why and a link to ``docs/tuning.md``, where the measurements
behind its value are. The GLSL never types these values: :func:`glsl_defines` emits them as
``#define``s (the add-on passes them to ``GPUShaderCreateInfo.define`` through
:meth:`precompute.shading.variant.Variant.defines`), and where a rule has to be GLSL code (the
grazing narrowing r · cos^0.5 is written ``sqrt(c)``) the expression itself is emitted from the
constant, so a change here changes both sides and the pictures stay bit-identical.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .. import constants
from ..sh import windows

# ----------------------------------------------------------------------------------------------
# Split sum and SH
# ----------------------------------------------------------------------------------------------
#: Roughness range of the hand-over from the split sum to SH: each where it is closer to Cycles
#: (docs/tuning.md#sh-blend).
SH_BLEND = (0.2, 0.45)


def sh_weight(roughness: float) -> float:
    """Weight of the SH path, smoothstep over ``SH_BLEND`` (0 = split sum only, 1 = SH only)."""
    lo, hi = SH_BLEND
    t = min(max((float(roughness) - lo) / (hi - lo), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


def drawn_material(material):
    """``material`` as the preview bakes it: a film drawn by the split sum alone (``sh_weight``
    0, roughness ≤ SH_BLEND[0]) without a diffuse base reads only its table's l = 0 entry (the
    film's albedo, tf_split_sum.glsl), so an automatic SH order becomes 0. Entry 0 does not
    depend on the order (equal to 3e-16 for the soap preset), and the bake, the upload and the
    shader shrink: 0.45 s against 2.15 s, 1 coefficient instead of 91 at the automatic l = 12.
    Without a prefilter (a World not analysed yet) such a film's SH path sees the World's l = 0
    only, until the prefilter is ready. An order set by hand is kept.
    """
    quality = material.quality
    if quality.sh_order != "auto" or sh_weight(material.roughness) > 0.0 or material.base_color is not None:
        return material
    return material.with_(quality=dataclasses.replace(quality, sh_order=0))


#: Lanczos width (l_max + 1)(1 + this · r): glossy lobes need a narrow window against ringing, rough
#: ones are blurred by it (docs/tuning.md#window-width).
WINDOW_WIDTH_PER_ROUGHNESS = 0.9


def lighting_window(l_max: int, roughness: float) -> np.ndarray:
    """Per-coefficient factors applied to the World's SH for a material of this roughness."""
    r = min(max(float(roughness), 0.0), 1.0)
    return windows.window(l_max, "lanczos", (l_max + 1.0) * (1.0 + WINDOW_WIDTH_PER_ROUGHNESS * r))


def windowed_lighting(coeffs, l_max: int, roughness: float) -> np.ndarray:
    """World SH (K, ≥ 3) → ((l_max + 1)², 3) float64 windowed by :func:`lighting_window`: what
    the shader's SH sum (and a radiance grid) reads. Missing coefficients are 0, extra ones
    dropped."""
    c = np.asarray(coeffs, dtype=np.float64)
    k = (int(l_max) + 1) ** 2
    full = np.zeros((k, 3))
    n = min(k, c.shape[0])
    full[:n] = c[:n, :3]
    return full * np.asarray(lighting_window(int(l_max), float(roughness)))[:k, None]


#: From this l_max on a combined film reads its albedo at the dominant direction: below, the second
#: fetch costs more than it gains (docs/tuning.md#moment).
MOMENT_MIN_L = 6


def uses_moment(l_max: int, split_only: bool) -> bool:
    """Whether the split sum reads the albedo at the dominant-direction angle (see
    :data:`MOMENT_MIN_L`): always for split-only films, from l_max 6 on for combined ones."""
    return bool(split_only) or int(l_max) >= MOMENT_MIN_L


# ----------------------------------------------------------------------------------------------
# Outgoing-radiance grid (shading/radiance_grid.py, tf_radiance_grid.glsl)
# ----------------------------------------------------------------------------------------------
#: Mirror-direction cells of the outgoing-radiance grid (W azimuth × H polar, equirect) and its
#: view azimuths ψ about the mirror direction (periodic); its view angles θo are the table's own
#: (grid_shape): 48 × 24 × 32 × A cells, 4.5 MiB (A = 16) to 9 MiB (A = 32) in RGBA16F, mean
#: ΔE2000 0.06–0.17 from the per-pixel l = 12 SH (docs/tuning.md#radiance-grid).
GRID_MIRROR = (48, 24)
GRID_AZIMUTHS = 32


def grid_shape(view_samples: int) -> tuple[int, int, int, int]:
    """(W, H, T, Ψ) of the grid of a table with ``view_samples`` view angles: T = that count, so
    the grid's θo nodes are the table's and its θo interpolation is the table's own."""
    return (GRID_MIRROR[0], GRID_MIRROR[1], int(view_samples), GRID_AZIMUTHS)


#: From this SH order on a constant-thickness film's SH half is read from the grid: below it the
#: per-pixel sum costs about what the grid's four fetches do (docs/tuning.md#radiance-grid).
GRID_MIN_L = 3


def uses_grid(l_max: int, vary_thickness: bool, sh_weight: float) -> bool:
    """Whether a film's SH half is read from the outgoing-radiance grid (see :data:`GRID_MIN_L`):
    an SH half (``sh_weight`` > 0) at an order from GRID_MIN_L on; a varying thickness only in
    the split-sum/SH hand-over (``sh_weight`` < 1), from the film-free basis grid of the exact
    lobe (shading/lobe_grid.py ``build_basis``: one grid per thickness row would not fit), and
    elsewhere keeps the per-pixel SH."""
    weight = float(sh_weight)
    return int(l_max) >= GRID_MIN_L and weight > 0.0 and (not vary_thickness or weight < 1.0)


def table_uses_grid(material, result, prefiltered: bool) -> bool:
    """Whether ``material``'s baked table ``result`` reads an SH grid (:func:`uses_grid` of a
    constant thickness): its SH order, its SH weight (1 while the World has no prefilter: the
    split sum needs one). The viewport asks it, and so does the bake helper, which builds the
    grid right after the table."""
    vary, weight = _table_facts(material, result, prefiltered)
    return not vary and uses_grid(result.sh_order, vary, weight)


def _table_facts(material, result, prefiltered: bool) -> tuple[bool, float]:
    """(whether the table's thickness varies: a range and more than one row, its SH weight)."""
    vary = bool(material.varies) and np.asarray(result.thicknesses_nm).size > 1
    return vary, sh_weight(material.roughness) if prefiltered else 1.0


def table_uses_basis_grid(material, result, prefiltered: bool) -> bool:
    """Whether ``material``'s baked table ``result`` of a varying thickness reads the film-free
    basis grid (:func:`uses_grid` with a varying thickness: the hand-over; the viewport's worker
    builds it, shading/lobe_grid.py ``build_basis``)."""
    vary, weight = _table_facts(material, result, prefiltered)
    return vary and uses_grid(result.sh_order, vary, weight)


#: Films in the hand-over (0 < sh_weight < 1, roughness 0.2–0.45) fill their grid by integrating
#: the exact lobe (shading/lobe_grid.py) instead of from the SH, with this many GGX nodes (θ × φ)
#: per cell and view angles: courtyard 800 nm r 0.3 against Cycles 2.06 → 0.95 mean ΔE2000
#: (docs/tuning.md#lobe-grid).
LOBE_GRID_SAMPLES = (16, 16)
LOBE_GRID_VIEWS = 16
#: A varying film's film-free basis grid (shading/lobe_grid.py ``build_basis``): GRID_HATS
#: piecewise-linear hats over u = v·h ∈ [0, 1] side by side along the texture's width, at
#: GRID_BASIS_VIEWS view nodes. The film's colour across the lobe as the hats interpolate it,
#: against the exact lobe grid (800 nm, r 0.3, a smooth World): 8 hats 0.75 % median, 9.1 % of
#: the peak at most (grazing); 12 hats 0.28 %, 3.6 %; 16 hats 0.16 %, 1.9 %; two nodes at each
#: view's own mean u ± spread 30 % at grazing views. In the product at roughness 0.3 (the noise
#: sphere, 1024 spp): 12 hats 1.36, 16 hats 1.21, 24 hats 1.13 mean ΔE2000, the draw 1.4×, 1.8×,
#: 2.6× the per-pixel SH on llvmpipe, 60, 80, 120 MiB in RGBA16F
#: (docs/tuning.md#lobe-grid, its basis grid section).
GRID_HATS = 16
GRID_BASIS_VIEWS = 16
GRID_BASIS_MIRROR = GRID_MIRROR
#: The weight of an integrated grid against the split sum, reached at roughness LOBE_GRID_RAMP[1]
#: by a smoothstep from LOBE_GRID_RAMP[0]: the grid's 7.5° mirror cells blur the sharpest lobes,
#: so the split sum keeps a share, and all of it at the hand-over's start (docs/tuning.md#lobe-grid).
LOBE_GRID_WEIGHT = 0.9
LOBE_GRID_RAMP = (0.2, 0.3)


def uses_lobe_grid(roughness: float, diffuse_base: bool = False, wall: bool = False) -> bool:
    """Whether a grid film's grid integrates the exact lobe (:data:`LOBE_GRID_SAMPLES`): in the
    hand-over, 0 < :func:`sh_weight` < 1, where neither the l = 12 SH nor the split sum's one
    colour per pixel holds; not under a ``diffuse_base`` or for a transparent film's ``wall``,
    whose tables hold more than the specular lobe the grid integrates (they keep the SH grid)."""
    return 0.0 < sh_weight(roughness) < 1.0 and not diffuse_base and not wall


def grid_weight(roughness: float, lobe_grid: bool) -> float:
    """The weight of the grid half of a film drawn from a grid: for an integrated one
    (:func:`uses_lobe_grid`) :data:`LOBE_GRID_WEIGHT` × smoothstep over :data:`LOBE_GRID_RAMP`,
    else :func:`sh_weight`."""
    if not lobe_grid:
        return sh_weight(roughness)
    lo, hi = LOBE_GRID_RAMP
    t = min(max((float(roughness) - lo) / (hi - lo), 0.0), 1.0)
    return LOBE_GRID_WEIGHT * t * t * (3.0 - 2.0 * t)


#: While a variant compiles (ahead, one per idle step) the viewport draws its film with the
#: variant of this order at most and no grid: bands above it are left out of the sum (the
#: table's and the lighting's layouts do not depend on the order), and up to l = 2 the
#: rotation is a few dot products that compile in a fraction of the l = 12 code's time.
STAND_IN_L = 2


# ----------------------------------------------------------------------------------------------
# Prefiltered levels
# ----------------------------------------------------------------------------------------------
#: Prefiltered levels of the split sum: no roughness far from one (docs/tuning.md#level-ladder).
LEVEL_COUNT = 9
#: Level k holds roughness (k / (J − 1))^this: dense where the lobe changes fastest
#: (docs/tuning.md#level-ladder).
LEVEL_EXPONENT = 2
#: Roughness of each prefiltered level (Blender roughness; α = r²).
ROUGHNESS_LEVELS = tuple(((np.arange(LEVEL_COUNT) / (LEVEL_COUNT - 1)) ** LEVEL_EXPONENT).tolist())

#: r_eff = r · cos(θo)^this: the prefilter's n = v = r lobe is wider than the masked one at grazing
#: views (docs/tuning.md#grazing-exponent).
GRAZING_EXPONENT = 0.5


def effective_roughness(roughness: float, cos_o) -> np.ndarray:
    """r_eff = r · cos(θo)^GRAZING_EXPONENT (cos θo clamped to [MIN_COS, 1])."""
    c = np.clip(np.asarray(cos_o, dtype=float), MIN_COS, 1.0)
    return np.clip(roughness, 0.0, 1.0) * c**GRAZING_EXPONENT


# ----------------------------------------------------------------------------------------------
# The World's lamps
# ----------------------------------------------------------------------------------------------
#: At most this many lamps (the shader's loop bound): more gains little (docs/tuning.md#max-lamps).
MAX_LAMPS = 8
#: Levels below this keep the lamps in the image (a mirror shows their shape), from it on the lamps
#: are shaded per direction (docs/tuning.md#lamp-level).
LAMP_LEVEL = 2

# ----------------------------------------------------------------------------------------------
# Blender's light objects (shading/lights.py)
# ----------------------------------------------------------------------------------------------
#: At most this many light objects per frame (the TFLights buffer: 5 vec4s each, 2.6 KiB); the
#: nearest/brightest are not chosen: the first in the depsgraph's order (docs/scene-lights.md).
MAX_LIGHTS = 32
#: Area lights: S × S cells, one sample each (docs/scene-lights.md#area-samples).
AREA_SAMPLES = 4
#: Rectangle lights: the cells follow the film's lobe, a Cauchy of this many α around the mirror
#: ray's hit (docs/scene-lights.md#area-samples), never narrower than AREA_MIN_WIDTH of the light.
AREA_LOBE_SCALE = 2.0
AREA_MIN_WIDTH = 1e-3
#: A lobe's centre and width are bounded to this many light sizes: float32 keeps c + w tan(·) to
#: 1e-5 there, and a wider lobe is uniform over the light anyway.
AREA_MAX_WIDTH = 100.0
#: The lobe width that makes the cells uniform: the mirror ray misses the light's plane.
AREA_UNIFORM_WIDTH = 1e6
#: Shortest axis of an area light the shaders divide by (a degenerate, zero-size light).
AREA_MIN_AXIS = 1e-12
#: Nearest distance to a light's centre or sample the shaders divide by: a 10⁵ W point light at
#: 0.1 mm gives 8·10¹⁴ W/m², far inside float32.
MIN_LIGHT_DISTANCE = 1e-4
#: The light kinds as the TFLights buffer stores them (shading/lights.py).
LIGHT_KINDS = {"SUN": 0, "POINT": 1, "SPOT": 2, "AREA": 3}
#: Vec4s per light in the TFLights buffer (addon/gpu/resources.py LIGHTS, lights.Lights.pack).
LIGHT_VEC4 = 5

# ----------------------------------------------------------------------------------------------
# Transparent films (shading/transmit.py)
# ----------------------------------------------------------------------------------------------
#: Cap of a sheet's reflection scale R / r where the film barely reflects (an AR coating over a
#: reflecting back face: S ≈ 9 at r = 0.5 %); the cap only guards r → 0 (docs/transparent-films.md).
WALL_SCALE_MAX = 16.0
#: Reflections inside a closed thin wall drawn after the far wall's own (shading.transmit): 2 (the
#: lamps' arcs after two and three reflections in a bubble: 2.70 → 1.36 mean ΔE2000 against
#: Cycles, benchmarks.transparent_films; a fourth reflection would take 0.04 more, in a numpy trace).
INSIDE_ORDERS = 2
#: The share of a wall's thickness variance its linear fit must explain (R²) for the reflections
#: inside to be drawn (shading.transmit.Inside.drawn): the benchmark's Map Range 1, a noise ≈ 0.
INSIDE_MIN_EXPLAINED = 0.5
#: Smallest reflectance and denominator a wall's formulas divide by (r → 0, r·R_b → 1).
WALL_GUARD = 1e-6
#: Solid glass's screen-space refraction (shading/glass/refract.py, glsl/tf_refract.glsl): the exit ray
#: is marched over the scene behind in REFRACT_STEPS samples at distances growing geometrically
#: from REFRACT_FIRST × the exit point's depth by REFRACT_GROWTH per step (1.16⁴⁷ ≈ 1070: the
#: last sample lies ≈ 10 depths away), and a crossing of the depth behind is refined by
#: REFRACT_REFINE bisections (the hit to 1/256 of a step). A crossing further behind the surface
#: than REFRACT_THICKNESS × its depth passed behind an occluder: no hit
#: (docs/transparent-films.md#solid-glass-refraction).
REFRACT_STEPS = 48
REFRACT_FIRST = 0.01
REFRACT_GROWTH = 1.16
REFRACT_REFINE = 8
REFRACT_THICKNESS = 0.25
#: A ray marched out of the picture (after a sample inside it) sees the picture's texel where it
#: left (the scene beyond the edge taken as the scene at the edge: the ground goes on) instead of
#: the World: a glass cube's side faces, whose rays leave sideways after total internal
#: reflection, and a ball's rim see the ground as Cycles does (docs/tuning.md#refract-edge);
#: only where the ray heads into that surface (refract._meets_ahead): one climbing away from the
#: ground sees the World.
REFRACT_EDGE = True
#: The line through the surface points under a ray's last two samples inside the picture
#: (refract._meets_ahead): its squared length, relative to the squared distance of the first from
#: the origin (at least 1), below which the two are one point and the line is unknown; and
#: |ray × line|² relative to the line's squared length below which the ray runs parallel to it
#: (never meets it). Float32 keeps ~1e-7 of a length: its square's resolution is ~1e-14.
REFRACT_LINE_EPS = 1e-12
#: Smooth solid glass reflects the scene behind where its mirror ray meets it (the same march),
#: in place of the World: fully at roughness 0, fading out linearly to none at this roughness,
#: where the split sum's blurred World stands (docs/transparent-films.md#solid-glass-refraction).
#: 0.2 before: the benchmark's ball (roughness 0.05) kept a quarter of the World's dark lower
#: half where Cycles reflects the ground (mean ΔE2000 over the Cycles pass 3.54; w = 1: 3.31).
REFRACT_MIRROR_ROUGHNESS = 0.5
#: The headless frame's background pass is rendered REFRACT_OVERSCAN × the frame's longer side
#: wider on each side when it has solid glass: rays bent out of the frame (a ball's top half sees
#: the ground in front of the camera, its rim the ground beside it) still find the scene there.
#: The glass sphere against (clamped) Cycles: mean ΔE2000 6.76 at 0.25, 5.75 at 0.5 (4× the
#: pass's pixels); against unclamped Cycles 5.29 at 0.5, 4.63 at 1.0 (9× the pass's pixels; the
#: rim's rays, bent furthest, find the ground; docs/transparent-films.md#solid-glass-refraction).
REFRACT_OVERSCAN = 1.0
#: …but never wider than this many pixels on its longer side (a 4K frame would otherwise need a
#: 7680 × 6000 pass: 740 MB as the RGBA32F texture the glass reads). Its pixels are the frame's:
#: a pass twice as fine was measured and not kept (docs/tuning.md#background-pass-density).
REFRACT_MAX_SIDE = 4096
#: Depth the scene-behind texture stores where nothing was drawn (the World): beyond any march.
REFRACT_FAR = 1e30
#: Solid glass's exit through its real mesh (shading/glass/glass_exit.py mesh_exit, glsl/tf_glass_exit.glsl):
#: the inner ray is marched over the object's front and back faces (the glass buffers) in
#: GLASS_STEPS even steps over GLASS_REACH × the entry point's distance from the object's origin
#: (a cube's corner lies √3 half sides away, a face's middle one: its space diagonal is 3.5× that),
#: the first step outside bisected GLASS_REFINE times; a point counts as outside a face when it
#: lies GLASS_SLACK × its depth beyond it (the buffers' rasterised depth against the interpolated
#: surface); GLASS_BOUNCES faces at most (total internal reflections): a path that has not left
#: by then carries nothing, as Cycles' bounce limit ends it (docs/tuning.md#glass-buffers).
GLASS_STEPS = 24
GLASS_REACH = 4.0
GLASS_REFINE = 6
GLASS_SLACK = 1e-4
GLASS_BOUNCES = 8
#: The glass buffers hold GLASS_LAYERS front and back faces per pixel, nearest first (depth
#: peeling): a concave glass's further spans, a wine glass's far wall behind its near one or its
#: foot behind its stem. A ray that leaves the glass is marched on, in GLASS_STEPS even steps over
#: the same reach, into those spans (it meets the far wall as Cycles' path does) before the scene
#: behind; a face more than GLASS_PEEL × its depth behind the layer before is the next layer's.
GLASS_LAYERS = 2
GLASS_PEEL = 1e-5
#: Solid glass's glints: the paths that the film reflects back inside 1 … GLASS_ORDERS times
#: before they leave (glsl/tf_main_frag.glsl tf_glass_glint; faces that reflect totally do so on
#: every path). Near a ball's rim the film reflects most of the light back inside (its inner angle
#: nears the critical one): Cycles' transmission there was 2–3× ours in the median with one. The
#: benchmark's ball over a Cycles pass: 3.12 with 1, 2.98 with 4 (docs/transparent-films.md).
GLASS_ORDERS = 4
#: Cycles' rule for a smooth-shaded face (``ensure_valid_specular_reflection``, Blender 5.2): a
#: shading normal whose mirror of the incoming ray (at cosine c to the face) rises less than
#: min(VALID_REFLECTION_SCALE c, VALID_REFLECTION_RISE) above the face is turned towards the
#: face's own normal until it rises exactly that much (shading/glass/glass_exit.py ``valid_normal``).
VALID_REFLECTION_SCALE = 0.9
VALID_REFLECTION_RISE = 0.01
#: With the glass buffers solid glass draws only its nearest front face: a fragment more than this
#: × its depth behind the front buffer's face is inside the glass (a wine glass's far wall, seen
#: through its near one), and is left out (docs/tuning.md#glass-buffers).
GLASS_FRONT_SLACK = 1e-3
#: The normal of a face the glass march meets is interpolated between the four texel centres
#: around the point (shading/glass/glass_exit.py ``_Glass._blend``), over the texels of the same
#: face: the object's, their normal within this cosine of the nearest texel's (a flat-shaded
#: crease, 20 degrees and more, keeps its edge) and their depth within GLASS_BLEND_DEPTH × its
#: depth (another surface behind keeps its own). The nearest texel's normal alone misplaced a
#: wine glass's rim glints by pixels (docs/transparent-films.md#solid-glass-refraction).
GLASS_BLEND_COS = 0.94
GLASS_BLEND_DEPTH = 0.02
#: Rough solid glass: the World's lamps in the tails of its paths' lobes (shading.glass.tails).
#: A lamp's own image (the World's sharp level shows it) is taken as this radius (radians): the
#: tails are counted outside it (the studio HDRI's lamps: about 2°; docs/tuning.md#glass-tail-core).
GLASS_TAIL_CORE = 0.035
#: A path leaving near the critical angle magnifies every earlier turn without bound: at most this.
GLASS_TAIL_MAX_GAIN = 30.0
#: The scene around solid glass (shading.glass.probe): where a path leaves the picture (towards
#: the camera, or off its edges) it sees the scene as six PROBE_FACE² views from the glass's centre
#: show it, resampled to a PROBE_ROWS × 2 PROBE_ROWS panorama of colour and distance. The path is
#: marched through it: PROBE_STEPS samples at distances growing by PROBE_GROWTH from PROBE_FIRST ×
#: its origin's distance from the probe's point, the first that passes behind the probe's surface
#: bisected PROBE_REFINE times; where it passes behind none, the World (docs/tuning.md#scene-probe).
PROBE_FACE = 128
PROBE_ROWS = 256
PROBE_STEPS = 32
PROBE_FIRST = 0.1
PROBE_GROWTH = 1.25
PROBE_REFINE = 6
#: EEVEE's samples per probe view (its TAA; the frame's pass keeps the scene's own): each costs
#: about as much as the view's own setup on llvmpipe, and the views are blurred by the resampling.
PROBE_SAMPLES = 2
#: Cycles' samples per probe view at most (a Cycles background pass; the scene's own where fewer).
PROBE_CYCLES_SAMPLES = 64
#: Solid glass's shadow and caustics in EEVEE's background pass (precompute/optics/caustics.py):
#: each sun's photons on a CAUSTIC_GRID² grid over the glass's bounding sphere; a cell of four
#: photons spread over its image on the receiver unless it is wider than CAUSTIC_MAX_EXTENT
#: pixels (its corners parted: another path), by up to CAUSTIC_MAX_SUB² sub-points; a photon counts
#: on a pixel whose depth is within CAUSTIC_DEPTH_SLACK × its own; photons below CAUSTIC_MIN_FLUX ×
#: the brightest are dropped (docs/transparent-films.md#the-background-pass-eevee-lit-like-cycles).
CAUSTIC_GRID = 160
CAUSTIC_MAX_EXTENT = 24.0
CAUSTIC_MAX_SUB = 32
CAUSTIC_DEPTH_SLACK = 0.05
CAUSTIC_MIN_FLUX = 1e-4
#: Directions per sun (its centre, the rest on a ring: caustics.disc_directions), for the soft
#: edges of a sun of finite size; 1: its centre alone.
CAUSTIC_DISC_SAMPLES = 1
#: Film reflections on one photon's path (off the glass outside, or back inside): each starts a
#: branch; a wine glass's thin walls cross 8 faces, and with every reflection followed its photons
#: took over 11 minutes.
CAUSTIC_REFLECTIONS = 1
#: Faces a photon may meet inside glass before it is dropped: Cycles' 12 transmission bounces by
#: default, 16 in the benchmarks' references. Rough glass reflects totally far more often than
#: smooth (a third of a rough ball's light at α 0.45) and its light leaves after a few faces:
#: with 8 a rough ball lost 5.5 % of it, with 16 0.8 % (tests/optics/test_caustics.py).
CAUSTIC_BOUNCES = 16
#: Rough glass's photons (Cycles' Filter Glossy, facets.blur_roughness) scatter apart: their
#: flux is averaged over a Gaussian of this × the glass's radius on the picture (caustics.smooth),
#: well inside the light's own spread (a third to a whole radius on the ground).
CAUSTIC_SMOOTH = 0.1
#: EEVEE's background pass lights the scene with the World's radiance above this × its mean
#: luminance lifted out into sun lights (addon/headless/background_lamps.py): the benchmark's checker
#: ground against Cycles 1.15× at 32 (the lamps' own threshold, lamps.THRESHOLD), 1.04× at 8,
#: 0.98× at 2 (EEVEE's own lighting: 5.1×; docs/tuning.md#background-lamp-threshold).
BACKGROUND_LAMP_THRESHOLD = 2.0

# ----------------------------------------------------------------------------------------------
# Guards
# ----------------------------------------------------------------------------------------------
#: Smallest cosine the shaders divide by (grazing views): constants.MIN_COS.
MIN_COS = constants.MIN_COS
#: Smallest GGX α of the lamps' lobe (below, a delta no sample resolves): constants.MIN_ALPHA.
MIN_ALPHA = constants.MIN_ALPHA
#: sin β below which the z-y-z split is one z-rotation (gimbal): far below any table resolution.
GIMBAL_SIN = 1e-7
#: |v − n (n·v)| below which the GLSL takes v ∥ n: float32 rounding leaves ~1e-7 (numpy: 1e-9).
TANGENT_EPS = 1e-6
#: X(±90°) entries below this are structural zeros (noise ≤ 3e-16, the least true entry 2⁻⁷): the
#: generated code skips them (docs/tuning.md#x90-generated).
X90_ZERO = 1e-9
#: Floor of a divisor, or of a squared length before a normalisation: keeps 0/0 finite; every value
#: the shading divides by in float32 is orders of magnitude above it.
DIVISION_FLOOR = 1e-30
#: Squared length below which the prefilter's direction moment counts as vanished (a black World
#: in the lobe): the split sum keeps the view angle (float32, as DIVISION_FLOOR).
MOMENT_EPS = DIVISION_FLOOR
#: The view-aligned frame's helper axis, for a view along the normal, is x unless the normal's
#: |x| reaches this (then y): any bound well inside (0, 1) keeps the helper far from parallel.
HELPER_AXIS_MAX = 0.9
#: Squared length of solid glass's exit direction below which it counts as totally internally
#: reflected (GLSL's refract() returns 0 there; numpy's exit ray is 0 to rounding).
TIR_EPS = 1e-12

# ----------------------------------------------------------------------------------------------
# Devices
# ----------------------------------------------------------------------------------------------
#: Device types drawing tables from a uniform buffer: cheaper than texelFetch on llvmpipe, dearer
#: on an NVIDIA GPU (docs/tuning.md#table-ubo-devices).
TABLE_UBO_DEVICES = ("SOFTWARE",)


# ----------------------------------------------------------------------------------------------
# Display
# ----------------------------------------------------------------------------------------------
#: Lattice points per axis of the viewport's display LUT (precompute/colour/display_lut.py): the
#: trilinear error against OCIO (docs/tuning.md#display-lut).
DISPLAY_LUT_SIZE = 65
#: The LUT shaper's offset a in log2(x + a): resolves the sRGB toe (docs/tuning.md#display-lut).
DISPLAY_LUT_FLOOR = 2.0**-12
#: The largest scene-linear value the LUT resolves (after exposure); brighter clamps: above
#: Filmic's and AgX's white (docs/tuning.md#display-lut).
DISPLAY_LUT_MAX = 2.0**7.2


# ----------------------------------------------------------------------------------------------
# GLSL
# ----------------------------------------------------------------------------------------------
def glsl_float(value: float) -> str:
    """A GLSL float literal for ``value`` (Python's shortest repr, with a point or an exponent)."""
    text = repr(float(value))
    if not all(c in "0123456789.e-+" for c in text):
        raise ValueError(f"{value!r} has no GLSL literal")
    return text if ("." in text or "e" in text) else text + ".0"


def glsl_power(x: str, exponent: float) -> str:
    """x^exponent as GLSL: ``sqrt`` for ½ and a product for 2 (what the shaders were written with,
    so the compiled code is unchanged), ``pow`` otherwise."""
    e = float(exponent)
    if e == 1.0:
        return f"({x})"
    if e == 0.5:
        return f"sqrt({x})"
    if e == 2.0:
        return f"(({x}) * ({x}))"
    return f"pow({x}, {glsl_float(e)})"


def _glsl_value(value) -> str:
    """A constant's GLSL literal by its Python type: a bool as 1/0, an int as an int, a float as a
    float (:func:`glsl_float`); a float constant is declared with a decimal point (``100.0``)."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return glsl_float(value)
    raise TypeError(f"policy constant of type {type(value).__name__} has no GLSL literal")


def _defines(*names: str) -> tuple[tuple[str, str], ...]:
    """``(TF_<name>, literal)`` of this module's constants ``names``, in their order."""
    return tuple((f"TF_{name}", _glsl_value(globals()[name])) for name in names)


def glsl_defines() -> tuple[tuple[str, str], ...]:
    """(name, value) of every ``#define`` of a shading rule the shaders use (read at call time).

    - ``TF_MAX_LAMPS``, ``TF_LAMP_LEVEL``: :data:`MAX_LAMPS`, :data:`LAMP_LEVEL`;
    - ``TF_MAX_LIGHTS``, ``TF_AREA_SAMPLES``, ``TF_AREA_LOBE_SCALE``, ``TF_AREA_MIN_WIDTH``,
      ``TF_AREA_MAX_WIDTH``, ``TF_AREA_UNIFORM_WIDTH``, ``TF_AREA_MIN_AXIS``,
      ``TF_MIN_LIGHT_DISTANCE``, ``TF_LIGHT_<KIND>``, ``TF_LIGHT_VEC4``: the light objects' rules
      (:data:`MAX_LIGHTS` … :data:`LIGHT_KINDS`) and their buffer's stride (:data:`LIGHT_VEC4`);
    - ``TF_WALL_SCALE_MAX``, ``TF_WALL_GUARD``, ``TF_INSIDE_ORDERS``: :data:`WALL_SCALE_MAX`,
      :data:`WALL_GUARD`, :data:`INSIDE_ORDERS`;
    - ``TF_MIN_COS``, ``TF_MIN_ALPHA``, ``TF_GIMBAL_SIN``, ``TF_TANGENT_EPS``,
      ``TF_DIVISION_FLOOR``, ``TF_MOMENT_EPS``, ``TF_HELPER_AXIS_MAX``, ``TF_TIR_EPS``: the guards;
    - ``TF_GRAZING(x)`` = x^GRAZING_EXPONENT (:func:`effective_roughness`);
    - ``TF_LADDER_ROUGHNESS(x)`` = x^LEVEL_EXPONENT, the roughness of the level at position x =
      k / (J − 1), and ``TF_LADDER_POSITION(r)`` = r^(1 / LEVEL_EXPONENT), its inverse;
    - ``TF_DISPLAY_LUT_SIZE``, ``TF_DISPLAY_LUT_FLOOR``, ``TF_DISPLAY_LUT_MAX``: the display LUT
      (:data:`DISPLAY_LUT_SIZE` … :data:`DISPLAY_LUT_MAX`).
    - ``TF_GRID_AZIMUTHS``: the grid's view azimuths :data:`GRID_AZIMUTHS`; ``TF_GRID_HATS``: a
      varying film's basis grid's hats over u (:data:`GRID_HATS`);
    - ``TF_REFRACT_STEPS``, ``TF_REFRACT_FIRST``, ``TF_REFRACT_GROWTH``, ``TF_REFRACT_REFINE``,
      ``TF_REFRACT_THICKNESS``, ``TF_REFRACT_MIRROR_ROUGHNESS``: solid glass's screen-space march
      (:data:`REFRACT_STEPS` …) and its mirror of the scene; ``TF_REFRACT_EDGE``: 1 where
      :data:`REFRACT_EDGE`; ``TF_REFRACT_FAR``: :data:`REFRACT_FAR`; ``TF_REFRACT_LINE_EPS``:
      :data:`REFRACT_LINE_EPS`;
    - ``TF_GLASS_STEPS``, ``TF_GLASS_REACH``, ``TF_GLASS_REFINE``, ``TF_GLASS_SLACK``,
      ``TF_GLASS_BOUNCES``, ``TF_GLASS_FRONT_SLACK``, ``TF_GLASS_LAYERS``, ``TF_GLASS_PEEL``,
      ``TF_GLASS_BLEND_COS``, ``TF_GLASS_BLEND_DEPTH``:
      the exit through the real mesh (:data:`GLASS_STEPS` …); ``TF_GLASS_ORDERS``: its glints
      (:data:`GLASS_ORDERS`); ``TF_GLASS_TAIL_CORE``, ``TF_GLASS_TAIL_MAX_GAIN``: the lamps in a
      rough path's tails (:data:`GLASS_TAIL_CORE`, :data:`GLASS_TAIL_MAX_GAIN`);
      ``TF_PROBE_STEPS``, ``TF_PROBE_FIRST``, ``TF_PROBE_GROWTH``, ``TF_PROBE_REFINE``: the march
      through the scene probe (:data:`PROBE_STEPS` …);
      ``TF_VALID_REFLECTION_SCALE``, ``TF_VALID_REFLECTION_RISE``: Cycles' rule at a
      smooth-shaded face (:data:`VALID_REFLECTION_SCALE`, :data:`VALID_REFLECTION_RISE`).
    """
    return (
        *_defines(
            "MAX_LAMPS",
            "LAMP_LEVEL",
            "MAX_LIGHTS",
            "AREA_SAMPLES",
            "MIN_LIGHT_DISTANCE",
            "AREA_LOBE_SCALE",
            "AREA_MIN_WIDTH",
            "AREA_MAX_WIDTH",
            "AREA_UNIFORM_WIDTH",
            "AREA_MIN_AXIS",
        ),
        *((f"TF_LIGHT_{kind}", str(code)) for kind, code in LIGHT_KINDS.items()),
        *_defines(
            "LIGHT_VEC4",
            "WALL_SCALE_MAX",
            "WALL_GUARD",
            "INSIDE_ORDERS",
            "MIN_COS",
            "MIN_ALPHA",
            "GIMBAL_SIN",
            "TANGENT_EPS",
            "DIVISION_FLOOR",
            "MOMENT_EPS",
            "HELPER_AXIS_MAX",
            "TIR_EPS",
        ),
        ("TF_GRAZING(x)", glsl_power("x", GRAZING_EXPONENT)),
        ("TF_LADDER_ROUGHNESS(x)", glsl_power("x", LEVEL_EXPONENT)),
        ("TF_LADDER_POSITION(r)", glsl_power("r", 1.0 / LEVEL_EXPONENT)),
        *_defines(
            "DISPLAY_LUT_SIZE",
            "DISPLAY_LUT_FLOOR",
            "DISPLAY_LUT_MAX",
            "GRID_AZIMUTHS",
            "GRID_HATS",
            "REFRACT_STEPS",
            "REFRACT_FIRST",
            "REFRACT_GROWTH",
            "REFRACT_REFINE",
            "REFRACT_THICKNESS",
            "REFRACT_MIRROR_ROUGHNESS",
            "REFRACT_EDGE",
            "REFRACT_FAR",
            "REFRACT_LINE_EPS",
            "GLASS_STEPS",
            "GLASS_REACH",
            "GLASS_REFINE",
            "GLASS_SLACK",
            "GLASS_BOUNCES",
            "GLASS_LAYERS",
            "GLASS_PEEL",
            "VALID_REFLECTION_SCALE",
            "VALID_REFLECTION_RISE",
            "GLASS_FRONT_SLACK",
            "GLASS_BLEND_COS",
            "GLASS_BLEND_DEPTH",
            "GLASS_ORDERS",
            "GLASS_TAIL_CORE",
            "GLASS_TAIL_MAX_GAIN",
            "PROBE_STEPS",
            "PROBE_FIRST",
            "PROBE_GROWTH",
            "PROBE_REFINE",
        ),
    )
