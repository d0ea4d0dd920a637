"""Rules for similarity search: the options, the query's descriptor, the ranked matches.

No HTTP types: the options arrive as the strings a client sent (form fields of
``POST /query``, query parameters of ``POST /meshes/{id}/similar``), so both are
validated by :func:`parse_options` with the same codes and sentences, and the
results are domain objects the router turns into responses.
"""

from __future__ import annotations

import hashlib
import importlib
import math
import time
from dataclasses import dataclass, field
from types import ModuleType

from sqlalchemy.orm import Session

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.presets import MODALITIES, PRESETS, Preset
from worker.recognition.calibration import Calibration

from ..descriptors import DescriptorSource, stored_descriptor, upload_descriptor
from ..errors import ConflictError, InvalidInputError
from ..gallery.index import Match
from ..gallery.service import Gallery
from ..links import collection_path
from ..models import Mesh
from ..repositories import meshes, query_previews
from ..schemas import parse_far
from ..state import AppState
from ..storage import ReceivedFile

#: The search options a client may send, with ``POST /query``'s file.
OPTION_NAMES = ("k", "preset", "fusion", "modalities", "far")
DEFAULT_K = 10
#: What :func:`parse_modalities` accepts (documented in the schema): blank, or names
#: separated by commas, spaces and empty items allowed.
MODALITIES_PATTERN = "^ *$|^[ ,]*(gdm|ddt|spectrum)( *,[ ,]*(gdm|ddt|spectrum))*[ ,]*$"


@dataclass(frozen=True)
class SearchOptions:
    """Validated search options: ``k`` matches, ranked under ``preset`` with ``fusion``
    (None: the preset's rule) over ``modalities``; with ``far``, each match is also
    accepted or not at that false acceptance rate (open-set: "not in the gallery" is
    an answer)."""

    k: int
    preset: Preset
    fusion: str | None
    modalities: tuple[str, ...]
    far: float | None = None


@dataclass
class RankedMatch:
    mesh: Mesh
    rank: int
    score: float
    scores: dict[str, float]
    #: P(same label as the query), from the gallery's calibration; None if uncalibrated.
    confidence: float | None = None
    #: Accepted at the options' FAR (None without one).
    accepted: bool | None = None
    #: Per modality: the share of the gallery's pairs of different objects farther apart
    #: (:mod:`app.gallery.reference`); empty before the gallery's first reference fit.
    closeness: dict[str, float] = field(default_factory=dict)
    #: A single view's best candidates: the share of the view this one holds in place
    #: (:func:`worker.engine.rigid.verified_fitness`); None for others.
    fitness: float | None = None


@dataclass
class PartialQuery:
    """A query ranked as a part: how partial it looks and how much of its whole it seems
    to miss (an estimate and its bounds: the parts' scale is measured on a grid), and
    whether it is one view (:attr:`ShapeDescriptor.single_view`: a point cloud, or a
    surface facing one way)."""

    partiality: float
    missing_share: float
    missing_range: tuple[float, float]
    single_view: bool = False
    cloud: bool = False
    #: Its surface looked noisy and was smoothed: a single view before its fit, any other
    #: surface before it was described (:attr:`ShapeDescriptor.surface_smoothed`).
    smoothed: bool = False
    #: How many of the best matches were verified rigidly (0: none).
    verified: int = 0
    #: The most any of them holds of the view (its fitness); None when none was fitted.
    held: float | None = None

    @property
    def found(self) -> bool:
        """A fitted match holds the view as its own object's surface does
        (:data:`worker.engine.rigid.HELD_FITNESS`)."""
        return self.held is not None and self.held >= _rigid().HELD_FITNESS

    @property
    def note(self) -> str:
        if self.single_view:
            # Described two-sided (its unseen side the image of the seen one), it matches
            # as nearly whole: the parts' scale does not measure what the scan misses.
            seen = "a scanner's point cloud" if self.cloud else "its faces all face one way"
            view = (
                f"One view of its object ({seen}): its unseen side is taken as the mirror "
                "image of the side it sees, so how much of the object is missing is not "
                "measured; "
            )
            noisy = self._noisy("fitted")
            if self.held is None:
                ranked = "matches are ranked by the parts that are there"
                return f"{view}{ranked}, so they have no confidence.{noisy}"
            fitted = (
                f"{self.verified} of the best by the parts that are there (and by their "
                "surfaces' features) were fitted to it rigidly and ranked among themselves "
                f"by how much of it they hold (fitness). The fittest holds "
                f"{math.floor(1000 * self.held + 1e-9) / 10:.1f}% of it"  # 89.97% is no 90.0%
            )
            least = f"{_rigid().HELD_FITNESS:.0%}"
            verdict = (
                f", at least {least}, as its own object's surface does: on the evaluation's "
                "views such a match was of the view's class every time without depth noise, "
                "all but 2 of 249 times with it."
                if self.found
                else f", under the {least} its own object's surface holds: the object may be "
                "enrolled in another pose only, or not at all, or the view sees too little of "
                "it; the matches have no confidence."
            )
            return view + fitted + verdict + noisy
        low, high = (round(100 * v) for v in self.missing_range)
        if high >= 10:
            return (
                f"Between {low}% and {high}% of the surface seems missing (its parts' best "
                "match, measured to that resolution); matches are ranked by the parts that are "
                f"there, so they have no confidence.{self._noisy('described')}"
            )
        return (
            "The surface looks open (cut, holed or scanned from one side), with little of it "
            "missing; matches are ranked by the parts that are there, so they have no "
            f"confidence.{self._noisy('described')}"
        )

    def _noisy(self, before: str) -> str:
        """The sentence saying the surface was smoothed (before it was ``before``), or
        nothing."""
        return f" {smoothed_sentence(before)}" if self.smoothed else ""


#: Below this share of the file's surface described, the answer says the rest was left out
#: (specks and debris are far smaller).
PARTIAL_SURFACE = 0.99


def smoothed_sentence(before: str) -> str:
    """The sentence saying a query's surface was smoothed before it was ``before``."""
    return (
        "Its surface looked noisy (rough, as a sensor's noise leaves a scan, not as a coarse "
        f"sampling does) and was smoothed before it was {before}."
    )


def query_notes(
    facts: dict[str, bool | int | float | list[int]], partial: PartialQuery | None
) -> list[str]:
    """What the answer says of its query (:func:`query_facts`) in sentences for a person,
    as the command line and the web page print them: the point cloud it was and the floor
    or wall left out of it, the part of the file left out, and how partial it looks
    (:attr:`PartialQuery.note`) or, a whole, that it was smoothed."""
    notes = []
    points = facts.get("input_points")
    grid = facts.get("input_grid")
    if isinstance(grid, list):
        width, height = grid
        notes.append(
            f"The query is a scanner's point cloud: {points:,} points on a {width} x {height} "
            "grid, triangulated by it."
        )
    elif isinstance(hidden := facts.get("input_hidden"), int):
        notes.append(
            f"The query is a point cloud that is not one view (a whole object's points, or "
            f"several views'): it was read as the view that sees most of it, {points:,} "
            f"points triangulated as seen from there; the {hidden:,} hidden behind them "
            "were left out."
        )
    elif points is not None:
        notes.append(
            f"The query is a scanner's point cloud: {points:,} points, triangulated as one view."
        )
    support = facts.get("input_support")
    if isinstance(support, int) and support > 0:
        notes.append(
            f"{support:,} other points were left out: they lie on a plane the object "
            "stood on or against (a floor, a table or a wall, running out of the frame "
            "with everything else in front of it)."
        )
    kept = facts.get("kept_area_fraction")
    if isinstance(kept, float) and kept < PARTIAL_SURFACE:
        notes.append(
            f"Only {kept:.0%} of the query file's surface was described: it has other, "
            "separate parts, which were left out (the largest connected part is described)."
        )
    if partial is not None:
        notes.append(partial.note)
    elif facts.get("smoothed"):
        notes.append(smoothed_sentence("described"))
    return notes


@dataclass
class SearchResult:
    """The answer to a search: the options used, the matches best first, timings."""

    options: SearchOptions
    collection: str
    gallery_size: int
    matches: list[RankedMatch]
    timings: dict[str, float]
    query: dict[str, bool | int | float | list[int]] = field(default_factory=dict)
    #: Where the query's descriptor came from: "computed" by a worker now, the
    #: "enrolled" mesh with the same bytes, a "recent" query's, or "stored" (/similar).
    descriptor_source: DescriptorSource = "computed"
    #: The score threshold at the options' FAR (None without one).
    threshold: float | None = None
    #: Where the query's preview (GLB) can be fetched, when there is one.
    preview: str | None = None
    #: How partial the query looks, when it was ranked as a part (None: as a whole).
    partial: PartialQuery | None = None
    #: The weight each modality's score carried in the fused score (a weight of 0: shown
    #: for information only).
    weights: dict[str, float] = field(default_factory=dict)
    #: What the answer says of its query, in sentences (:func:`query_notes`).
    notes: list[str] = field(default_factory=list)

    @property
    def fusion(self) -> str:
        return self.options.fusion or self.options.preset.fusion


def _blank_to_none(value: str | None) -> str | None:
    """An option sent empty or as spaces is the default; any other text is validated."""
    return (value or "").strip(" ") or None


def resolve_preset(gallery: Gallery, name: str | None) -> Preset:
    """The preset a query asks for; only the collection's can be searched."""
    if name is None or name == gallery.preset.name:
        return gallery.preset
    if name not in PRESETS:
        known = ", ".join(sorted(PRESETS))
        raise InvalidInputError(
            f"There is no preset called {name!r}; known presets: {known}.", code="unknown_preset"
        )
    raise ConflictError(
        f"Collection {gallery.name!r} is described with preset {gallery.preset.name!r}, so "
        f"it can only be searched with that preset, not {name!r}.",
        code="preset_not_enrolled",
    )


def parse_modalities(text: str | None, preset: Preset) -> tuple[str, ...]:
    if text is None:
        return preset.scored_modalities
    names = tuple(dict.fromkeys(p.strip(" ") for p in text.split(",") if p.strip(" ")))
    unknown = [n for n in names if n not in MODALITIES]
    if unknown or not names:
        raise InvalidInputError(
            f"Unknown modalities {unknown}; choose among {', '.join(MODALITIES)}.",
            code="unknown_modality",
        )
    return names


def parse_k(text: str | None) -> int:
    if text is None:
        return DEFAULT_K
    try:
        return int(text)
    except ValueError:
        raise InvalidInputError("k must be a whole number.", code="invalid_k") from None


def check_k(state: AppState, k: int) -> int:
    if not 1 <= k <= state.settings.max_k:
        raise InvalidInputError(
            f"k must be between 1 and {state.settings.max_k}.", code="invalid_k"
        )
    return k


def parse_options(
    state: AppState,
    gallery: Gallery,
    *,
    k: str | None,
    preset: str | None,
    fusion: str | None,
    modalities: str | None,
    far: str | None = None,
) -> SearchOptions:
    """Validate the options as sent (blank means the default).

    Raises
    ------
    ConflictError
        ``preset_not_enrolled``: a preset other than the collection's.
    InvalidInputError
        ``unknown_preset``, ``unknown_modality``,
        ``invalid_k`` or ``invalid_fusion``, each with a sentence.
    """
    rule = _blank_to_none(fusion)
    if rule not in (None, "sum", "product"):
        raise InvalidInputError("fusion must be 'sum' or 'product'.", code="invalid_fusion")
    count = parse_k(_blank_to_none(k))
    chosen = resolve_preset(gallery, _blank_to_none(preset))
    mods = parse_modalities(_blank_to_none(modalities), chosen)
    options = SearchOptions(
        k=check_k(state, count),
        preset=chosen,
        fusion=rule,
        modalities=mods,
        far=parse_far(_blank_to_none(far)),
    )
    return options


def query_facts(descriptor: ShapeDescriptor) -> dict[str, bool | int | float | list[int]]:
    """What the answer says of the query's mesh: its size as cleaned and as described,
    (when known) the described part's share of the file's surface area and the share of
    its surface facing one way, the points (and grid and the support's points left out,
    when organized) of the point cloud it was, and whether it was smoothed of a scanner's
    noise."""
    facts: dict[str, bool | int | float | list[int]] = {
        "input_vertices": descriptor.input_vertices,
        "input_faces": descriptor.input_faces,
        "vertices": descriptor.vertices,
    }
    if descriptor.kept_area_fraction is not None:
        facts["kept_area_fraction"] = descriptor.kept_area_fraction
    if descriptor.facing_share is not None:
        facts["facing_share"] = round(descriptor.facing_share, 3)
    if descriptor.input_points is not None:
        facts["input_points"] = descriptor.input_points
    if descriptor.input_grid is not None:
        facts["input_grid"] = list(descriptor.input_grid)
    if descriptor.input_support is not None:
        facts["input_support"] = descriptor.input_support
    if descriptor.input_hidden is not None:
        facts["input_hidden"] = descriptor.input_hidden
    if descriptor.surface_smoothed:
        facts["smoothed"] = True
    return facts


def rank(
    session: Session,
    state: AppState,
    gallery: Gallery,
    descriptor: ShapeDescriptor,
    options: SearchOptions,
    *,
    exclude: tuple[int, ...] = (),
    timings: dict[str, float],
    descriptor_source: DescriptorSource,
) -> SearchResult:
    # A single view's best are verified (rigidly), however few matches were asked for.
    asked = max(options.k, _rigid().FEATURE_POOL) if descriptor.single_view else options.k
    matches, stats = gallery.search(
        descriptor,
        asked,
        fusion=options.fusion,
        modalities=options.modalities,
        exclude=exclude,
    )
    fitness: dict[int, float] = {}
    if descriptor.single_view and stats.parts_scale is not None:
        clock = time.perf_counter()
        matches, fitness = _verified(
            session, state, gallery, descriptor, matches, stats.parts_scale
        )
        timings = {**timings, "verify": time.perf_counter() - clock}
    matches = matches[: options.k]
    rows = meshes.by_ids(session, [m.id for m in matches])
    partial = None
    if stats.kept_share is not None and stats.kept_range is not None:
        file_share = descriptor.kept_area_fraction or 1.0
        kept = stats.kept_share * file_share
        # Rounded: the grid's resolution is some hundredths, not sixteen digits.
        low, high = (round(max(0.0, 1.0 - k * file_share), 2) for k in reversed(stats.kept_range))
        partial = PartialQuery(
            stats.partiality,
            round(max(0.0, 1.0 - kept), 2),
            (low, high),
            single_view=descriptor.single_view,
            cloud=descriptor.input_points is not None,
            smoothed=bool(descriptor.surface_smoothed),
            verified=len(fitness),
            held=max(fitness.values(), default=None),
        )
    reference = gallery.reference
    # The calibration is of whole queries' scores; a part's are on another scale.
    calibration = None if partial else _calibration_for(state, gallery, options)
    threshold = None
    if options.far is not None and calibration is not None:
        assert calibration is not None  # _calibration_for raised otherwise
        threshold = calibration.threshold_at(options.far)
    ranked: list[RankedMatch] = []
    for match in matches:
        mesh = rows.get(match.id)
        if mesh is None:  # deleted a moment ago
            continue
        ranked.append(
            RankedMatch(
                mesh,
                len(ranked) + 1,
                match.score,
                match.scores,
                confidence=None
                if calibration is None
                else float(calibration.confidence(match.score)),
                accepted=None if threshold is None else bool(match.score <= threshold),
                closeness={}
                if reference is None
                else {
                    m: c
                    for m, v in match.scores.items()
                    if (c := reference.closeness(m, v)) is not None
                },
                fitness=fitness.get(match.id),
            )
        )
    facts = query_facts(descriptor)
    return SearchResult(
        options=options,
        collection=gallery.name,
        gallery_size=len(gallery),
        matches=ranked,
        timings={**timings, "search": stats.seconds},
        query=facts,
        descriptor_source=descriptor_source,
        threshold=threshold,
        partial=partial,
        weights=stats.weights,
        notes=query_notes(facts, partial),
    )


def _verified(
    session: Session,
    state: AppState,
    gallery: Gallery,
    descriptor: ShapeDescriptor,
    matches: list[Match],
    parts_scale: float,
) -> tuple[list[Match], dict[int, float]]:
    """A single view's ``FEATURE_POOL`` best matches, those it was fitted on
    (:func:`worker.engine.rigid.verified_fitness`) in the places they held among them,
    most of the view held first (:func:`worker.engine.rigid.verified_order`), then the
    rest, and each fitted match's fitness; the matches as they are when one of them has
    no surface kept. Each candidate's anchors are kept (``state.verify_anchors``) by its
    stored descriptor's content."""
    rigid = _rigid()
    if rigid.kept_surface(descriptor) is None:  # stored before surfaces were kept
        return matches, {}
    shortlist = matches[: rigid.FEATURE_POOL]
    preset = gallery.preset
    stored = meshes.descriptors_for(session, [m.id for m in shortlist], preset.name, preset.version)
    if len(stored) < len(shortlist):  # deleted a moment ago
        return matches, {}
    candidates, anchors = [], []
    for m in shortlist:
        data = stored[m.id].data
        candidate = ShapeDescriptor.from_npz_bytes(data)
        key = hashlib.blake2b(data, digest_size=16).digest()
        made = state.verify_anchors.get(key)
        if made is not None:
            state.metrics.verify_anchors.labels("kept").inc()
        else:
            made = rigid.candidate_anchors(candidate)
            if made is not None:
                state.verify_anchors.put(key, made)
                state.metrics.verify_anchors.labels("made").inc()
        candidates.append(candidate)
        anchors.append(made)
    metric = preset.units == "metric"
    threads = state.settings.verify_threads
    fitness = rigid.verified_fitness(descriptor, candidates, parts_scale, metric, anchors, threads)
    if fitness is None:
        return matches, {}
    order = rigid.verified_order(fitness)
    held = {m.id: float(f) for m, f in zip(shortlist, fitness, strict=True) if math.isfinite(f)}
    return [shortlist[i] for i in order] + matches[len(shortlist) :], held


def _rigid() -> ModuleType:
    """:mod:`worker.engine.rigid`, imported by the first single view: it needs scipy,
    which the service starts without (only workers describe)."""
    return importlib.import_module("worker.engine.rigid")


def _calibration_for(
    state: AppState, gallery: Gallery, options: SearchOptions
) -> Calibration | None:
    """The calibration of the score the options rank by; None if there is none (too few
    labelled pairs), unless a FAR was asked for (then 409)."""
    settings = state.settings
    try:
        fit = gallery.calibration(
            max_pairs=settings.calibration_max_pairs,
            refit_seconds=settings.calibration_refit_seconds,
        )
    except ConflictError:
        if options.far is not None:
            raise
        return None
    return fit.for_fusion(options.modalities, options.fusion or options.preset.fusion)


def query_by_upload(
    session: Session,
    state: AppState,
    gallery: Gallery,
    upload: ReceivedFile,
    options: SearchOptions,
) -> SearchResult:
    """Rank the gallery against an uploaded mesh (:func:`upload_descriptor`)."""
    gallery.check_ready()  # before the worker spends seconds on the query
    descriptor, source, timings, preview = upload_descriptor(
        session, state, gallery, upload, options.preset
    )
    result = rank(
        session,
        state,
        gallery,
        descriptor,
        options,
        timings=timings,
        descriptor_source=source,
    )
    if preview or _has_preview(session, gallery, upload.sha256):
        result.preview = f"{collection_path(gallery.name)}/previews/{upload.sha256}"
    return result


def _has_preview(session: Session, gallery: Gallery, sha256: str) -> bool:
    """Whether :func:`query_preview` has something for these bytes in the collection (no
    bytes read: every search that reuses a descriptor asks)."""
    if query_previews.has_query_preview(session, gallery.collection_id, sha256):
        return True
    mesh = meshes.get_by_sha256(session, gallery.collection_id, sha256)
    return mesh is not None and meshes.has_preview(session, mesh.id)


def query_preview(session: Session, gallery: Gallery, sha256: str) -> bytes | None:
    """The preview (GLB) of bytes recently searched with in, or enrolled in, ``gallery``'s
    collection, if one was made (another collection's are never served here)."""
    recent = query_previews.get_query_preview(session, gallery.collection_id, sha256)
    if recent is not None:
        return recent
    mesh = meshes.get_by_sha256(session, gallery.collection_id, sha256)
    stored = None if mesh is None else meshes.get_preview(session, mesh.id)
    return None if stored is None else stored.glb


def similar_to(
    session: Session, state: AppState, gallery: Gallery, mesh_id: int, options: SearchOptions
) -> SearchResult:
    """Rank the gallery against an enrolled mesh's stored descriptor (itself left out)."""
    descriptor = stored_descriptor(session, gallery, mesh_id, options.preset)
    result = rank(
        session,
        state,
        gallery,
        descriptor,
        options,
        exclude=(mesh_id,),
        timings={},
        descriptor_source="stored",
    )
    if meshes.has_preview(session, mesh_id):
        result.preview = f"{collection_path(gallery.name)}/meshes/{mesh_id}/preview"
    return result
