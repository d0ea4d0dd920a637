"""Response models of GET /calibration and POST /verify."""

from __future__ import annotations

from pydantic import BaseModel, Field


class OperatingPoint(BaseModel):
    far: float = Field(description="the false acceptance rate asked for")
    threshold: float = Field(description="accept a pair whose score is at most this")
    estimated_far: float = Field(description="FAR at that threshold on the labelled pairs")
    estimated_frr: float = Field(description="false rejection rate there")


class ScoreCalibration(BaseModel):
    eer: float = Field(description="equal error rate")
    operating_points: list[OperatingPoint]


class RocOut(BaseModel):
    far: list[float]
    frr: list[float]


class CalibrationOut(BaseModel):
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


class VerificationOut(BaseModel):
    same: bool = Field(description="the score is within the threshold at the FAR asked for")
    score: float = Field(description="the preset's fused dissimilarity to the claim")
    scores: dict[str, float] = Field(description="per-modality dissimilarities")
    threshold: float
    far: float = Field(description="the false acceptance rate asked for")
    estimated_far: float = Field(description="FAR at the threshold, on the labelled pairs")
    estimated_frr: float = Field(description="FRR at the threshold, on the labelled pairs")
    confidence: float = Field(description="probability of the same label at this score")
    matched_id: int = Field(description="the enrolled mesh compared (the closest of a label)")
    candidates: int = Field(description="enrolled meshes of the claim compared")
    probe: str = Field(description="'upload' or 'mesh <id>'")
    trusted: bool = Field(description="whether the calibration meets its trust rule")
