"""HTTP layer of verification: ``GET /calibration`` and ``POST /verify``."""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

import numpy as np
from fastapi import APIRouter

from worker.engine.presets import Preset
from worker.recognition.calibration import Calibration
from worker.recognition.fusion import Adoption, FusionScores

from ..deps import (
    MAX_ROW_ID,
    READ_ACCESS,
    GalleryDep,
    MultipartDep,
    ReadSessionDep,
    StateDep,
    require_file,
)
from ..errors import InvalidInputError
from ..gallery.pairs import FUSED
from ..gallery.weights import GalleryFusion
from ..schemas import (
    ACCESS_RESPONSES,
    ERROR_RESPONSES,
    FILE_RESPONSES,
    MESH_FILE,
    check_text,
    multipart_body,
    parse_far,
    threshold_out,
)
from . import service
from .schemas import (
    AdoptionOut,
    CalibrationOut,
    FusionFold,
    FusionOut,
    HistogramOut,
    OperatingPoint,
    RecognitionScores,
    RocOut,
    ScoreCalibration,
    VerificationOut,
)

router = APIRouter(
    tags=["verification"],
    dependencies=READ_ACCESS,
    responses=ERROR_RESPONSES | ACCESS_RESPONSES,
)

ROC_POINTS = 200
DEFAULT_FAR = 0.01
VERIFY_FIELDS = ("mesh_id", "claim_id", "claim_label", "far")

NOT_CALIBRATED: dict[int | str, dict[str, Any]] = {
    409: {"description": "Too few labelled pairs to calibrate (`not_calibrated`)"},
}
VERIFY_BODY = multipart_body(
    {
        "file": MESH_FILE
        | {"description": f"the mesh to verify (or mesh_id): {MESH_FILE['description']}"},
        "mesh_id": {
            "type": "integer",
            "minimum": 1,
            "maximum": MAX_ROW_ID,
            "description": "an enrolled mesh to verify (or file)",
        },
        "claim_id": {
            "type": "integer",
            "minimum": 1,
            "maximum": MAX_ROW_ID,
            "description": "the enrolled mesh it is claimed to be",
        },
        "claim_label": {
            "type": "string",
            # Not blank (a blank label says nothing), and no NUL (TEXT_PATTERN).
            "pattern": "^[^\\x00]*[^\\x00\\s][^\\x00]*$",
            "description": "the label it is claimed to have (the closest "
            "enrolled mesh of that label decides)",
        },
        "far": {
            "type": "number",
            "exclusiveMinimum": 0,
            "exclusiveMaximum": 1,
            "default": DEFAULT_FAR,
            "description": "false acceptance rate of the decision",
        },
    },
    one_of_each=(("file", "mesh_id"), ("claim_id", "claim_label")),
)


def _operating_points(row: Calibration) -> list[OperatingPoint]:
    return [
        OperatingPoint(far=far, threshold=threshold_out(t), estimated_far=f, estimated_frr=r)
        for far, t, f, r in service.operating_points(row)
    ]


@router.get(
    "/calibration",
    operation_id="get_calibration",
    response_model=CalibrationOut,
    summary="How the gallery's scores separate same from different objects",
    description=(
        "From every pair of enrolled meshes that both have a label (a random sample above "
        "the pair budget): the ROC, the EER, and the score threshold at FAR 0.1%, 1% and 5% "
        "of the preset's fused score, and of each modality. Refitted after enrollments and "
        "deletions (at most every SHAPES_CALIBRATION_REFIT_SECONDS)."
    ),
    responses=NOT_CALIBRATED,
)
def get_calibration(gallery: GalleryDep, state: StateDep) -> CalibrationOut:
    fit = service.calibration(state, gallery)
    row = fit.rows[FUSED]
    keep = np.unique(np.linspace(0, len(row.far) - 1, min(ROC_POINTS, len(row.far))).astype(int))
    preset = gallery.preset
    edges, genuine, impostor = fit.histogram()
    return CalibrationOut(
        collection=gallery.name,
        preset=preset.name,
        preset_version=preset.version,
        score="+".join(preset.scored_modalities) + f" {preset.fusion}",
        shapes=fit.shapes,
        labelled_shapes=fit.labelled,
        labels=fit.labels,
        genuine_pairs=row.genuine,
        impostor_pairs=row.impostor,
        sampled=fit.sampled,
        trusted=row.trusted,
        trust_rule=service.TRUST_RULE,
        eer=row.eer,
        operating_points=_operating_points(row),
        roc=RocOut(far=row.far[keep].tolist(), frr=row.frr[keep].tolist()),
        modalities={
            m: ScoreCalibration(
                eer=fit.rows[m].eer, operating_points=_operating_points(fit.rows[m])
            )
            for m in fit.rows
            if m != FUSED
        },
        fitted_at=fit.fitted_at,
        fusion=fusion_out(gallery.fusion, gallery.base_preset),
        histogram=HistogramOut(
            edges=edges.tolist(), genuine=genuine.tolist(), impostor=impostor.tolist()
        ),
    )


def _scores(scores: FusionScores) -> RecognitionScores:
    return RecognitionScores(eer=scores.eer, nn=scores.nn, map=scores.map)


def _adoption(adoption: Adoption) -> AdoptionOut:
    fields = asdict(adoption)
    fields["statistic"] = adoption.statistic if math.isfinite(adoption.statistic) else None
    return AdoptionOut(**fields)


def fusion_out(fusion: GalleryFusion, preset: Preset) -> FusionOut:
    tuning = fusion.tuning
    return FusionOut(
        weights=fusion.weights,
        comparisons=fusion.comparisons,
        source=fusion.source,
        reason=fusion.reason,
        preset_weights={m: preset.weight(m) for m in preset.scored_modalities},
        preset_comparisons={m: preset.comparison(m) for m in preset.scored_modalities},
        labelled_shapes=fusion.shapes,
        labels=fusion.classes,
        sampled=fusion.sampled,
        folds=[]
        if tuning is None
        else [
            FusionFold(
                held_out_shapes=fold.held_out_objects,
                weights=fold.weights,
                comparisons=fold.comparisons,
                held_out=_scores(fold.held_out),
                preset=_scores(fold.preset),
            )
            for fold in tuning.folds
        ],
        rounds=0 if tuning is None else tuning.repeats,
        held_out=None if tuning is None else _scores(tuning.held_out),
        preset_held_out=None if tuning is None else _scores(tuning.preset_held_out),
        adoption=None if fusion.adoption is None else AdoptionOut(**asdict(fusion.adoption)),
        fitted_at=fusion.fitted_at,
    )


def _optional_id(fields: dict[str, str], name: str) -> int | None:
    text = (fields.get(name) or "").strip()
    if not text:
        return None
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= MAX_ROW_ID:
        raise InvalidInputError(
            f"{name} must be a mesh id (a whole number from 1 to {MAX_ROW_ID}).",
            code=f"invalid_{name}",
        )
    return value


@router.post(
    "/verify",
    operation_id="verify",
    response_model=VerificationOut,
    summary="Is this mesh the claimed object? Yes or no at a chosen FAR",
    description=(
        "The probe (a file, or an enrolled mesh's id) against a claim (an enrolled mesh's "
        "id, or a label: the closest enrolled mesh of it decides), under the preset's fused "
        "score and the gallery's calibration.\n\n"
        "`curl -F file=@wolf2.off.gz -F claim_label=wolf -F far=0.01 "
        "http://127.0.0.1:8000/verify`"
    ),
    responses=NOT_CALIBRATED
    | FILE_RESPONSES
    | {
        404: {"description": "No such claimed mesh or label in the gallery"},
        503: {"description": "Index loading, or no worker answered in time"},
    },
    openapi_extra=VERIFY_BODY,
)
def verify(
    gallery: GalleryDep, upload: MultipartDep, session: ReadSessionDep, state: StateDep
) -> VerificationOut:
    fields = upload.fields
    unknown = set(fields) - set(VERIFY_FIELDS)
    if unknown:
        raise InvalidInputError(
            f"Unknown form fields: {', '.join(sorted(unknown))}; "
            "use file or mesh_id, claim_id or claim_label, and far.",
            code="unknown_field",
        )
    far = parse_far((fields.get("far") or "").strip() or None)
    claim_label = check_text(fields.get("claim_label") or "", "claim_label").strip() or None
    result = service.verify(
        session,
        state,
        gallery,
        upload=require_file(upload) if upload.file is not None else None,
        mesh_id=_optional_id(fields, "mesh_id"),
        claim_id=_optional_id(fields, "claim_id"),
        claim_label=claim_label,
        far=DEFAULT_FAR if far is None else far,
    )
    return VerificationOut(
        same=result.same,
        score=result.score,
        scores=result.scores,
        threshold=threshold_out(result.threshold),
        far=result.far,
        estimated_far=result.estimated_far,
        estimated_frr=result.estimated_frr,
        confidence=result.confidence,
        matched_id=result.matched_id,
        candidates=result.candidates,
        probe=result.probe,
        trusted=result.calibration.rows[FUSED].trusted,
    )
