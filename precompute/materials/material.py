"""Validated, hashable description of an iridescent material, and the presets.

A :class:`Material` is plain data (JSON-serialisable through :meth:`Material.to_dict`), so the
same description drives the CLI, the Blender add-on, the cache key and the EXR header.

Index specifications (``IndexSpec``) accepted everywhere a medium is named:

- a number ``1.33`` or ``[n, k]`` → constant N = n + ik;
- ``{"cauchy": [A, B, C]}`` (λ in µm), ``{"sellmeier": {"B": [...], "C": [...]}}``;
- ``{"metal": "gold"}`` → tabulated conductor from :mod:`precompute.optics.metals`;
- ``{"table": {"wavelengths_nm": [...], "n": [...], "k": [...]}}``;
- ``{"f82_tint": {"f0": [r, g, b], "tint": [r, g, b]}}`` → Blender's metallic Principled BSDF
  (Base Color, Specular Tint): a per-channel conductor (see ``_f82_tint_index``).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace

from .. import _checks
from ..colour import rgb_spaces, spectra
from ..optics import metals
from ..optics.dispersion import CauchyIndex, ConstantIndex, SellmeierIndex, TabulatedIndex
from ..optics.gulbrandsen2014 import conductor_from_rgb
from . import validate

AUTO = "auto"
MODELS = ("exact", "glassner2000")
COLOUR_MODES = ("spectral", "per_channel")
#: Energy lost to single scattering in rough microfacets: "none"; "film" — Kulla & Conty with the
#: film's own lobe-average reflectance per channel (physical, the default for our materials);
#: "cycles" — the film-free dielectric F_avg, as Cycles' Multiscatter GGX does for a Principled
#: thin film (for interop parity).
MULTISCATTER = ("none", "film", "cycles")
#: Highest SH order of a table or the World: the one constant behind effects.MAX_ORDER and the
#: shaders' addon/gpu/resources.py MAX_L (the lighting UBO has room for exactly this many bands).
MAX_SH_ORDER = 12


def _index_model(name: str, spec):
    """Turn an IndexSpec into a dispersion model, raising ValueError naming ``name``.

    Every value is checked (:mod:`.validate`): finite numbers, and a dispersive index gives
    0 < n ≤ 1000 and 0 ≤ k ≤ 1000 at every wavelength of 360–830 nm. Specs found valid are
    remembered, so building the same description again costs no evaluation.
    """
    if validate.is_real(spec):
        return ConstantIndex(*validate.constant_index(name, spec))
    if isinstance(spec, (list, tuple)) and len(spec) == 2 and all(validate.is_real(v) for v in spec):
        return ConstantIndex(*validate.constant_index(name, spec[0], spec[1]))
    if isinstance(spec, bool):
        raise ValueError(f"{name} must be an index, got {spec!r}")
    key = validate.spec_key(spec)
    known = validate.known_valid(key)
    if isinstance(spec, dict) and len(spec) == 1:
        ((kind, value),) = spec.items()
        if kind == "cauchy":
            model = CauchyIndex(*map(float, value if known else validate.cauchy_coefficients(name, value)))
        elif kind == "sellmeier":
            b, c = (value["B"], value["C"]) if known else validate.sellmeier_coefficients(name, value)
            model = SellmeierIndex(tuple(map(float, b)), tuple(map(float, c)))
        elif kind == "metal":
            if not isinstance(value, str):
                raise ValueError(f"{name}: a metal is named by a string, got {value!r}")
            try:
                model = metals.get_metal(value)
            except ValueError as exc:
                raise ValueError(f"{name}: {exc}") from None
        elif kind == "table":
            wl, n, k = (
                (value["wavelengths_nm"], value["n"], value.get("k", [0.0] * len(value["n"])))
                if known
                else validate.table_columns(name, value)
            )
            model = TabulatedIndex(
                tuple(map(float, wl)), tuple(map(float, n)), tuple(map(float, k)), name=name
            )
        elif kind == "f82_tint":
            model = _f82_tint_index(name, value)
        else:
            raise ValueError(
                f"{name}: unknown index kind {kind!r} (use cauchy, sellmeier, metal, table or f82_tint)"
            )
    else:
        raise ValueError(f"{name} must be n, [n, k] or a dict such as {{'metal': 'gold'}}, got {spec!r}")
    validate.remember_valid(key)
    return model


def _f82_tint_index(name: str, value):
    """Blender's metallic Principled BSDF, ``{"f0": Base Color, "tint": Specular Tint}`` (RGB in
    [0, 1]): spectrally a Gulbrandsen (n, k) fit per channel (optics.gulbrandsen2014);
    the Cycles-matching colour mode evaluates the F82-tint model itself (film_channels)."""
    if not isinstance(value, dict) or set(value) - {"f0", "tint"} or "f0" not in value:
        raise ValueError(f"{name}: f82_tint needs {{'f0': [r, g, b], 'tint': [r, g, b]}}, got {value!r}")
    rgb = {key: value.get(key, (1.0, 1.0, 1.0)) for key in ("f0", "tint")}
    for key, v in rgb.items():
        if (
            not isinstance(v, (list, tuple))
            or len(v) != 3
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) and 0 <= c <= 1 for c in v)
        ):
            raise ValueError(f"{name}: f82_tint {key} must be three values in [0, 1], got {v!r}")
    return _index_model(name, conductor_from_rgb(rgb["f0"], rgb["tint"]))


@dataclass(frozen=True)
class Layer:
    """One film layer: an index specification and a thickness in nm."""

    index: object
    thickness_nm: float


@dataclass(frozen=True)
class Quality:
    """Resolution choices; each is ``"auto"`` or a number."""

    sh_order: object = AUTO
    view_samples: object = AUTO
    thickness_samples: object = AUTO
    wavelength_count: object = AUTO


@dataclass(frozen=True)
class Material:
    """An iridescent material: film stack on a substrate under a GGX microfacet surface.

    Parameters mirror Cycles' Principled BSDF thin film where they overlap: ``roughness`` is
    Blender's (α = roughness²), thicknesses in nm, film and substrate indices.

    ``thickness_range_nm`` makes the TOP layer's thickness vary over the surface between the
    two values (a texture or attribute picks it per pixel); the table then gains a thickness axis.
    """

    layers: tuple = (Layer(1.33, 400.0),)
    substrate: object = 1.0
    ambient: float = 1.0
    roughness: float = 0.3
    thickness_range_nm: tuple | None = None
    base_color: tuple | None = None
    model: str = "exact"
    colour_mode: str = "spectral"
    colour_space: str = "Linear Rec.709"
    illuminant: str = "E"
    multiscatter: str = "film"
    quality: Quality = field(default_factory=Quality)

    def __post_init__(self):
        if isinstance(self.layers, (str, bytes, dict)) or not hasattr(self.layers, "__iter__"):
            raise ValueError(f"layers must be a list of layers, got {self.layers!r}")
        layers = []
        for i, l in enumerate(self.layers):
            if i >= validate.MAX_LAYERS:
                raise ValueError(
                    f"layers: at most {validate.MAX_LAYERS} layers (the bake's cost grows with each), "
                    f"got more"
                )
            try:
                layers.append(l if isinstance(l, Layer) else Layer(**l) if isinstance(l, dict) else Layer(*l))
            except TypeError:
                raise ValueError(f"layers[{i}] must be (index, thickness_nm), got {l!r}") from None
        object.__setattr__(self, "layers", tuple(layers))
        if not isinstance(self.quality, Quality):
            try:
                object.__setattr__(self, "quality", Quality(**dict(self.quality)))
            except (TypeError, ValueError):
                raise ValueError(
                    f"quality must be a Quality or a dict of its fields, got {self.quality!r}"
                ) from None
        self.validate()

    # ----------------------------------------------------------------------------------------
    def validate(self) -> None:
        """Raise ValueError naming the first invalid parameter.

        Every value is checked, with the limits of :mod:`.validate` and their reasons: indices
        finite with 0 < n ≤ 1000 and 0 ≤ k ≤ 1000 over 360–830 nm, thicknesses finite in
        [0, 100 µm], at most 128 layers, roughness and the diffuse colour in [0, 1].
        """
        validate.real("ambient", self.ambient, 1.0, validate.MAX_INDEX_N, why="air 1.0, water 1.33")
        if len(self.layers) > validate.MAX_LAYERS:
            raise ValueError(f"layers: at most {validate.MAX_LAYERS} layers, got {len(self.layers)}")
        for i, layer in enumerate(self.layers):
            _index_model(f"layers[{i}].index", layer.index)
            validate.real(
                f"layers[{i}].thickness_nm",
                layer.thickness_nm,
                0.0,
                validate.MAX_THICKNESS_NM,
                why="100 µm is Blender's Thin Film Thickness maximum",
            )
        _index_model("substrate", self.substrate)
        validate.real("roughness", self.roughness, 0.0, 1.0)
        self._validate_range()
        self._validate_base_color()
        _checks.choice("model", self.model, MODELS)
        _checks.choice("colour_mode", self.colour_mode, COLOUR_MODES)
        _checks.choice("multiscatter", self.multiscatter, MULTISCATTER)
        if self.model == "glassner2000" and len(self.layers) != 1:
            raise ValueError(
                "model 'glassner2000' is the paper's single-film approximation: use exactly one layer"
            )
        self._validate_quality()
        for name in ("colour_space", "illuminant"):
            if not isinstance(getattr(self, name), str):
                raise ValueError(f"{name} must be a name, got {getattr(self, name)!r}")
        rgb_spaces.xyz_to_rgb_matrix(self.colour_space)  # raises for unknown spaces
        spectra.illuminant_spd(self.illuminant, [560.0])

    def _validate_range(self) -> None:
        """The thickness range: two finite values 0 ≤ min < max ≤ 100 µm, with a film layer."""
        if self.thickness_range_nm is None:
            return
        if not self.layers:
            raise ValueError("thickness_range_nm needs at least one film layer")
        rng = self.thickness_range_nm
        if isinstance(rng, (str, bytes, dict)) or not hasattr(rng, "__len__") or len(rng) != 2:
            raise ValueError(f"thickness_range_nm must be (min, max) finite numbers, got {rng!r}")
        lo = validate.real("thickness_range_nm min", rng[0], 0.0, validate.MAX_THICKNESS_NM)
        hi = validate.real("thickness_range_nm max", rng[1], 0.0, validate.MAX_THICKNESS_NM)
        if not lo < hi:
            raise ValueError(f"thickness_range_nm needs 0 ≤ min < max, got {tuple(rng)!r}")

    def _validate_base_color(self) -> None:
        """The diffuse base colour: None, or three values in [0, 1]."""
        if self.base_color is None:
            return
        c = self.base_color
        if isinstance(c, (str, bytes, dict)) or not hasattr(c, "__len__") or len(c) != 3:
            raise ValueError(f"base_color must be three values in [0, 1], got {c!r}")
        for channel, v in zip("RGB", c, strict=True):
            validate.real(f"base_color {channel}", v, 0.0, 1.0)

    def _validate_quality(self) -> None:
        """Each quality field: "auto" or an int within its bounds."""
        q = self.quality
        for name, lo, hi in (
            ("sh_order", 0, MAX_SH_ORDER),
            ("view_samples", 2, 512),
            ("thickness_samples", 2, 512),
            ("wavelength_count", 3, 8192),
        ):
            v = getattr(q, name)
            if not (isinstance(v, str) and v == AUTO):
                _checks.positive_int(f"quality.{name}", v, minimum=lo, maximum=hi)

    # ----------------------------------------------------------------------------------------
    def indices(self) -> list:
        """Dispersion models from ambient to substrate."""
        return (
            [ConstantIndex(float(self.ambient))]
            + [_index_model(f"layers[{i}].index", l.index) for i, l in enumerate(self.layers)]
            + [_index_model("substrate", self.substrate)]
        )

    def thicknesses(self) -> list[float]:
        """Thickness of each layer in nm, top first."""
        return [float(l.thickness_nm) for l in self.layers]

    @property
    def varies(self) -> bool:
        """True when the top layer's thickness varies over the surface (a range is set)."""
        return self.thickness_range_nm is not None

    def to_dict(self) -> dict:
        """The material as plain JSON types (the cache key and the EXR header use it)."""
        d = asdict(self)
        d["layers"] = [asdict(l) for l in self.layers]
        return json.loads(json.dumps(d))  # tuples → lists, canonical JSON types

    @classmethod
    def from_dict(cls, data: dict) -> Material:
        """Material from `to_dict` output; unknown keys are an error."""
        data = dict(data)
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown material parameters: {sorted(unknown)}")
        for key in ("thickness_range_nm", "base_color"):  # JSON lists back to tuples
            if isinstance(data.get(key), list):
                data[key] = tuple(data[key])
        return cls(**data)  # __post_init__ turns layer rows and a quality dict into their types

    def with_(self, **changes) -> Material:
        """A copy with *changes* applied (dataclasses.replace)."""
        return replace(self, **changes)


def _beetle_layers(pairs: int = 8) -> tuple:
    # Chitin (n ≈ 1.56) / melanised chitin (n ≈ 1.68 + 0.05i) reflectors, after Stavenga et al.
    # (2011), J. R. Soc. Interface 8, 1246 ("Coloration principles of nymphaline butterflies"),
    # and Kinoshita (2008), *Structural Colors in the Realm of Nature*, ch. 5.
    return tuple(
        Layer(1.56 if i % 2 == 0 else [1.68, 0.05], 95.0 if i % 2 == 0 else 80.0) for i in range(2 * pairs)
    )


#: Named presets; each value documents where its numbers come from.
PRESETS: dict[str, Material] = {
    # Water film in air; soap lowers the surface tension, not the index (n ≈ 1.33).
    "soap_film": Material(
        layers=(Layer(1.33, 500.0),), substrate=1.0, roughness=0.05, thickness_range_nm=(0.0, 1000.0)
    ),
    # Mineral oil (n ≈ 1.47) on water (1.33); slicks are 0.1–1 µm thick.
    "oil_on_water": Material(
        layers=(Layer(1.47, 300.0),), substrate=1.33, roughness=0.1, thickness_range_nm=(100.0, 800.0)
    ),
    # Anodic TiO₂ (n ≈ 2.4–2.7 across the visible; Cauchy fit to anatase, DeVore 1951 JOSA 41, 416)
    # on titanium (Johnson & Christy 1974). 20–150 nm oxide gives gold → purple → blue → green.
    "anodised_titanium": Material(
        layers=(Layer({"cauchy": [2.30, 0.045, 0.0]}, 75.0),),
        substrate={"metal": "titanium"},
        roughness=0.25,
        thickness_range_nm=(20.0, 150.0),
    ),
    # Heat tint: an iron-oxide layer (Fe₃O₄/Fe₂O₃, n ≈ 2.6 + 0.3i) on iron; 20–100 nm gives
    # straw → bronze → purple → blue as temperature rises.
    "heat_tinted_steel": Material(
        layers=(Layer([2.6, 0.3], 60.0),),
        substrate={"metal": "iron"},
        roughness=0.3,
        thickness_range_nm=(20.0, 100.0),
    ),
    "beetle_multilayer": Material(layers=_beetle_layers(), substrate=1.56, roughness=0.35),
    # The paper's coated car window: a ~quarter-wave MgF₂ (1.38) coating on glass (1.52).
    "coated_car_window": Material(
        layers=(Layer(1.38, 140.0),), substrate=1.52, roughness=0.15, thickness_range_nm=(100.0, 300.0)
    ),
}


#: What a material that cannot be evaluated is drawn as, so it is seen and not mistaken for a film
#: (docs/hostile-input.md): matte magenta, a diffuse base (1, 0, 1) under no film on a substrate
#: that matches the ambient (no specular reflection at all), lit by the World like every film.
#: SH order 2 holds a Lambertian lobe (≥ 99 % of its irradiance) and the surface looks the same
#: from every angle, so two view samples suffice: it bakes in ~10 ms.
FALLBACK = Material(
    layers=(),
    substrate=1.0,
    roughness=1.0,
    base_color=(1.0, 0.0, 1.0),
    quality=Quality(sh_order=2, view_samples=2),
)


def preset(name: str) -> Material:
    """A preset by name; ValueError listing the names if unknown."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
    return PRESETS[name]
