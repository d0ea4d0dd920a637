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

from .presets import MODALITIES, PARTS, SIZE

#: A surface facing one way this much (:func:`worker.engine.holes.facing_share`) is one
#: view of its object (a height field over the view: the faces a camera sees), not a cut
#: or a holed copy of a whole (at most 0.89 of the partiality protocol's cut-30 copies of
#: TOSCA and SCAPE, its single views at least 0.998).
ONE_VIEW_FACING = 0.95

#: Every array a descriptor stores: the vector modalities, the parts and their reach, and
#: the gridded surface.
ARRAYS = (*MODALITIES, PARTS, "parts_reach", "surface")


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
        :func:`~worker.engine.mesh_io.read_mesh`; or a range scan's pieces its shortcuts
        joined, :func:`~worker.engine.pipeline.without_grid_shortcuts`); None when the
        mesh did not come from a file and kept every piece, or for a descriptor stored
        before this was recorded.
    parts : (m, C) float16, the parts modality (:mod:`~worker.engine.parts`): each
        sample's log geodesic-ball area profile on the preset's grid of radii, at half
        precision (its rounding, under 0.004, is far below the differences compared);
        (0, 0) when the preset has none.
    parts_reach : (m,) float, each sample's geodesic distance to the surface's open
        boundary in square roots of its area (``inf`` on a closed surface).
    longest_open_loop : the described surface's longest open boundary loop before its
        small holes were closed, in square roots of its area (0 when closed;
        :func:`~worker.engine.holes.longest_open_loop`): how partial it looks. None for
        a descriptor stored before this was recorded.
    area : the described surface's area in the file's own units (squared), measured on
        its resampling (one sheet of a view made two-sided;
        :func:`~worker.engine.pipeline.described_area`): the size modality
        (:data:`~worker.engine.presets.SIZE`). None for a descriptor stored before this
        was recorded.
    input_points, input_grid : when the file was a point cloud (triangulated as
        :mod:`~worker.engine.scans` reads one view), its points that saw the surface, and
        its grid (width, height) when it was organized (a depth camera's PCD or a laser
        scanner's structured E57 scan, triangulated by it); None for a mesh.
    input_support : of an organized cloud, the points of the floor, table or wall its
        object stood on or against, left out (:func:`~worker.engine.scans.without_support`);
        None for a mesh or a cloud without a grid.
    input_hidden : of a cloud that was not one view (a whole object's), the points hidden
        from where it was seen, left out (:func:`~worker.engine.scans.whole_view`); None
        for a mesh or one view.
    facing_share : the largest share of the described surface's area whose faces face
        one direction (:func:`~worker.engine.holes.facing_share`): about a half for a
        whole, a cut or a holed copy, near 1 for one view of a scanner. None for a
        descriptor stored before this was recorded.
    surface : (m, 6) float16, the file's surface as points with normals on a grid
        (:func:`~worker.engine.surface_points.gridded_surface`), for rigid verification
        (:mod:`~worker.engine.rigid`); (0, 6) for a descriptor stored before it was kept.
    surface_unit, surface_voxel : the grid's unit in the file's length unit, and its
        spacing in units; None with no surface.
    surface_smoothed : whether the surface was smoothed of a sensor's noise: a whole, cut
        or holed surface before it was described (:func:`~worker.engine.denoise.denoised`),
        a single view before it was gridded (:func:`~worker.engine.denoise.view_denoised`);
        None for a descriptor stored before this was recorded.
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
    parts: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.float16))
    parts_reach: np.ndarray = field(default_factory=lambda: np.zeros(0))
    longest_open_loop: float | None = None
    area: float | None = None
    input_points: int | None = None
    input_grid: tuple[int, int] | None = None
    input_support: int | None = None
    input_hidden: int | None = None
    facing_share: float | None = None
    surface: np.ndarray = field(default_factory=lambda: np.zeros((0, 6), dtype=np.float16))
    surface_unit: float | None = None
    surface_voxel: float | None = None
    surface_smoothed: bool | None = None

    @property
    def single_view(self) -> bool:
        """Whether it is one view of its object: a point cloud (read as one view), or a
        surface facing one way (:data:`ONE_VIEW_FACING`)."""
        if self.input_points is not None:
            return True
        return self.facing_share is not None and self.facing_share >= ONE_VIEW_FACING

    def vector(self, modality: str) -> np.ndarray:
        """The modality as the flat vector that eqs. (8) and (9) compare: one of
        :data:`~worker.engine.presets.MODALITIES`, or the size, ``[sqrt(area)]`` (1,),
        a length in the file's unit.

        Raises
        ------
        KeyError
            An unknown modality.
        ValueError
            The size of a descriptor stored before its area was recorded.
        """
        if modality == SIZE:
            if self.area is None:
                raise ValueError(
                    "this descriptor was stored before its surface's area was recorded: "
                    "describe the mesh again to compare its size"
                )
            return np.array([np.sqrt(self.area)])
        if modality not in MODALITIES:
            raise KeyError(f"unknown modality {modality!r}")
        return np.ravel(getattr(self, modality))

    def to_json(self) -> dict[str, Any]:
        out = self._meta()
        for name in ARRAYS:
            array = np.asarray(getattr(self, name), dtype=np.float64)
            values = [None if np.isinf(x) else x for x in array.ravel().tolist()]
            out[name] = {"shape": list(array.shape), "values": values}
        return out

    def _meta(self) -> dict[str, Any]:
        """Everything but the arrays."""
        return {
            "preset": self.preset,
            "preset_version": self.preset_version,
            "input_vertices": self.input_vertices,
            "input_faces": self.input_faces,
            "vertices": self.vertices,
            "timings": self.timings,
            "kept_area_fraction": self.kept_area_fraction,
            "longest_open_loop": self.longest_open_loop,
            "area": self.area,
            "input_points": self.input_points,
            "input_grid": None if self.input_grid is None else list(self.input_grid),
            "input_support": self.input_support,
            "input_hidden": self.input_hidden,
            "facing_share": self.facing_share,
            "surface_unit": self.surface_unit,
            "surface_voxel": self.surface_voxel,
            "surface_smoothed": self.surface_smoothed,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ShapeDescriptor:
        arrays = {
            name: np.asarray(
                [np.inf if x is None else x for x in data[name]["values"]], dtype=np.float64
            ).reshape(data[name]["shape"])
            for name in ARRAYS
            if name in data
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
            # Descriptors stored before the parts modality have none.
            parts=np.asarray(arrays.get("parts", np.zeros((0, 0))), dtype=np.float16),
            parts_reach=np.asarray(arrays.get("parts_reach", np.zeros(0)), dtype=np.float64),
            longest_open_loop=meta.get("longest_open_loop"),
            area=meta.get("area"),
            input_points=meta.get("input_points"),
            input_grid=None if (grid := meta.get("input_grid")) is None else (grid[0], grid[1]),
            input_support=meta.get("input_support"),
            input_hidden=meta.get("input_hidden"),
            facing_share=meta.get("facing_share"),
            # Descriptors stored before the surface was kept have none.
            surface=np.asarray(arrays.get("surface", np.zeros((0, 6))), dtype=np.float16).reshape(
                -1, 6
            ),
            surface_unit=meta.get("surface_unit"),
            surface_voxel=meta.get("surface_voxel"),
            surface_smoothed=meta.get("surface_smoothed"),
        )

    def to_npz_bytes(self) -> bytes:
        buffer = io.BytesIO()
        np.savez(
            buffer,
            meta=np.array(json.dumps(self._meta())),
            **{name: getattr(self, name) for name in ARRAYS},
        )
        return buffer.getvalue()

    @classmethod
    def from_npz_bytes(cls, data: bytes) -> ShapeDescriptor:
        with np.load(io.BytesIO(data)) as npz:
            meta = json.loads(str(npz["meta"]))
            arrays = {name: np.array(npz[name]) for name in ARRAYS if name in npz}
        return cls._from_parts(meta, arrays, meta.get("timings", {}))
