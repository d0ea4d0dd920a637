"""Rules for similarity search: query descriptors, index search, ranked matches."""

from __future__ import annotations

import time
import uuid

from sqlalchemy.orm import Session

from worker.engine.pipeline import ShapeDescriptor
from worker.engine.presets import MODALITIES, PRESETS, Preset

from ..errors import ConflictError, InvalidInputError, NotFoundError, UnavailableError
from ..gallery import vectors_of
from ..index import GalleryIndex, SearchStats
from ..meshes import repository as meshes
from ..models import MeshStatus
from ..state import AppState
from ..uploads import UploadedFile
from .schemas import MatchOut, QueryOut


def resolve_preset(state: AppState, name: str | None) -> Preset:
    """The preset a query asks for; only the enrolled one can be searched."""
    if name is None or name == state.preset.name:
        return state.preset
    if name not in PRESETS:
        known = ", ".join(sorted(PRESETS))
        raise InvalidInputError(
            f"There is no preset called {name!r}; known presets: {known}.", code="unknown_preset"
        )
    raise InvalidInputError(
        f"The gallery is described with preset {state.preset.name!r}, so it can only be "
        f"searched with that preset, not {name!r}.",
        code="preset_not_enrolled",
    )


def parse_modalities(text: str | None, preset: Preset) -> tuple[str, ...]:
    if text is None or not text.strip():
        return tuple(preset.fused_modalities)
    names = tuple(dict.fromkeys(p.strip() for p in text.split(",") if p.strip()))
    unknown = [n for n in names if n not in MODALITIES]
    if unknown or not names:
        raise InvalidInputError(
            f"Unknown modalities {unknown}; choose among {', '.join(MODALITIES)}.",
            code="unknown_modality",
        )
    return names


def check_k(state: AppState, k: int) -> int:
    if not 1 <= k <= state.settings.max_k:
        raise InvalidInputError(
            f"k must be between 1 and {state.settings.max_k}.", code="invalid_k"
        )
    return k


def ready_index(state: AppState) -> GalleryIndex:
    if state.index is None:
        raise UnavailableError(
            "The index is still loading; try again in a moment.", code="index_loading"
        )
    return state.index


def describe_query(state: AppState, upload: UploadedFile, preset: Preset) -> ShapeDescriptor:
    """The query's descriptor, computed by a worker (blocking; call from a thread)."""
    return state.queue.describe_now(uuid.uuid4().hex, upload.path, upload.filename, preset.name)


def rank(
    session: Session,
    state: AppState,
    vectors: dict,
    *,
    k: int,
    preset: Preset,
    fusion: str | None,
    modalities: tuple[str, ...],
    exclude: tuple[int, ...] = (),
    timings: dict[str, float],
    query_info: dict[str, int],
) -> QueryOut:
    index = ready_index(state)
    stats = SearchStats()
    matches = index.search(
        vectors, k, fusion=fusion, modalities=modalities, exclude=exclude, stats=stats
    )
    state.metrics.search_seconds.observe(stats.seconds)
    timings = {**timings, "search": stats.seconds}
    rows = meshes.by_ids(session, [m.id for m in matches])
    out: list[MatchOut] = []
    for match in matches:
        mesh = rows.get(match.id)
        if mesh is None:  # deleted a moment ago
            continue
        out.append(
            MatchOut(
                mesh_id=mesh.id,
                name=mesh.name,
                label=mesh.label,
                rank=len(out) + 1,
                score=match.score,
                scores=match.scores,
            )
        )
    return QueryOut(
        preset=preset.name,
        preset_version=preset.version,
        dissimilarity=preset.dissimilarity,
        fusion=fusion or preset.fusion,
        modalities=list(modalities),
        k=k,
        gallery_size=len(index),
        matches=out,
        timings=timings,
        query=query_info,
    )


def query_by_upload(
    session: Session,
    state: AppState,
    upload: UploadedFile,
    *,
    k: int,
    preset_name: str | None,
    fusion: str | None,
    modalities: str | None,
) -> QueryOut:
    preset = resolve_preset(state, preset_name)
    mods = parse_modalities(modalities, preset)
    check_k(state, k)
    ready_index(state)
    started = time.perf_counter()
    descriptor = describe_query(state, upload, preset)
    timings = dict(descriptor.timings)
    timings["describe_wall"] = time.perf_counter() - started
    return rank(
        session,
        state,
        vectors_of(descriptor),
        k=k,
        preset=preset,
        fusion=fusion,
        modalities=mods,
        timings=timings,
        query_info={
            "input_vertices": descriptor.input_vertices,
            "input_faces": descriptor.input_faces,
            "vertices": descriptor.vertices,
        },
    )


def similar_to(
    session: Session,
    state: AppState,
    mesh_id: int,
    *,
    k: int,
    preset_name: str | None,
    fusion: str | None,
    modalities: str | None,
) -> QueryOut:
    preset = resolve_preset(state, preset_name)
    mods = parse_modalities(modalities, preset)
    check_k(state, k)
    mesh = meshes.get(session, mesh_id)
    if mesh is None:
        raise NotFoundError(f"There is no mesh with id {mesh_id}.")
    stored = meshes.get_descriptor(session, mesh_id, preset.name, preset.version)
    if stored is None or mesh.status != MeshStatus.ready.value:
        raise ConflictError(
            f"Mesh {mesh_id} is {mesh.status}, not ready; it has no descriptor to compare yet.",
            code="mesh_not_ready",
        )
    descriptor = ShapeDescriptor.from_npz_bytes(stored.data)
    return rank(
        session,
        state,
        vectors_of(descriptor),
        k=k,
        preset=preset,
        fusion=fusion,
        modalities=mods,
        exclude=(mesh_id,),
        timings={},
        query_info={"input_vertices": descriptor.input_vertices, "vertices": descriptor.vertices},
    )
