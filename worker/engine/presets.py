"""Named, versioned parameter sets of the method.

Every number the descriptor depends on lives here, so a stored descriptor can say
exactly what made it (``name`` and ``version``); a change of any field that alters
descriptors must bump ``version``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Literal

Dissimilarity = Literal["D1", "D2"]
#: How one modality's flat vectors are compared: eq. (8), eq. (9), or ShapeDNA's
#: reweighted Euclidean distance (the spectrum only; Reuter et al. 2006, lapy's
#: ``reweight_ev``: eigenvalue ``i`` divided by ``i``, then the Euclidean distance).
Comparison = Literal["D1", "D2", "reweighted euclidean"]
REWEIGHTED: Comparison = "reweighted euclidean"
#: Each comparison, and the modalities it may compare.
COMPARISONS: dict[Comparison, tuple[str, ...]] = {
    "D1": ("gdm", "ddt", "spectrum"),
    "D2": ("gdm", "ddt", "spectrum"),
    REWEIGHTED: ("spectrum",),
}
Fusion = Literal["sum", "product"]
Measure = Literal["vertices", "surface"]
DdtElements = Literal["core", "diagonal", "slice_values"]
MassMatrix = Literal["lumped", "averaged"]
Units = Literal["any", "metric"]
#: What a collection's files' units are: "any", arbitrary (a file and the same file
#: rescaled are the same shape); "metric", calibrated (millimetres, metres: a scanner's),
#: so that a shape's size tells shapes apart.
UNITS: tuple[Units, ...] = ("any", "metric")
#: The modalities that are one flat vector per shape (eqs. 8 and 9 compare them): the
#: shape's, every one of them blind to scale.
MODALITIES = ("gdm", "ddt", "spectrum")
#: The modality of local profiles that compares a part with a whole (:mod:`.parts`).
PARTS = "parts"
#: The size modality: the flat vector ``[sqrt(A)]`` of the described surface's area ``A``
#: in the file's own units (:meth:`~worker.engine.descriptor.ShapeDescriptor.vector`),
#: scored only in a collection of metric units (:attr:`Preset.scored_modalities`) and
#: compared by :func:`worker.engine.compare.size_dissimilarity`.
SIZE = "size"


@dataclass(frozen=True)
class Preset:
    """Parameters of the GDM/DDT modal representation (Smeets et al. 2010).

    Attributes
    ----------
    name, version : preset identity recorded with every descriptor.
    n_vertices : resampling target (sec. 4.2: 2,500 for SHREC).
    max_edge : if given, the resampled mesh's edges are split at their midpoints
        until none is longer than this many edges of an equilateral tiling of the
        surface by ``n_vertices`` vertices (:func:`worker.engine.resample.resample_mesh`,
        which takes the vertices this adds out of the decimation's): decimation leaves
        flat and ruled parts (a CAD file's strips) one element long, which the operators
        cannot resolve. None: the decimated mesh as it is.
    gdm_singular_values : k largest singular values of the GDM kept (sec. 4.2: 19).
    ddt_core_shape : HOSVD core size of the DDT (sec. 4.2: 20 x 20 x 5).
    diffusion_times : t_D of eq. (4) (sec. 4.2: 100, 200, 400, 800, 1500).
    n_eigenpairs : eigenpairs of L phi = lambda A phi kept in eq. (4) (its ``k``);
        for the paper's presets chosen so that truncation changes the DDT by < 1e-3
        (relative Frobenius) at t_D = 100.
    spectrum_size : non-zero Laplace-Beltrami eigenvalues in the spectrum modality.
    spectrum_mass : the mass matrix of the spectrum modality's eigenvalues: "lumped",
        eq. (3)'s diagonal ``A``; or "averaged", the mean of the lumped and the
        consistent mass, whose eigenvalues depend far less on the triangulation
        (:func:`worker.engine.diffusion.averaged_mass_eigenpairs`).
    ddt_mass : the same choice for the eigenpairs of eq. (4) in the DDT (the surface
        measure only): "lumped", eq. (3)'s ``A``; or "averaged", the averaged mass's
        Ritz pairs, as the spectrum's.
    heat_time_factor : heat-method time step in units of the squared mean edge length.
    gdm_samples : with the "surface" measure, geodesic distances from this many
        samples spread over the surface (farthest-point sampling) instead of from
        every vertex; the GDM's singular values are then those of the same surface
        operator integrated over the samples' Voronoi cells
        (:func:`worker.engine.modal.modal_gdm`). None: every vertex.
    max_hole_perimeter : close every boundary loop shorter than this many square
        roots of the surface's area before resampling (a gap of at most
        ``max_hole_perimeter^2 / (4 pi)`` of the area;
        :func:`worker.engine.holes.close_small_holes`). None: describe the surface
        with its holes, as the paper does.
    two_sided_views : a surface facing one way (a single view of its object,
        :data:`worker.engine.descriptor.ONE_VIEW_FACING`) is resampled to half of
        ``n_vertices`` and glued to its own image along its boundary
        (:func:`worker.engine.holes.two_sided`) before it is described, its unseen side
        taken as the mirror of the side it shows; False: described as it is.
    smooth_noise : any other surface rough with a scanner's noise is smoothed before it
        is described (:func:`worker.engine.denoise.denoised`); False: described as it
        is, as the paper does.
    measure : "vertices", the paper's GDM and DDT as matrices over the vertex set
        (slices divided by their sums); or "surface", both weighted by the lumped
        vertex areas so their modal representations approximate the surface's
        integral operators whatever the triangulation, the GDM's divided by
        ``A^(3/2)`` and the DDT's diffusion times in units of ``A / (15 n_vertices)``
        (the paper's unit for a closed mesh of ``n_vertices`` vertices) instead of
        the resampled mesh's mean triangle area, the heat time in edge lengths of the
        surface rather than of the mesh (see :mod:`worker.engine.modal` and
        :func:`worker.engine.geodesic.heat_time`).
    ddt_elements : "core", the whole HOSVD core (the paper); or "diagonal", its
        elements ``S[i, i, k]``. Weighted by area, the slices nearly share their
        eigenfunctions, so the HOSVD nearly diagonalizes them and most off-diagonal
        elements are rounding-level numbers whose relative differences (eq. 8) are
        noise; or "slice_values", no HOSVD: the ``min(r1, r2)`` largest singular
        values of each diffusion time's slice, as the GDM's (the numbers the diagonal
        tends to, without its swaps between nearly equal modes;
        :func:`worker.engine.modal.slice_singular_values`; needs ``ddt_mix_times``
        False, the core's third size the number of times).
    ddt_mix_times : True, the DDT's whole HOSVD (the paper), whose third factor
        turns the core's slices into combinations of the diffusion times; False, only
        the two vertex modes are decomposed (the ones eq. 5 permutes), so slice ``k``
        of the core is time ``t_k``'s own (:func:`worker.engine.modal.vertex_modes_core`;
        the core's third size must then be the number of times).
    parts_first_radius : the parts modality's smallest radius, in units of the square
        root of the surface's area (:mod:`worker.engine.parts`); None: no parts modality.
        Its radii grow by ``2^(1/4)``, from the GDM's samples (needs ``gdm_samples``).
    parts_radii : radii compared per sample.
    parts_scales : the query scales span ``parts_scales - 1`` steps of the profiles' grid
        (up to ``2^(5/8) = 1.54`` at 6: a part down to 42% of its whole's area).
    parts_extra_scales : steps of the grid past those that a query is also tried at (2
        more: up to ``2^(7/8) = 1.83``, a part down to 30%); there a sample's largest
        radii fall past the profiles' last column and are left out, as those past its
        reach are.
    parts_scale_steps : query scales per step of the grid, ``2^(j/8p)`` (between two of
        its columns the profiles are interpolated).
    parts_scale_prior : ``lambda`` of the prior ``lambda log s`` against shrinking a whole.
    parts_min_radii : a query sample with fewer radii clear of its boundary is left out.
    parts_centroid_radii : the first radii compared that also compare the discs'
        centroids (:func:`worker.engine.parts.ball_centroid_profiles`); 0: areas only.
    parts_centroid_weight : the centroid profiles' weight beside the areas' (``w``: each
        difference of a centroid profile counts as ``w`` times one of an area profile).
    partial_loop : the query's longest open boundary loop (in square roots of its area)
        from which it starts to look partial, and at which it looks wholly so
        (:func:`worker.engine.compare.partiality`).
    normalize_scale : True, every descriptor is scale-free (the GDM's and the DDT's
        slices divided by their sums, sec. 4.2, or the surface measure's area units);
        False, sec. 4.1's TOSCA protocol ("because the objects have already the same
        scale, no surface preprocessing is needed"): the GDM's singular values in the
        file's length unit, the DDT as eq. (4) gives it (the paper's ``A`` and time unit
        make it scale-free by themselves). The "vertices" measure only.
    dissimilarity : D1 (eq. 8) or D2 (eq. 9), every modality's comparison unless
        ``comparisons`` names another.
    comparisons : modality -> its own comparison (:data:`COMPARISONS`), e.g. a fusion
        learned on a collection (:func:`with_fusion`). Empty: ``dissimilarity`` for all.
    fusion : sum or product rule over ``fused_modalities``.
    fused_modalities : modalities combined into the final score of a whole query.
    units : the collection's units (:data:`UNITS`): "any", the score is the fused
        modalities' (every descriptor scale-free); "metric", the size modality
        (:data:`SIZE`) is fused with them, at ``fusion_weights["size"]``. Only how
        descriptors are compared: the same descriptors serve both.
    fusion_weights : exponent (product) or factor (sum) per fused modality, and the
        size's (key :data:`SIZE`), used when ``units`` is "metric".
    size_tolerance : the floor of the size's comparison
        (:func:`~worker.engine.compare.size_dissimilarity`): eq. (8)'s D1 of two sizes,
        about their relative difference, is raised to it, so that sizes closer than this
        are told apart by the shape alone (a body's size moves by a few percent with its
        pose and its scan). Chosen with the size's weight by cross-validation
        (docs/decisions.md).
    partial_weights : the exponents (product rule) of a query that looks wholly partial;
        a query part way is weighed in between (:func:`worker.engine.compare.query_weights`).
        Empty: every query is weighed as a whole.
    """

    name: str
    version: int
    n_vertices: int = 2500
    max_edge: float | None = None
    gdm_singular_values: int = 19
    ddt_core_shape: tuple[int, int, int] = (20, 20, 5)
    diffusion_times: tuple[float, ...] = (100.0, 200.0, 400.0, 800.0, 1500.0)
    n_eigenpairs: int = 150
    spectrum_size: int = 50
    spectrum_mass: MassMatrix = "lumped"
    ddt_mass: MassMatrix = "lumped"
    heat_time_factor: float = 1.0
    gdm_samples: int | None = None
    max_hole_perimeter: float | None = None
    two_sided_views: bool = False
    smooth_noise: bool = False
    measure: Measure = "vertices"
    ddt_elements: DdtElements = "core"
    ddt_mix_times: bool = True
    parts_first_radius: float | None = None
    parts_radii: int = 15
    parts_scales: int = 6
    parts_extra_scales: int = 0
    parts_scale_steps: int = 1
    parts_scale_prior: float = 0.02
    parts_min_radii: int = 3
    parts_centroid_radii: int = 0
    parts_centroid_weight: float = 0.0
    partial_loop: tuple[float, float] = (0.1, 0.3)
    normalize_scale: bool = True
    dissimilarity: Dissimilarity = "D2"
    comparisons: dict[str, Comparison] = field(default_factory=dict)
    fusion: Fusion = "product"
    fused_modalities: tuple[str, ...] = ("gdm", "ddt")
    units: Units = "any"
    fusion_weights: dict[str, float] = field(default_factory=dict)
    size_tolerance: float = 0.02
    partial_weights: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.ddt_core_shape[2] > len(self.diffusion_times):
            raise ValueError("the DDT core cannot have more slices than diffusion times")
        if not self.ddt_mix_times and self.ddt_core_shape[2] != len(self.diffusion_times):
            raise ValueError("without mixing the times, the DDT core has one slice per time")
        if self.ddt_elements == "slice_values" and self.ddt_mix_times:
            raise ValueError("the DDT's slice values are each time's own: ddt_mix_times=False")
        if self.ddt_mass == "averaged" and self.measure != "surface":
            raise ValueError("the DDT's averaged mass needs the surface measure")
        if self.spectrum_size >= self.n_eigenpairs:
            raise ValueError("spectrum_size must be below n_eigenpairs")
        if self.gdm_samples is not None and (
            self.measure != "surface" or self.gdm_samples < self.gdm_singular_values
        ):
            raise ValueError(
                "gdm_samples needs the surface measure and at least gdm_singular_values samples"
            )
        unknown = set(self.fused_modalities) - set(MODALITIES)
        if unknown:
            raise ValueError(f"unknown modalities {sorted(unknown)}")
        unknown = set(self.fusion_weights) - {*MODALITIES, SIZE}
        if unknown:
            raise ValueError(f"unknown modalities {sorted(unknown)} in fusion_weights")
        for modality, kind in self.comparisons.items():
            if modality not in COMPARISONS.get(kind, ()):
                raise ValueError(f"{modality} cannot be compared by {kind!r}")
        if self.units not in UNITS:
            raise ValueError(f"unknown units {self.units!r}; use one of {', '.join(UNITS)}")
        if self.units == "metric" and SIZE not in self.fusion_weights:
            raise ValueError(f"a metric preset weighs the size: fusion_weights[{SIZE!r}]")
        if not 0.0 <= self.size_tolerance < 2.0:
            raise ValueError("size_tolerance is a D1 value (eq. 8): from 0 up to 2")
        if not self.normalize_scale and self.measure != "vertices":
            raise ValueError("normalize_scale=False is sec. 4.1's, on the vertices measure")
        unknown = set(self.partial_weights) - {*MODALITIES, PARTS}
        if unknown:
            raise ValueError(f"unknown modalities {sorted(unknown)} in partial_weights")
        if self.parts_first_radius is not None and self.gdm_samples is None:
            raise ValueError("the parts modality is computed from the GDM's samples")
        if PARTS in self.partial_weights and (
            self.parts_first_radius is None or self.fusion != "product"
        ):
            raise ValueError("partial_weights weigh the parts modality in a product rule")
        if self.parts_extra_scales < 0:
            raise ValueError("parts_extra_scales: a number of steps of the grid, from 0")
        if self.parts_scale_steps < 1:
            raise ValueError("parts_scale_steps: at least one query scale per step of the grid")
        if not 0 <= self.parts_centroid_radii <= self.parts_radii:
            raise ValueError("parts_centroid_radii: from 0 up to parts_radii")
        if (self.parts_centroid_radii > 0) != (self.parts_centroid_weight > 0):
            raise ValueError("parts_centroid_radii and parts_centroid_weight come together")
        if not 0.0 <= self.partial_loop[0] < self.partial_loop[1]:
            raise ValueError("partial_loop must rise from a non-negative start")

    @property
    def has_parts(self) -> bool:
        """Whether descriptors carry the parts modality (:mod:`worker.engine.parts`)."""
        return self.parts_first_radius is not None

    def parts_shape(self) -> tuple[int, int] | None:
        """(samples, compared values) of a whole's parts profiles, the areas' radii and
        the centroids'; None without parts."""
        if self.parts_first_radius is None or self.gdm_samples is None:
            return None
        return self.gdm_samples, self.parts_radii + self.parts_centroid_radii

    def weight(self, modality: str) -> float:
        return self.fusion_weights.get(modality, 1.0)

    @property
    def scored_modalities(self) -> tuple[str, ...]:
        """The modalities of the preset's score of a whole query: ``fused_modalities``,
        and the size (:data:`SIZE`, last) when the collection's units are metric."""
        if self.units == "metric":
            return (*self.fused_modalities, SIZE)
        return self.fused_modalities

    def comparison(self, modality: str) -> str:
        """The name of a modality's comparison: its own (``comparisons``) or the preset's
        eq. (8) or (9), or for the size eq. (8) at least ``size_tolerance``."""
        if modality == SIZE:
            return f"D1 >= {self.size_tolerance:g}"
        return self.comparisons.get(modality, self.dissimilarity)

    def uses_sigma(self, modalities: tuple[str, ...] | None = None) -> bool:
        """Whether any of ``modalities`` (default: the scored ones) is compared by eq. (9),
        which needs the gallery's sigma."""
        return any(self.comparison(m) == "D2" for m in modalities or self.scored_modalities)

    def modality_sizes(self) -> dict[str, int]:
        """Length of each modality's flat vector (what eqs. 8 and 9 compare): the shape's
        (:data:`MODALITIES`), and the size's (one) when the units are metric."""
        r1, r2, r3 = self.ddt_core_shape
        sizes = {
            "gdm": self.gdm_singular_values,
            "ddt": r1 * r2 * r3 if self.ddt_elements == "core" else min(r1, r2) * r3,
            "spectrum": self.spectrum_size,
        }
        if self.units == "metric":
            sizes[SIZE] = 1
        return sizes

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def descriptor_fields(self) -> dict[str, Any]:
        """The fields the descriptors depend on (everything but how they are compared)."""
        return {k: v for k, v in self.to_dict().items() if k not in COMPARISON_FIELDS}

    def __hash__(self) -> int:
        return hash((self.name, self.version))


PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        # Sec. 4.1: TOSCA meshes of about 3,000 vertices, no scale normalization (the
        # objects share one scale), D1, sum rule.
        Preset(
            name="smeets2010-tosca",
            version=6,
            n_vertices=3000,
            normalize_scale=False,
            dissimilarity="D1",
            fusion="sum",
            # Every preset's size weight (metric units only): shapes tune --units metric
            # on TOSCA (docs/evaluation.md).
            fusion_weights={SIZE: 8.0},
        ),
        # Sec. 4.2: SHREC 2010, 2,500 vertices, 19 singular values, 20x20x5 core,
        # D2 and the product rule.
        Preset(name="smeets2010-shrec", version=5, fusion_weights={SIZE: 2.0}),
        # Beyond the paper: the Laplace-Beltrami spectrum alone (the third modality), D1.
        Preset(
            name="lb-spectrum",
            version=5,
            dissimilarity="D1",
            fusion="sum",
            fused_modalities=("spectrum",),
            fusion_weights={SIZE: 1.0},
        ),
        # The paper's GDM and DDT as operators of the surface, fused with the spectrum;
        # a query that looks partial is ranked by the parts modality.
        # Its versions, what each changed and why: docs/decisions.md.
        Preset(
            name="smeets2010-surface",
            version=20,
            max_edge=3.0,
            max_hole_perimeter=0.5,
            two_sided_views=True,
            smooth_noise=True,
            measure="surface",
            heat_time_factor=12.0,
            gdm_samples=500,
            n_eigenpairs=100,
            spectrum_mass="averaged",
            ddt_mass="averaged",
            ddt_elements="slice_values",
            ddt_mix_times=False,
            dissimilarity="D1",
            fusion="product",
            fused_modalities=("gdm", "ddt", "spectrum"),
            # Chosen by cross-validation on TOSCA (shapes tune; docs/evaluation.md); the
            # size's (metric units only) on TOSCA and on TOSCA with SCAPE.
            fusion_weights={"gdm": 0.0, "ddt": 0.5, "spectrum": 1.0, SIZE: 1.0},
            parts_first_radius=0.07,
            parts_extra_scales=2,
            parts_scale_steps=4,
            # Chosen by cross-validation on the partiality protocol (docs/decisions.md).
            parts_centroid_radii=9,
            parts_centroid_weight=4.0,
            partial_weights={PARTS: 1.0},
        ),
    )
}

DEFAULT_PRESET = "smeets2010-surface"

#: Fields that only say how descriptors are compared, not how they are made.
COMPARISON_FIELDS = (
    "dissimilarity",
    "comparisons",
    "fusion",
    "fused_modalities",
    "units",
    "fusion_weights",
    "size_tolerance",
    "parts_scale_prior",
    "parts_extra_scales",
    "parts_scale_steps",
    "parts_min_radii",
    "partial_loop",
    "partial_weights",
)


def with_units(preset: Preset, units: str) -> Preset:
    """``preset`` for a collection of these units (:data:`UNITS`): "metric" scores the size
    with the shape at the preset's ``fusion_weights["size"]``; "any" is the scale-free
    score. The descriptors are the same either way.

    Raises
    ------
    ValueError
        Unknown units, or metric units for a preset that has no size weight.
    """
    if units not in UNITS:
        raise ValueError(f"unknown units {units!r}; use one of {', '.join(UNITS)}")
    return replace(preset, units=units)


def with_fusion(
    preset: Preset, weights: Mapping[str, float], comparisons: Mapping[str, str] | None = None
) -> Preset:
    """``preset`` fusing with these weights (and these modalities' comparisons, the others
    kept): a fusion learned or pinned for one collection. The descriptors are the same.

    Raises
    ------
    ValueError
        A comparison a modality cannot take (:data:`COMPARISONS`), or one of an unknown
        modality.
    """
    chosen = dict(preset.comparisons)
    for modality, kind in (comparisons or {}).items():
        if modality == SIZE:
            continue  # the size has its one comparison
        if kind not in COMPARISONS:
            raise ValueError(f"unknown comparison {kind!r}; use one of {', '.join(COMPARISONS)}")
        chosen[modality] = kind
    own = {m: k for m, k in chosen.items() if k != preset.dissimilarity}
    return replace(preset, fusion_weights={**preset.fusion_weights, **weights}, comparisons=own)


def get_preset(name: str) -> Preset:
    """Return the preset called ``name``; ``KeyError`` names the known ones."""
    try:
        return PRESETS[name]
    except KeyError:
        known = ", ".join(sorted(PRESETS))
        raise KeyError(f"unknown preset {name!r}; known presets: {known}") from None
