"""Bridge between Blender materials and :mod:`precompute`: descriptions, tables, write-back.

Everything here takes bpy objects (materials, meshes, the extension's property groups) and
returns plain Python / numpy values; the physics stays in ``precompute``.

- :func:`description` — the :class:`~precompute.material.Material` a Blender material shows:
  from the extension's settings when they are enabled, else from a Principled BSDF with a thin
  film (Cycles interop), else None. :func:`warnings` lists what the preview cannot follow.
- :func:`get_table` — the baked SH table of a description: an in-memory LRU, then the on-disk
  :class:`~precompute.table_io.TableCache`, then a bake. Equal descriptions share one table.
- :func:`write_back_to_principled` — the extension's settings into the Principled BSDF, so
  Cycles' final render matches the preview as far as Cycles' single film allows.
- :func:`thickness_per_vertex` / :func:`corner_order` — per-corner thickness parameter in [0, 1]
  for the three thickness sources (mesh attribute, procedural noise, image).

Numbers read from Blender are float32; :func:`_f32` turns them back into the shortest decimal
that rounds to the same float32 (1.33 stays 1.33, not 1.3300000429153442), so a description
from the UI equals the preset or CLI material with the same values and shares its cache key.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import threading

import numpy as np

from ..precompute import bake, spectra, table_io
from ..precompute.material import AUTO, PRESETS, Layer, Material, Quality
from ..precompute.optics import metals, reflectance
from ..precompute.shading import policy

__all__ = [
    "LRU_SIZE",
    "apply_preset",
    "applying",
    "conductor_from_rgb",
    "parse_plan",
    "bake_count",
    "clear_caches",
    "clear_memory_cache",
    "corner_order",
    "description",
    "description_from_props",
    "description_key",
    "fill_from_material",
    "format_plan",
    "get_table",
    "get_table_with_source",
    "gulbrandsen_nk",
    "mark_custom",
    "metal_rgb",
    "peek_table",
    "principled_node",
    "table_cache",
    "thickness_per_vertex",
    "value_noise",
    "warnings",
    "working_space",
    "write_back_to_principled",
]

log = logging.getLogger(__name__)

#: Principled BSDF socket names (Blender 4.0+; checked against 5.2).
SOCKET_THICKNESS = "Thin Film Thickness"
SOCKET_FILM_IOR = "Thin Film IOR"
SOCKET_IOR = "IOR"
SOCKET_ROUGHNESS = "Roughness"
SOCKET_METALLIC = "Metallic"
SOCKET_BASE_COLOR = "Base Color"
SOCKET_SPECULAR_TINT = "Specular Tint"
SOCKET_TRANSMISSION = "Transmission Weight"

#: Wavelengths (nm) standing for the R, G and B channels when an RGB conductor fit becomes a
#: spectral table (roughly the dominant wavelengths of the Rec.709 primaries).
RGB_WAVELENGTHS_NM = (465.0, 550.0, 610.0)
#: Where a film's dispersive index is read for Principled's single "Thin Film IOR".
REFERENCE_WAVELENGTH_NM = 550.0
#: cos θ of the F82 edge-tint angle (θ ≈ 81.8°, cos θ = 1/7) of Blender's metallic Fresnel.
F82_COS = 1.0 / 7.0

#: Extra Material fields for a Principled preview: Cycles' film-free multiscatter compensation,
#: where precompute offers that choice.
_CYCLES_PARITY = {"multiscatter": "cycles"} if "multiscatter" in Material.__dataclass_fields__ else {}

#: Entries kept in the in-memory table cache.
LRU_SIZE = 32

#: Number of real bakes (cache misses) since the module was loaded; the tests read it.
bake_count = 0

_lru: collections.OrderedDict = collections.OrderedDict()
_lock = threading.RLock()
_applying = 0  # > 0 while fill_from_material writes properties (they must not mark CUSTOM)


# ----------------------------------------------------------------------------------------------
# Small helpers
# ----------------------------------------------------------------------------------------------
def _f32(value) -> float:
    """The shortest decimal that rounds to the same float32 as ``value`` (NaN/Inf pass through)."""
    return float(str(np.float32(value)))


def _file_working_space() -> str:
    import bpy

    colorspace = getattr(bpy.data, "colorspace", None)  # Blender 5.x: per-file working space
    return getattr(colorspace, "working_space", "") if colorspace is not None else ""


def working_space() -> str:
    """The blend file's working colour space if precompute knows it, else "Linear Rec.709"."""
    name = _file_working_space()
    return name if name in spectra.WORKING_SPACES else spectra.DEFAULT_SPACE


def _metal_name(identifier: str) -> str:
    return metals.get_metal(identifier.lower()).name


def _enum_id(name: str) -> str:
    return name.upper()


def _tree(bpy_material):
    return getattr(bpy_material, "node_tree", None)


def _output_node(tree):
    """The active Material Output node (falling back to any), or None."""
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    for node in outputs:
        if getattr(node, "is_active_output", False):
            return node
    return outputs[0] if outputs else None


def principled_node(bpy_material):
    """The Principled BSDF feeding the material output's Surface, else the first one, else None."""
    tree = _tree(bpy_material)
    if tree is None:
        return None
    output = _output_node(tree)
    if output is not None:
        surface = output.inputs.get("Surface")
        if surface is not None and surface.is_linked:
            node = surface.links[0].from_node
            if node.bl_idname == "ShaderNodeBsdfPrincipled":
                return node
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeBsdfPrincipled":
            return node
    return None


# ----------------------------------------------------------------------------------------------
# Conductors from RGB: Gulbrandsen (2014), and its inverse through precompute
# ----------------------------------------------------------------------------------------------
def gulbrandsen_nk(reflectivity, edge_tint) -> tuple[np.ndarray, np.ndarray]:
    """Complex index (n, k) from normal-incidence reflectivity r and edge tint g, per channel.

    O. Gulbrandsen (2014), "Artist Friendly Metallic Fresnel", Journal of Computer Graphics
    Techniques 3(4), 64–72: with n_min = (1 − r)/(1 + r) and n_max = (1 + √r)/(1 − √r),

        n = g·n_min + (1 − g)·n_max,   k = √[(r(n + 1)² − (n − 1)²) / (1 − r)],

    which reproduces F(0°) = ((n − 1)² + k²)/((n + 1)² + k²) = r exactly for any g in [0, 1].
    r is clamped to [0, 0.99] (the formula diverges at 1) and g to [0, 1].
    """
    r = np.clip(np.asarray(reflectivity, dtype=float), 0.0, 0.99)
    g = np.clip(np.asarray(edge_tint, dtype=float), 0.0, 1.0)
    root = np.sqrt(r)
    n_min = (1.0 - r) / (1.0 + r)
    n_max = (1.0 + root) / (1.0 - root)
    n = g * n_min + (1.0 - g) * n_max
    k = np.sqrt(np.maximum(0.0, (r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r)))
    return n, k


def _conductor_fresnel(n, k, cos_i):
    """Unpolarised Fresnel reflectance from air into N = n + ik (broadcasting)."""
    eta = np.asarray(n, dtype=complex) + 1j * np.asarray(k, dtype=float)
    cos_i = np.asarray(cos_i, dtype=float)
    eta2 = eta * eta
    q = np.sqrt(eta2 - (1.0 - cos_i * cos_i))
    rs = (cos_i - q) / (cos_i + q)
    rp = (eta2 * cos_i - q) / (eta2 * cos_i + q)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def _schlick(f0, cos_i):
    return f0 + (1.0 - f0) * (1.0 - cos_i) ** 5


def conductor_from_rgb(base_color, specular_tint=(1.0, 1.0, 1.0)) -> dict:
    """A tabulated-index spec approximating Principled's metal for ``base_color`` (per channel).

    Blender's metallic Fresnel is the F82-tint model: F0 = Base Color, and the reflectance at
    cos θ = 1/7 is Specular Tint × Schlick(F0, 1/7). Gulbrandsen's formula fixes F0; the edge
    tint g of each channel is chosen (grid search on [0, 1]) so that the conductor's Fresnel at
    cos θ = 1/7 is as close as it gets to that F82 value. The three (n, k) pairs are placed at
    :data:`RGB_WAVELENGTHS_NM` and held flat beyond them (360–830 nm).
    """
    r = np.clip(np.asarray(base_color, dtype=float)[:3], 0.0, 0.99)
    tint = np.clip(np.asarray(specular_tint, dtype=float)[:3], 0.0, 1.0)
    target = tint * _schlick(r, F82_COS)
    grid = np.linspace(0.0, 1.0, 401)
    n, k = gulbrandsen_nk(r[None, :], grid[:, None])  # (G, 3)
    f82 = _conductor_fresnel(n, k, F82_COS)
    best = np.argmin(np.abs(f82 - target[None, :]), axis=0)
    n_rgb, k_rgb = n[best, [0, 1, 2]], k[best, [0, 1, 2]]
    # Channels ordered R, G, B; the table runs from blue to red.
    n_bgr = [round(float(v), 6) for v in n_rgb[::-1]]
    k_bgr = [round(float(v), 6) for v in k_rgb[::-1]]
    wl = [spectra.WAVELENGTH_MIN_NM, *RGB_WAVELENGTHS_NM, spectra.WAVELENGTH_MAX_NM]
    return {
        "table": {
            "wavelengths_nm": [float(w) for w in wl],
            "n": [n_bgr[0], *n_bgr, n_bgr[-1]],
            "k": [k_bgr[0], *k_bgr, k_bgr[-1]],
        }
    }


def _spectrum_rgb(spectrum, wavelengths_nm, colour_space: str) -> np.ndarray:
    """A reflectance spectrum as working-space RGB (E white: a flat 1 gives (1, 1, 1))."""
    xyz = spectra.spectrum_to_xyz(spectrum, wavelengths_nm)
    return spectra.xyz_to_rgb_matrix(colour_space) @ xyz


def metal_rgb(index_spec, colour_space: str | None = None) -> tuple[tuple, tuple]:
    """(Base Color, Specular Tint) for Principled's metal model from a conductor's index.

    Base Color is the normal-incidence reflectance R(0°, λ) integrated to RGB; Specular Tint
    is R(cos θ = 1/7) in RGB divided by Schlick(F0, 1/7) (Blender's F82 tint), clamped to [0, 1].
    """
    space = colour_space or spectra.DEFAULT_SPACE
    medium = Material(layers=(), substrate=index_spec).indices()[-1]
    wl = spectra.wavelength_grid(95)
    spectra_r = reflectance([1.0, medium], [], wl, [1.0, F82_COS])  # (2, W)
    f0 = np.clip(_spectrum_rgb(spectra_r[0], wl, space), 0.0, 1.0)
    f82 = np.clip(_spectrum_rgb(spectra_r[1], wl, space), 0.0, 1.0)
    tint = np.clip(f82 / np.maximum(_schlick(f0, F82_COS), 1e-6), 0.0, 1.0)
    return tuple(float(v) for v in f0), tuple(float(v) for v in tint)


def _real_index(spec, wavelength_nm: float = REFERENCE_WAVELENGTH_NM) -> complex:
    """N at one wavelength of any IndexSpec."""
    medium = Material(layers=(), substrate=spec).indices()[-1]
    return complex(np.asarray(medium.index(np.array([wavelength_nm])))[0])


# ----------------------------------------------------------------------------------------------
# Properties ↔ Material
# ----------------------------------------------------------------------------------------------
def _layer_spec(layer):
    mode = layer.index_mode
    if mode == "CAUCHY":
        return {"cauchy": [_f32(layer.cauchy_a), _f32(layer.cauchy_b), _f32(layer.cauchy_c)]}
    if mode == "METAL":
        return {"metal": _metal_name(layer.metal)}
    n, k = _f32(layer.n), _f32(layer.k)
    return [n, k] if k != 0.0 else n


def _substrate_spec(props):
    mode = props.substrate_mode
    if mode == "METAL":
        return {"metal": _metal_name(props.substrate_metal)}
    if mode == "CUSTOM":
        n, k = _f32(props.substrate_n), _f32(props.substrate_k)
        return [n, k] if k != 0.0 else n
    return _f32(props.substrate_ior)


def _quality(props) -> Quality:
    def count(value):
        return AUTO if int(value) == 0 else int(value)

    return Quality(
        sh_order=AUTO if props.sh_order == "AUTO" else int(props.sh_order),
        view_samples=count(props.view_samples),
        thickness_samples=count(props.thickness_samples),
        wavelength_count=count(props.wavelength_count),
    )


def description_from_props(props, colour_space: str | None = None) -> Material:
    """The Material of the extension's settings (ValueError naming the bad parameter)."""
    layers = tuple(Layer(_layer_spec(layer), _f32(layer.thickness_nm)) for layer in props.layers)
    return Material(
        layers=layers,
        substrate=_substrate_spec(props),
        ambient=_f32(props.ambient_ior),
        roughness=_f32(props.roughness),
        thickness_range_nm=(
            (_f32(props.thickness_min_nm), _f32(props.thickness_max_nm)) if props.vary_thickness else None
        ),
        base_color=tuple(_f32(v) for v in props.diffuse_color) if props.diffuse_base else None,
        model=props.model.lower(),
        colour_mode=props.colour_mode.lower(),
        colour_space=colour_space or working_space(),
        illuminant=props.illuminant,
        quality=_quality(props),
    )


@contextlib.contextmanager
def _filling():
    global _applying
    _applying += 1
    try:
        yield
    finally:
        _applying -= 1


def applying() -> bool:
    """True while :func:`fill_from_material` is writing properties."""
    return _applying > 0


def mark_custom(props) -> None:
    """The user changed a physical setting by hand: the preset no longer describes it."""
    if not applying() and props.preset != "CUSTOM":
        with _filling():
            props.preset = "CUSTOM"


def _set_index(target, spec, prefix: str, allow_cauchy: bool) -> None:
    """Write an IndexSpec into (prefix)mode/n/k/metal/cauchy properties."""
    if isinstance(spec, dict):
        ((kind, value),) = spec.items()
        if kind == "metal":
            setattr(target, prefix + "mode" if prefix else "index_mode", "METAL")
            setattr(target, prefix + "metal" if prefix else "metal", _enum_id(metals.get_metal(value).name))
            return
        if kind == "cauchy" and allow_cauchy:
            a, b, c = (list(value) + [0.0, 0.0, 0.0])[:3]
            target.index_mode = "CAUCHY"
            target.cauchy_a, target.cauchy_b, target.cauchy_c = a, b, c
            return
        raise ValueError(f"index kind {kind!r} cannot be edited in the panel (use the CLI)")
    n, k = (float(spec), 0.0) if isinstance(spec, (int, float)) else (float(spec[0]), float(spec[1]))
    if prefix:  # substrate
        if k == 0.0:
            target.substrate_mode = "DIELECTRIC"
            target.substrate_ior = n
        else:
            target.substrate_mode = "CUSTOM"
            target.substrate_n, target.substrate_k = n, k
    else:
        target.index_mode = "CONSTANT"
        target.n, target.k = n, k


def fill_from_material(props, material: Material) -> None:
    """Write a Material's physical settings into the extension's properties.

    Film stack, substrate, ambient, roughness, thickness range, diffuse base and model are set;
    the viewing choices (colour mode, illuminant, quality) are left as the user set them.
    """
    with _filling():
        props.layers.clear()
        for layer in material.layers:
            item = props.layers.add()
            _set_index(item, layer.index, "", allow_cauchy=True)
            item.thickness_nm = float(layer.thickness_nm)
        props.active_layer_index = 0
        _set_index(props, material.substrate, "substrate_", allow_cauchy=False)
        props.ambient_ior = float(material.ambient)
        props.roughness = float(material.roughness)
        props.vary_thickness = material.thickness_range_nm is not None
        if material.thickness_range_nm is not None:
            props.thickness_min_nm, props.thickness_max_nm = map(float, material.thickness_range_nm)
        props.diffuse_base = material.base_color is not None
        if material.base_color is not None:
            props.diffuse_color = tuple(material.base_color)
        props.model = material.model.upper()


def apply_preset(props, name: str) -> None:
    """Fill the properties from ``PRESETS[name]`` (lower-case key or enum identifier)."""
    key = name.lower()
    if key not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
    fill_from_material(props, PRESETS[key])
    with _filling():
        props.preset = key.upper()


# ----------------------------------------------------------------------------------------------
# Principled BSDF interop
# ----------------------------------------------------------------------------------------------
def _socket_value(node, name: str, notes: list[str]):
    """An input's own value; a linked input uses its default value and adds a warning."""
    socket = node.inputs[name]
    value = socket.default_value
    value = tuple(value) if hasattr(value, "__len__") else float(value)
    if socket.is_linked:
        shown = f"{value:g}" if isinstance(value, float) else ", ".join(f"{v:.3g}" for v in value[:3])
        notes.append(
            f"'{name}' of '{node.name}' is driven by a link (a texture?): the preview uses its "
            f"unlinked value {shown}"
        )
    return value


def _principled(bpy_material) -> tuple[Material | None, list[str]]:
    node = principled_node(bpy_material)
    if node is None or SOCKET_THICKNESS not in node.inputs:
        return None, []
    notes: list[str] = []
    thickness = _f32(_socket_value(node, SOCKET_THICKNESS, notes))
    if not thickness > 0.0:
        # A zero film is the bare Principled BSDF, which Blender's own viewport already shows.
        return None, []
    film_ior = _f32(_socket_value(node, SOCKET_FILM_IOR, notes))
    roughness = min(1.0, max(0.0, _f32(_socket_value(node, SOCKET_ROUGHNESS, notes))))
    metallic = _f32(_socket_value(node, SOCKET_METALLIC, notes))
    base = tuple(min(1.0, max(0.0, _f32(v))) for v in _socket_value(node, SOCKET_BASE_COLOR, notes)[:3])
    if metallic > 0.5:
        tint = _socket_value(node, SOCKET_SPECULAR_TINT, notes)[:3]
        substrate = conductor_from_rgb(base, tint)
        base_color = None
        if metallic < 1.0:
            notes.append(f"Metallic {metallic:g} is previewed as a pure metal (Metallic 1)")
    else:
        substrate = _f32(_socket_value(node, SOCKET_IOR, notes))
        transmission = _f32(_socket_value(node, SOCKET_TRANSMISSION, notes))
        # An opaque dielectric shows its Base Color as diffuse under the specular layer; a
        # transmissive one (glass, water, a soap bubble) reflects only the film.
        base_color = base if transmission < 0.5 else None
        if metallic > 0.0:
            notes.append(f"Metallic {metallic:g} is previewed as a dielectric (Metallic 0)")
        if 0.0 < transmission < 1.0:
            notes.append(f"Transmission {transmission:g} is previewed as {round(transmission):d}")
    desc = Material(
        layers=(Layer(film_ior, thickness),),
        substrate=substrate,
        ambient=1.0,
        roughness=roughness,
        base_color=base_color,
        colour_mode="per_channel",
        colour_space=working_space(),
        **_CYCLES_PARITY,
    )
    return desc, notes


def description(bpy_material) -> Material | None:
    """What the preview shows for ``bpy_material``, or None if it has no thin film.

    1. The extension's settings (``material.thinfilm_sh``) when enabled.
    2. Otherwise a Principled BSDF with Thin Film Thickness > 0 (the one feeding the output's
       Surface, else the first): film index = Thin Film IOR, thickness = Thin Film Thickness,
       substrate = IOR (dielectric) or, for Metallic > 0.5, a Gulbrandsen (n, k) fit of Base
       Color and Specular Tint; roughness = Roughness; per-channel colour like Cycles; ambient 1.
       Linked sockets use their unlinked values (see :func:`warnings`).
    3. Otherwise None. A zero thickness is not previewed: it is the bare Principled BSDF.

    Raises ValueError (naming the parameter) for invalid settings.
    """
    props = getattr(bpy_material, "thinfilm_sh", None)
    if props is not None and props.enabled:
        try:
            return description_from_props(props)
        except ValueError as exc:
            raise ValueError(f"material {bpy_material.name!r}: {exc}") from None
    return _principled(bpy_material)[0]


def warnings(bpy_material) -> list[str]:
    """What the preview of ``bpy_material`` does not follow (empty when everything is shown)."""
    props = getattr(bpy_material, "thinfilm_sh", None)
    if props is not None and props.enabled:
        notes = []
        if props.vary_thickness and props.thickness_source == "ATTRIBUTE" and not props.thickness_attribute:
            notes.append("thickness source ATTRIBUTE needs an attribute name")
        if props.vary_thickness and props.thickness_source == "IMAGE" and props.thickness_image is None:
            notes.append("thickness source IMAGE needs an image")
    else:
        notes = _principled(bpy_material)[1]
    space = _file_working_space()
    if space and space not in spectra.WORKING_SPACES:
        notes.append(f"working colour space {space!r} is not supported: previewing in Linear Rec.709")
    return notes


# ----------------------------------------------------------------------------------------------
# Tables: memory LRU → disk cache → bake
# ----------------------------------------------------------------------------------------------
def description_key(desc: Material) -> str:
    """Cache key of a description: :func:`precompute.bake.table_key` (parameters + planner version)."""
    return bake.table_key(desc)


def table_cache() -> table_io.TableCache:
    """The on-disk cache in the directory chosen in the add-on preferences (or the default)."""
    from . import cache_dir  # late: this package's __init__ imports this module

    return table_io.TableCache(cache_dir())


def _remember(key: str, result) -> None:
    with _lock:
        _lru[key] = result
        _lru.move_to_end(key)
        while len(_lru) > LRU_SIZE:
            _lru.popitem(last=False)


def peek_table(desc: Material):
    """The table of ``desc`` if it is in memory (never touches the disk, never bakes), else None."""
    key = description_key(desc)
    with _lock:
        result = _lru.get(key)
        if result is not None:
            _lru.move_to_end(key)
        return result


def _attributes(result) -> dict:
    attrs = result.attributes()
    attrs["reasons"] = {k: str(v) for k, v in result.reasons.items()}
    attrs["timings_s"] = {k: float(v) for k, v in result.timings_s.items()}
    attrs["wavelengths_nm"] = [float(w) for w in result.wavelengths_nm]
    return attrs


def _from_table(table) -> bake.BakeResult:
    a = table.attributes
    lo, hi = a["thickness_axis_nm"]
    return bake.BakeResult(
        data=np.array(table.data),
        material=Material.from_dict(a["material"]),
        sh_order=int(a["sh_order"]),
        view_angles_rad=bake.view_angles(int(a["view_samples"])),
        thicknesses_nm=np.linspace(float(lo), float(hi), int(a["thickness_samples"])),
        wavelengths_nm=np.asarray(a["wavelengths_nm"], dtype=float),
        u_nodes=int(a["u_nodes"]),
        reasons=dict(a.get("reasons", {})),
        timings_s=dict(a.get("timings_s", {})),
    )


def get_table_with_source(desc: Material, cache=None, progress=None) -> tuple[bake.BakeResult, str]:
    """Like :func:`get_table`, also saying where the table came from: memory, disk or bake."""
    global bake_count
    key = description_key(desc)
    hit = peek_table(desc)
    if hit is not None:
        return hit, "memory"
    if cache is None:
        cache = table_cache()
    expect = {"material": desc.to_dict()}
    table = None
    try:
        table = cache.load(key, expect=expect, kind=bake.FORMAT_KIND)
    except OSError as exc:
        log.warning("thinfilm_sh: cache %s unreadable (%s); baking", cache.directory, exc)
    if table is not None:
        try:
            result = _from_table(table)
        except (KeyError, TypeError, ValueError) as exc:  # a valid EXR but not one of ours
            log.warning("thinfilm_sh: cached table %s unusable (%s); baking", table.path, exc)
        else:
            _remember(key, result)
            return result, "disk"
    result = bake.bake(desc, progress)
    with _lock:
        bake_count += 1
    try:
        cache.store(key, result.data, _attributes(result), kind=bake.FORMAT_KIND)
    except (OSError, ValueError) as exc:
        log.warning("thinfilm_sh: could not store the table in %s: %s", cache.directory, exc)
    _remember(key, result)
    return result, "bake"


def get_table(desc: Material, cache=None, progress=None) -> bake.BakeResult:
    """The baked table of ``desc``: from memory, else the disk cache, else a fresh bake.

    ``cache`` is a :class:`~precompute.table_io.TableCache` (default: :func:`table_cache`).
    A corrupt disk entry is moved aside by the cache and re-baked. ``progress(fraction, text)``
    is passed to :func:`precompute.bake.bake`; an exception it raises aborts the bake and
    nothing is stored. Thread-safe.
    """
    return get_table_with_source(desc, cache, progress)[0]


def clear_memory_cache() -> None:
    with _lock:
        _lru.clear()


def clear_caches(cache=None) -> int:
    """Empty the in-memory tables and the disk cache; returns how many files were removed."""
    clear_memory_cache()
    return (cache or table_cache()).clear()


_PLAN_ORDER = ("sh_order", "view_samples", "thickness_samples", "wavelength_count", "u_nodes")


def shading_path(roughness: float) -> str:
    """How the viewport and the headless render shade a film of this roughness, for the panel.

    policy.sh_weight: 0 → the split sum alone (prefiltered World × the film's albedo at the
    lobe light's angle), 1 → the SH path alone, between them a blend.
    """
    w = policy.sh_weight(roughness)
    if w <= 0.0:
        return "Shading: split sum (glossy)"
    if w >= 1.0:
        return "Shading: spherical harmonics (rough)"
    return f"Shading: split sum {100 * (1 - w):.0f} % + SH {100 * w:.0f} %"


def format_plan(result, source: str = "bake") -> str:
    """One line per quality choice, "name value: reason", then where the table came from."""
    values = {
        "sh_order": result.sh_order,
        "view_samples": int(result.view_angles_rad.size),
        "thickness_samples": int(result.thicknesses_nm.size),
        "wavelength_count": int(result.wavelengths_nm.size),
        "u_nodes": result.u_nodes,
    }
    lines = [f"{name} {values[name]}: {result.reasons.get(name, '')}".rstrip(": ") for name in _PLAN_ORDER]
    lines.append(f"source {source}")
    return "\n".join(lines)


def parse_plan(text: str) -> dict[str, str]:
    """name → chosen value from :func:`format_plan`'s text (for the panel)."""
    out = {}
    for line in text.splitlines():
        name, _, rest = line.partition(" ")
        out[name] = rest.partition(":")[0].strip()
    return out


# ----------------------------------------------------------------------------------------------
# Write-back to Principled
# ----------------------------------------------------------------------------------------------
def _ensure_principled(bpy_material):
    tree = _tree(bpy_material)
    if tree is None:
        bpy_material.use_nodes = True  # only pre-5.0 materials can lack a tree
        tree = bpy_material.node_tree
    node = principled_node(bpy_material)
    output = _output_node(tree)
    if output is None:
        output = tree.nodes.new("ShaderNodeOutputMaterial")
        output.location = (300.0, 0.0)
    if node is None:
        node = tree.nodes.new("ShaderNodeBsdfPrincipled")
        node.location = (output.location.x - 300.0, output.location.y)
    surface = output.inputs["Surface"]
    if not surface.is_linked:
        tree.links.new(node.outputs["BSDF"], surface)
    return node


def _set_socket(node, name: str, value, notes: list[str]) -> None:
    socket = node.inputs[name]
    socket.default_value = value
    if socket.is_linked:
        notes.append(f"'{name}' is linked in '{node.name}': Cycles uses the link, not the written value")


def write_back_to_principled(bpy_material) -> list[str]:
    """Write the extension's settings into the material's Principled BSDF; returns warnings.

    Creates a Principled BSDF connected to the output if there is none. Thin Film Thickness is
    the top layer's thickness (the middle of the range when it varies), Thin Film IOR the top
    layer's n at 550 nm; a dielectric substrate sets IOR (Transmission 1 unless the diffuse base
    is on, which sets Base Color), a conductor sets Metallic 1 with Base Color = its normal-
    incidence reflectance and Specular Tint = its F82 tint, both integrated from the spectrum.
    Cycles has one film: a multilayer writes only its top layer (with a warning).
    """
    props = bpy_material.thinfilm_sh
    desc = description_from_props(props)
    notes: list[str] = []
    node = _ensure_principled(bpy_material)
    if desc.layers:
        top = desc.layers[0]
        thickness = float(top.thickness_nm)
        if desc.thickness_range_nm is not None:
            lo, hi = desc.thickness_range_nm
            thickness = 0.5 * (lo + hi)
            notes.append(
                f"thickness varies {lo:g}–{hi:g} nm: wrote the middle, {thickness:g} nm "
                "(drive Thin Film Thickness with a texture for the variation)"
            )
        film = _real_index(top.index)
        if film.imag != 0.0 or isinstance(top.index, dict):
            notes.append(f"the film index is written as n = {film.real:.4g} at 550 nm (no k, no dispersion)")
        _set_socket(node, SOCKET_THICKNESS, thickness, notes)
        _set_socket(node, SOCKET_FILM_IOR, max(1.0, film.real), notes)
        if film.real < 1.0:
            notes.append(f"film n {film.real:.4g} < 1 is clamped to 1 by the Principled BSDF")
        if len(desc.layers) > 1:
            notes.append(
                f"the Principled BSDF has a single film: wrote the top layer of {len(desc.layers)}; "
                "Cycles renders will not match the multilayer preview"
            )
    else:
        _set_socket(node, SOCKET_THICKNESS, 0.0, notes)
    substrate = _real_index(desc.substrate)
    conductor = isinstance(desc.substrate, dict) or substrate.imag > 0.0
    if conductor:
        base, tint = metal_rgb(desc.substrate, desc.colour_space)
        _set_socket(node, SOCKET_METALLIC, 1.0, notes)
        _set_socket(node, SOCKET_BASE_COLOR, (*base, 1.0), notes)
        _set_socket(node, SOCKET_SPECULAR_TINT, (*tint, 1.0), notes)
        if desc.base_color is not None:
            notes.append("a metal has no diffuse base in the Principled BSDF: the diffuse colour is dropped")
    else:
        _set_socket(node, SOCKET_METALLIC, 0.0, notes)
        _set_socket(node, SOCKET_IOR, substrate.real, notes)
        _set_socket(node, SOCKET_SPECULAR_TINT, (1.0, 1.0, 1.0, 1.0), notes)
        if desc.base_color is not None:
            _set_socket(node, SOCKET_BASE_COLOR, (*desc.base_color, 1.0), notes)
            _set_socket(node, SOCKET_TRANSMISSION, 0.0, notes)
        else:
            _set_socket(node, SOCKET_TRANSMISSION, 1.0, notes)
    _set_socket(node, SOCKET_ROUGHNESS, float(desc.roughness), notes)
    if desc.ambient != 1.0:
        notes.append(f"ambient index {desc.ambient:g} has no Principled equivalent (Cycles assumes 1)")
    if desc.model != "exact":
        notes.append(f"model {desc.model!r} is previewed; Cycles always uses its exact film model")
    return notes


# ----------------------------------------------------------------------------------------------
# Thickness over the surface
# ----------------------------------------------------------------------------------------------
def corner_order(mesh) -> np.ndarray:
    """Corner (loop) indices of the mesh's loop triangles, flattened: shape (3·triangles,).

    ``thickness_per_vertex(...)[corner_order(mesh)]`` gives one value per triangle corner in
    the order of ``mesh.loop_triangles``.
    """
    mesh.calc_loop_triangles()
    loops = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    return loops


def _corner_vertices(mesh) -> np.ndarray:
    out = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", out)
    return out


def _corner_faces(mesh) -> np.ndarray:
    totals = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", totals)
    # Blender stores each face's corners contiguously, faces in order (face offsets).
    return np.repeat(np.arange(len(totals), dtype=np.int32), totals)


_NUMERIC_ATTRIBUTES = {"FLOAT": np.float32, "INT": np.int32, "INT8": np.int8, "BOOLEAN": bool}


def _attribute_values(obj, mesh, name: str) -> np.ndarray:
    where = f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"
    if not name:
        raise ValueError(f"{where}: thickness source ATTRIBUTE needs an attribute name")
    attribute = mesh.attributes.get(name)
    if attribute is None:
        found = sorted(a.name for a in mesh.attributes if a.data_type in _NUMERIC_ATTRIBUTES)
        found = [n for n in found if not n.startswith(".")]
        raise ValueError(
            f"{where}: mesh {mesh.name!r} has no attribute {name!r} for the film thickness "
            f"(float attributes on points or corners; this mesh has {found or 'none'})"
        )
    if attribute.data_type not in _NUMERIC_ATTRIBUTES:
        raise ValueError(
            f"{where}: attribute {name!r} holds {attribute.data_type}; the thickness needs a FLOAT attribute"
        )
    values = np.empty(len(attribute.data), dtype=_NUMERIC_ATTRIBUTES[attribute.data_type])
    attribute.data.foreach_get("value", values)
    values = values.astype(np.float64)
    if attribute.domain == "POINT":
        return values[_corner_vertices(mesh)]
    if attribute.domain == "CORNER":
        return values
    if attribute.domain == "FACE":
        return values[_corner_faces(mesh)]
    raise ValueError(
        f"{where}: attribute {name!r} is on the {attribute.domain} domain; "
        "use a point, corner or face attribute"
    )


def _hash01(ix, iy, iz, seed: int) -> np.ndarray:
    """Integer lattice point → uniform value in [0, 1), deterministic on every platform.

    Coordinates are mixed with large odd constants and finished with MurmurHash3's fmix32
    (Appleby 2011), all in wrapping uint32 arithmetic.
    """

    def u32(a):
        return (np.asarray(a, dtype=np.int64) & 0xFFFFFFFF).astype(np.uint32)

    h = u32(ix) * np.uint32(0x8DA6B343)
    h ^= u32(iy) * np.uint32(0xD8163841)
    h ^= u32(iz) * np.uint32(0xCB1AB31F)
    h ^= np.uint32((int(seed) * 0x9E3779B9) & 0xFFFFFFFF)
    h ^= h >> np.uint32(16)
    h *= np.uint32(0x85EBCA6B)
    h ^= h >> np.uint32(13)
    h *= np.uint32(0xC2B2AE35)
    h ^= h >> np.uint32(16)
    return h.astype(np.float64) / 4294967296.0


def value_noise(points, scale: float = 1.0, seed: int = 0, octaves: int = 3) -> np.ndarray:
    """Fractal 3-D value noise in [0, 1] at ``points`` (N, 3).

    Each octave hashes the integer lattice around p·scale·2^o, blends the eight corner values
    with the quintic fade 6t⁵ − 15t⁴ + 10t³ (Perlin 2002) and is weighted 2^−o; the sum is
    divided by the total weight, so the result stays in [0, 1].
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3) * float(scale)
    total = np.zeros(p.shape[0])
    weight = 0.0
    with np.errstate(over="ignore"):
        for octave in range(octaves):
            q = p * (2.0**octave) + 17.0 * octave
            cell = np.floor(q)
            f = q - cell
            w = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
            cell = cell.astype(np.int64)
            value = np.zeros(p.shape[0])
            for dx in (0, 1):
                for dy in (0, 1):
                    for dz in (0, 1):
                        corner = _hash01(cell[:, 0] + dx, cell[:, 1] + dy, cell[:, 2] + dz, seed + octave)
                        wx = w[:, 0] if dx else 1.0 - w[:, 0]
                        wy = w[:, 1] if dy else 1.0 - w[:, 1]
                        wz = w[:, 2] if dz else 1.0 - w[:, 2]
                        value += wx * wy * wz * corner
            amplitude = 0.5**octave
            total += amplitude * value
            weight += amplitude
    return np.clip(total / weight, 0.0, 1.0)


def _image_values(obj, mesh, image, uv_map: str) -> np.ndarray:
    where = f"object {obj.name!r}" if obj is not None else f"mesh {mesh.name!r}"
    if image is None:
        raise ValueError(f"{where}: thickness source IMAGE needs an image")
    width, height = int(image.size[0]), int(image.size[1])
    channels = int(image.channels)
    if width * height == 0 or channels == 0:
        raise ValueError(f"{where}: image {image.name!r} has no pixels (is its file missing?)")
    layer = mesh.uv_layers.get(uv_map) if uv_map else None
    if uv_map and layer is None:
        raise ValueError(
            f"{where}: mesh {mesh.name!r} has no UV map {uv_map!r} "
            f"(it has {[uv.name for uv in mesh.uv_layers] or 'none'})"
        )
    if layer is None:
        layer = next((uv for uv in mesh.uv_layers if uv.active_render), None) or mesh.uv_layers.active
    if layer is None:
        raise ValueError(f"{where}: mesh {mesh.name!r} has no UV map for the thickness image")
    uv = np.empty(2 * len(mesh.loops), dtype=np.float32)
    layer.data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2).astype(np.float64)
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    first = pixels.reshape(height, width, channels)[:, :, 0].astype(np.float64)  # row 0 = bottom
    # Bilinear between pixel centres ((i + ½)/W, (j + ½)/H), repeating like Image Texture's default.
    x = uv[:, 0] * width - 0.5
    y = uv[:, 1] * height - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0 = x0.astype(np.int64) % width
    y0 = y0.astype(np.int64) % height
    x1, y1 = (x0 + 1) % width, (y0 + 1) % height
    return (
        first[y0, x0] * (1 - fx) * (1 - fy)
        + first[y0, x1] * fx * (1 - fy)
        + first[y1, x0] * (1 - fx) * fy
        + first[y1, x1] * fx * fy
    )


def thickness_per_vertex(obj, mesh, props) -> np.ndarray | None:
    """Per-corner (loop) thickness parameter in [0, 1], or None when the thickness is constant.

    The top layer's thickness at a corner is min + value·(max − min). Sources:

    - ATTRIBUTE: the float attribute ``props.thickness_attribute`` on points, corners or faces
      (values clipped to [0, 1]); a missing attribute raises ValueError naming it.
    - NOISE: :func:`value_noise` of the object-space vertex positions, ``noise_scale`` and
      ``noise_seed``; deterministic.
    - IMAGE: the first channel of ``props.thickness_image`` at the corners' UVs (UV map
      ``props.thickness_uv_map``, empty = the active render map), bilinear, repeating, raw pixel
      values (use Non-Color images).

    Index the result with :func:`corner_order` for loop-triangle corners.
    """
    if not props.vary_thickness:
        return None
    source = props.thickness_source
    if source == "ATTRIBUTE":
        values = _attribute_values(obj, mesh, props.thickness_attribute)
    elif source == "NOISE":
        co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        per_vertex = value_noise(co.reshape(-1, 3), props.noise_scale, props.noise_seed)
        values = per_vertex[_corner_vertices(mesh)]
    elif source == "IMAGE":
        values = _image_values(obj, mesh, props.thickness_image, props.thickness_uv_map)
    else:
        raise ValueError(f"unknown thickness source {source!r}")
    values = np.nan_to_num(np.asarray(values, dtype=np.float64), nan=0.0)
    return np.clip(values, 0.0, 1.0)
