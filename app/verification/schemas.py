"""Response models of GET /calibration and POST /verify."""

from __future__ import annotations

from pydantic import BaseModel, Field

from ..schemas import THRESHOLD_DESCRIPTION


class OperatingPoint(BaseModel):
    far: float = Field(description="the false acceptance rate asked for")
    threshold: float | None = Field(description=THRESHOLD_DESCRIPTION)
    estimated_far: float = Field(description="FAR at that threshold on the labelled pairs")
    estimated_frr: float = Field(description="false rejection rate there")


class ScoreCalibration(BaseModel):
    eer: float = Field(description="equal error rate")
    operating_points: list[OperatingPoint]


class RocOut(BaseModel):
    far: list[float]
    frr: list[float]


class RecognitionScores(BaseModel):
    eer: float = Field(description="equal error rate")
    nn: float = Field(description="nearest-neighbour rate")
    map: float = Field(description="mean average precision")


class FusionFold(BaseModel):
    held_out_shapes: int
    weights: dict[str, float] = Field(description="chosen on the other folds' shapes")
    comparisons: dict[str, str] = Field(description="each modality's comparison, chosen with them")
    held_out: RecognitionScores = Field(description="those weights on this fold's shapes")
    preset: RecognitionScores = Field(description="the preset's weights on the same shapes")


class AdoptionOut(BaseModel):
    gain: float = Field(
        description="mean over the folds of the preset's loss (mean of EER and 1 - mAP) "
        "minus the learned choice's"
    )
    statistic: float | None = Field(
        description="the gain's corrected resampled t statistic (null: every fold gained "
        "the same, so the gain has no spread)"
    )
    critical: float = Field(description="Student's one-sided quantile it must exceed")
    confidence: float
    adopted: bool


class FusionOut(BaseModel):
    weights: dict[str, float] = Field(description="the weights the gallery fuses with")
    comparisons: dict[str, str] = Field(
        description="each modality's comparison: D1 (eq. 8), D2 (eq. 9), reweighted "
        "euclidean (ShapeDNA's, the spectrum) or the size's"
    )
    source: str = Field(
        description="preset, pinned (SHAPES_FUSION_WEIGHTS or the collection's) or learned"
    )
    reason: str = Field(description="why these weights, in a sentence")
    preset_weights: dict[str, float]
    preset_comparisons: dict[str, str]
    labelled_shapes: int = Field(description="labelled shapes learned on (0: none)")
    labels: int
    sampled: bool = Field(description="learned on a stratified sample of the labelled shapes")
    folds: list[FusionFold] = Field(
        description="the cross-validation, fold by fold: each round's folds in turn"
    )
    rounds: int = Field(description="rounds of the folds, each dealt from its own seed (0: none)")
    held_out: RecognitionScores | None = Field(
        description="the folds' choices on their held-out shapes (mean over the folds)"
    )
    preset_held_out: RecognitionScores | None = Field(
        description="the preset's weights on the same held-out shapes"
    )
    adoption: AdoptionOut | None = Field(
        description="the test of the folds' gain: the learned fusion is used when it passes"
    )
    fitted_at: float


class HistogramOut(BaseModel):
    edges: list[float] = Field(description="bin edges of the fused score, even on a log scale")
    genuine: list[int] = Field(description="pairs of the same label in each bin")
    impostor: list[int] = Field(description="pairs of different labels in each bin")


class CalibrationOut(BaseModel):
    collection: str = Field(description="the collection whose pairs are calibrated")
    preset: str
    preset_version: int
    score: str = Field(description="the calibrated score: the preset's fused one")
    shapes: int = Field(description="described shapes in the gallery")
    labelled_shapes: int
    labels: int
    genuine_pairs: int = Field(description="pairs of shapes with the same label")
    impostor_pairs: int = Field(description="pairs with different labels")
    sampled: bool = Field(description="the pairs are a random sample (above the pair budget)")
    trusted: bool
    trust_rule: str
    eer: float
    operating_points: list[OperatingPoint]
    roc: RocOut = Field(description="FRR against FAR (at most 200 points)")
    modalities: dict[str, ScoreCalibration] = Field(description="each modality on its own")
    fitted_at: float = Field(description="Unix time of the fit (refitted after changes)")
    fusion: FusionOut = Field(description="the fusion weights the fused score uses, and why")
    histogram: HistogramOut = Field(
        description="how the genuine and the impostor pairs' fused scores spread: where the "
        "ROC says little (no error at any threshold), the gap between them still shows"
    )


class VerificationOut(BaseModel):
    same: bool = Field(description="the score is within the threshold at the FAR asked for")
    score: float = Field(description="the preset's fused dissimilarity to the claim")
    scores: dict[str, float] = Field(description="per-modality dissimilarities")
    threshold: float | None = Field(description=THRESHOLD_DESCRIPTION)
    far: float = Field(description="the false acceptance rate asked for")
    estimated_far: float = Field(description="FAR at the threshold, on the labelled pairs")
    estimated_frr: float = Field(description="FRR at the threshold, on the labelled pairs")
    confidence: float = Field(description="probability of the same label at this score")
    matched_id: int = Field(description="the enrolled mesh compared (the closest of a label)")
    candidates: int = Field(description="enrolled meshes of the claim compared")
    probe: str = Field(description="'upload' or 'mesh <id>'")
    trusted: bool = Field(description="whether the calibration meets its trust rule")
