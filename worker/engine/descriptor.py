"""The modal descriptors of one shape (:class:`ShapeDescriptor`), what every room passes
around: made by :mod:`.pipeline`, stored by the service and the evaluation cache as npz
bytes or JSON, compared by :mod:`.compare`."""

from __future__ import annotations

import io
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .presets import MODALITIES


@dataclass
class ShapeDescriptor:
    """The modal descriptors of one shape and how they were made.

    Attributes
    ----------
    preset, preset_version : the preset that made it.
    gdm : (k,) float, largest singular values of the normalized GDM.
    ddt : float, the normalized DDT's modal representation (:func:`ddt_descriptor`):
        its |HOSVD core| (r1, r2, r3), or (r, s) values per diffusion time.
    spectrum : (s,) float, area-normalized Laplace-Beltrami eigenvalues.
    input_vertices, input_faces : size of the cleaned upload.
    vertices : size after resampling.
    timings : seconds per stage.
    kept_area_fraction : the described part's share of the file's surface area (below 1
        when the file has other, separate parts, which are left out;
        :func:`~worker.engine.mesh_io.read_mesh`); None when the mesh did not come from
        a file, or for a descriptor stored before this was recorded.
    """

    preset: str
    preset_version: int
    gdm: np.ndarray
    ddt: np.ndarray
    spectrum: np.ndarray
    input_vertices: int
    input_faces: int
    vertices: int
    timings: dict[str, float] = field(default_factory=dict)
    kept_area_fraction: float | None = None

    def vector(self, modality: str) -> np.ndarray:
        """The modality as the flat vector that eqs. (8) and (9) compare."""
        if modality not in MODALITIES:
            raise KeyError(f"unknown modality {modality!r}")
        return np.ravel(getattr(self, modality))

    def to_json(self) -> dict[str, Any]:
        out = {
            "preset": self.preset,
            "preset_version": self.preset_version,
            "input_vertices": self.input_vertices,
            "input_faces": self.input_faces,
            "vertices": self.vertices,
            "timings": self.timings,
            "kept_area_fraction": self.kept_area_fraction,
        }
        for name in MODALITIES:
            array = getattr(self, name)
            out[name] = {"shape": list(array.shape), "values": array.ravel().tolist()}
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ShapeDescriptor:
        arrays = {
            name: np.asarray(data[name]["values"], dtype=np.float64).reshape(data[name]["shape"])
            for name in MODALITIES
        }
        return cls._from_parts(data, arrays, dict(data.get("timings", {})))

    @classmethod
    def _from_parts(
        cls, meta: Mapping[str, Any], arrays: Mapping[str, np.ndarray], timings: dict[str, float]
    ) -> ShapeDescriptor:
        """From the metadata fields, modality -> array, and the stage timings."""
        return cls(
            preset=meta["preset"],
            preset_version=meta["preset_version"],
            gdm=arrays["gdm"],
            ddt=arrays["ddt"],
            spectrum=arrays["spectrum"],
            input_vertices=meta["input_vertices"],
            input_faces=meta["input_faces"],
            vertices=meta["vertices"],
            timings=timings,
            kept_area_fraction=meta.get("kept_area_fraction"),
        )

    def to_npz_bytes(self) -> bytes:
        buffer = io.BytesIO()
        meta = {k: v for k, v in self.to_json().items() if k not in MODALITIES}
        np.savez(
            buffer,
            meta=np.array(json.dumps(meta)),
            **{name: getattr(self, name) for name in MODALITIES},
        )
        return buffer.getvalue()

    @classmethod
    def from_npz_bytes(cls, data: bytes) -> ShapeDescriptor:
        with np.load(io.BytesIO(data)) as npz:
            meta = json.loads(str(npz["meta"]))
            arrays = {name: np.array(npz[name]) for name in MODALITIES}
        return cls._from_parts(meta, arrays, meta.get("timings", {}))
