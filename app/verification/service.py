"""Rules of verification: the gallery's calibration, and "is this the same object?"."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from worker.recognition.calibration import OPERATING_FARS, Calibration

from ..descriptors import enrolled_mesh, stored_descriptor, upload_descriptor
from ..errors import InvalidInputError, NotFoundError
from ..gallery.pairs import FUSED, GalleryCalibration
from ..gallery.service import Gallery
from ..repositories import meshes
from ..state import AppState
from ..storage import ReceivedFile

#: The rule GET /calibration states for "trusted".
TRUST_RULE = (
    "at least 100 genuine and 1,000 impostor labelled pairs (so FAR 0.1% rests on at least "
    "one accepted impostor pair); with fewer, thresholds and EER are estimates from few pairs"
)


def calibration(state: AppState, gallery: Gallery) -> GalleryCalibration:
    """The gallery's current calibration (``not_calibrated`` 409 with too few pairs)."""
    settings = state.settings
    return gallery.calibration(
        max_pairs=settings.calibration_max_pairs,
        refit_seconds=settings.calibration_refit_seconds,
    )


def operating_points(row: Calibration) -> list[tuple[float, float, float, float]]:
    """``(target FAR, threshold, estimated FAR, estimated FRR)`` at ``OPERATING_FARS``."""
    out = []
    for far in OPERATING_FARS:
        threshold = row.threshold_at(far)
        out.append((far, threshold, *row.rates_at(threshold)))
    return out


@dataclass
class Verification:
    """The answer to "is the probe the claimed object?" at a false acceptance rate."""

    same: bool
    score: float
    scores: dict[str, float]
    threshold: float
    far: float
    estimated_far: float
    estimated_frr: float
    confidence: float
    matched_id: int
    candidates: int
    probe: str
    calibration: GalleryCalibration


def verify(
    session: Session,
    state: AppState,
    gallery: Gallery,
    *,
    upload: ReceivedFile | None,
    mesh_id: int | None,
    claim_id: int | None,
    claim_label: str | None,
    far: float,
) -> Verification:
    """Compare a probe (an upload or an enrolled mesh) with a claim (an enrolled mesh,
    or every enrolled mesh of a label, the closest deciding) under the preset's fused
    score, and accept it when the score is within the threshold at ``far``.

    Raises
    ------
    InvalidInputError
        Not exactly one probe or one claim.
    NotFoundError
        The claimed mesh or label is not in the gallery.
    ConflictError
        The gallery is not calibrated (``not_calibrated``), or a mesh is not ready.
    """
    if (upload is None) == (mesh_id is None):
        raise InvalidInputError(
            "Send the mesh to verify either as a file (field 'file') or as an enrolled "
            "mesh's id (field 'mesh_id'), not both.",
            code="invalid_probe",
        )
    if (claim_id is None) == (claim_label is None):
        raise InvalidInputError(
            "Say what the mesh is claimed to be: an enrolled mesh's id (field 'claim_id') "
            "or a label (field 'claim_label'), one of the two.",
            code="invalid_claim",
        )
    preset = gallery.preset
    fit = calibration(state, gallery)
    if claim_id is not None:
        enrolled_mesh(session, gallery, claim_id)  # 404 for an unknown id
        targets = [claim_id]
    else:
        assert claim_label is not None
        targets = meshes.ids_with_label(session, gallery.collection_id, claim_label)
    if upload is not None:
        descriptor, *_ = upload_descriptor(session, state, gallery, upload, preset)
        probe = "upload"
    else:
        assert mesh_id is not None
        descriptor = stored_descriptor(session, gallery, mesh_id, preset)
        probe = f"mesh {mesh_id}"
        targets = [t for t in targets if t != mesh_id]
    scored = gallery.scores(descriptor, targets)
    if not scored:
        what = f"mesh {claim_id}" if claim_id is not None else f"label {claim_label!r}"
        raise NotFoundError(
            f"The gallery has no described shape for {what} to compare with"
            + (" (other than the probe itself)." if mesh_id is not None else "."),
            code="claim_not_found",
        )
    matched, (score, scores) = min(scored.items(), key=lambda item: (item[1][0], item[0]))
    row = fit.rows[FUSED]
    threshold = row.threshold_at(far)
    estimated_far, estimated_frr = row.rates_at(threshold)
    return Verification(
        same=bool(score <= threshold),
        score=score,
        scores=scores,
        threshold=threshold,
        far=far,
        estimated_far=estimated_far,
        estimated_frr=estimated_frr,
        confidence=float(row.confidence(score)),
        matched_id=matched,
        candidates=len(scored),
        probe=probe,
        calibration=fit,
    )
