"""From a mesh file to the paper's descriptors, with per-stage timings."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .denoise import denoised, view_denoised
from .descriptor import ONE_VIEW_FACING, ShapeDescriptor
from .diffusion import (
    LaplaceBeltrami,
    averaged_mass_eigenpairs,
    in_diffusion_time_units,
    laplace_beltrami_eigenpairs,
    normalized_spectrum,
    surface_eigenpairs,
)
from .formats import DEFAULT_MAX_FACES
from .geodesic import farthest_point_samples, geodesic_distance_matrix, sample_distances
from .holes import (
    boundary_loops,
    close_small_holes,
    facing_share,
    longest_open_loop,
    sheets_apart,
    two_sided,
)
from .intrinsic import surface_operators
from .mesh_io import (
    CANONICAL_AREA,
    CleanedMesh,
    Mesh,
    canonical_frame,
    clean_surface,
    face_areas,
    read_mesh,
)
from .modal import (
    core_diagonal,
    ddt_core,
    modal_gdm,
    slice_singular_values,
    small_ddt,
    voronoi_areas,
)
from .parts import (
    ball_profiles,
    boundary_reach,
    grid_radii,
    with_centroids,
)
from .presets import Preset
from .resample import resample_mesh
from .scans import grid_sight, unshadowed
from .surface_points import ANCHOR_VOXEL, VIEW_VOXEL, gridded_surface


def resampled_surface(mesh: Mesh, preset: Preset, *, resampled: bool = False) -> Mesh:
    """The mesh every descriptor of ``mesh`` is computed on: a range scan's shortcuts left
    out (:func:`without_grid_shortcuts`), in its canonical frame
    (:func:`~worker.engine.mesh_io.canonical_frame`), its small holes closed if the
    preset says so (:func:`~worker.engine.holes.close_small_holes`), resampled to the
    preset's vertex count, its edges bounded if the preset says so, a single view made
    two-sided if the preset says so (:func:`~worker.engine.holes.two_sided`); only moved
    to its canonical frame when it is ``resampled`` already (:func:`describe_mesh`)."""
    if resampled:
        return canonical_frame(mesh)
    surface = canonical_frame(without_grid_shortcuts(mesh).mesh)
    return _resampled(surface, preset, facing_share(surface))


def _resampled(surface: Mesh, preset: Preset, facing: float) -> Mesh:
    """:func:`resampled_surface` of a surface already in its canonical frame that faces
    one way by the share ``facing`` (:func:`~worker.engine.holes.facing_share`): a single
    view made two-sided if the preset says so."""
    if preset.max_hole_perimeter is not None:
        surface = close_small_holes(surface, preset.max_hole_perimeter, CANONICAL_AREA)
    if _made_two_sided(preset, facing):
        # Each sheet half the vertices, so the operators' cost stays the preset's.
        return two_sided(resample_mesh(surface, preset.n_vertices // 2, preset.max_edge))
    return resample_mesh(surface, preset.n_vertices, preset.max_edge)


def _made_two_sided(preset: Preset, facing: float) -> bool:
    """Whether a surface facing one way by the share ``facing`` is described as
    :func:`~worker.engine.holes.two_sided` (a single view, with a preset that says so)."""
    return preset.two_sided_views and facing >= ONE_VIEW_FACING


def parts_descriptor(
    resampled: Mesh,
    samples: np.ndarray,
    sample_distances: np.ndarray,
    vertex_areas: np.ndarray,
    preset: Preset,
) -> tuple[np.ndarray, np.ndarray]:
    """The parts modality (:mod:`~worker.engine.parts`) of a resampled surface in its
    canonical frame, from the GDM's sample distances.

    Its radii are in square roots of the resampled surface's own area, not the file's
    (the canonical frame's): a noisy file's area is crumpled (at noise of 0.5% of its
    diagonal, 1.2 to 14 times its resampled surface's on TOSCA), and the file's would
    scale the radii by the noise instead of the shape.

    Returns
    -------
    profiles : (m, C) float16, log geodesic-ball area profiles on the preset's grid,
        followed by their balls' centroid profiles when the preset compares them
        (:func:`~worker.engine.parts.with_centroids`, (m, 2C)).
    reach : (m,) float, each sample's distance to the open boundary, in square roots of
        the area (``inf`` when the surface is closed).
    """
    unit = float(np.sqrt(vertex_areas.sum()))
    radii = grid_radii(preset)
    first = radii[0] * unit
    positions = resampled.vertices if preset.parts_centroid_radii else None
    profiles, centroids = ball_profiles(
        sample_distances, vertex_areas, first, len(radii), positions, samples
    )
    profiles = with_centroids(profiles, centroids)
    loops = boundary_loops(resampled)
    boundary = np.unique(np.concatenate([loops.start, loops.end]))
    return profiles.astype(np.float16), boundary_reach(sample_distances, boundary) / unit


def ddt_descriptor(
    eigenvalues: np.ndarray,
    eigenvectors: np.ndarray,
    preset: Preset,
    mass: np.ndarray | None,
    coordinates: np.ndarray | None = None,
) -> np.ndarray:
    """The DDT modality of eq. (4)'s eigenpairs (eigenfunctions ``eigenvectors`` or
    ``eigenvectors @ coordinates``, :func:`~worker.engine.modal.small_ddt`), as the
    preset's ``ddt_elements`` say: the HOSVD core (eqs. 5-7), its diagonal, or each
    slice's singular values."""
    times = preset.diffusion_times
    normalize = preset.normalize_scale
    if preset.ddt_elements == "slice_values":
        tensor = small_ddt(eigenvalues, eigenvectors, times, mass, coordinates, normalize)
        return slice_singular_values(tensor, min(preset.ddt_core_shape[:2]))
    core = ddt_core(
        eigenvalues,
        eigenvectors,
        times,
        preset.ddt_core_shape,
        mass,
        mix_times=preset.ddt_mix_times,
        coordinates=coordinates,
        normalize=normalize,
    )
    return core_diagonal(core) if preset.ddt_elements == "diagonal" else core


def without_grid_shortcuts(mesh: Mesh) -> CleanedMesh:
    """A range scan triangulated as an orthographic depth grid without the triangles that
    run along its line of sight over an occlusion gap (:func:`~.scans.grid_sight`,
    :func:`~.scans.unshadowed`: the rule a depth camera's organized cloud is read by), its
    largest piece and that piece's share of the rest; any other mesh as it is (share 1)."""
    sight = grid_sight(mesh.vertices, mesh.faces)
    kept = None if sight is None else unshadowed(mesh.vertices, mesh.faces, sight=sight)
    if kept is None or kept.all():
        return CleanedMesh(mesh, 1.0)
    return clean_surface(mesh.vertices, mesh.faces[kept])


def described_area(described: Mesh, two_sided_view: bool) -> float:
    """The area of the surface a descriptor is computed on, in the canonical frame: the
    size (:attr:`~worker.engine.descriptor.ShapeDescriptor.area`) once in the file's
    units. One sheet of a view made two-sided.

    Not the file's own area: noise crumples a fine surface, its resampling hardly (TOSCA's
    copies at noise of 0.5% of the diagonal: a median 6.0 times their source's area, their
    resampling 1.064 times; docs/decisions.md, "Default v13")."""
    area = float(face_areas(described.vertices, described.faces).sum())
    return area / 2 if two_sided_view else area


def describe_mesh(mesh: Mesh, preset: Preset, *, resampled: bool = False) -> ShapeDescriptor:
    """Compute all modalities of a cleaned mesh, and record its area (the size).

    Stages (timed): ``resample``, ``gdm`` (intrinsic Delaunay, heat-method GDM),
    ``eigen_ddt`` (eq. 3 eigenpairs and the DDT's modal representation), ``modal``
    (GDM singular values), ``parts`` (the parts modality, when the preset has it),
    ``surface`` (the surface gridded for rigid verification).

    Parameters
    ----------
    mesh : a cleaned mesh, in the file's units.
    preset : the parameters.
    resampled : the mesh is already the preset's resampling (one resampling of a figure
        carried to its poses, :func:`~worker.engine.resample.carry_resampling`): it is
        described as it is, only moved to its canonical frame.
    """
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[stage] = now - clock
        clock = now

    # A range scan's shortcuts are no surface. Everything below is in the canonical
    # frame, the file's area scaled to CANONICAL_AREA.
    scanned = CleanedMesh(mesh, 1.0) if resampled else without_grid_shortcuts(mesh)
    surface = canonical_frame(scanned.mesh)
    facing = facing_share(surface)
    two_sided_view = not resampled and _made_two_sided(preset, facing)
    # Any other surface rough with a sensor's noise is described smoothed of it (a view
    # is smoothed only where it is gridded, below).
    smooth = preset.smooth_noise and not (resampled or two_sided_view)
    source = denoised(scanned.mesh) if smooth else scanned.mesh
    if source is not scanned.mesh:
        surface = canonical_frame(source)
    file_area = float(face_areas(source.vertices, source.faces).sum())
    open_loop = longest_open_loop(surface, CANONICAL_AREA)
    described = surface if resampled else _resampled(surface, preset, facing)
    area = described_area(described, two_sided_view) * file_area / CANONICAL_AREA
    lap("resample")
    intrinsic, ops = surface_operators(described.vertices, described.faces)
    on_surface = preset.measure == "surface"
    mass = ops.vertex_areas if on_surface else None
    heat_reference = preset.n_vertices if on_surface else None
    sample_areas = None
    if preset.gdm_samples is None:
        gdm = geodesic_distance_matrix(intrinsic, ops, preset.heat_time_factor, heat_reference)
    else:
        spread = sheets_apart(described) if two_sided_view else described.vertices
        samples = farthest_point_samples(spread, preset.gdm_samples, ops.vertex_areas)
        gdm = sample_distances(intrinsic, ops, samples, preset.heat_time_factor, heat_reference)
        sample_areas = voronoi_areas(gdm, ops.vertex_areas)
    lap("gdm")
    op = LaplaceBeltrami.from_fem(ops)
    eigenvalues, eigenvectors = laplace_beltrami_eigenpairs(op, preset.n_eigenpairs)
    # The averaged mass's Ritz pairs, for the spectrum and the DDT that ask for them.
    averaged = None
    if "averaged" in (preset.spectrum_mass, preset.ddt_mass):
        ritz_values, coordinates = averaged_mass_eigenpairs(
            op, intrinsic, ops, eigenvalues, eigenvectors
        )
        averaged = ritz_values * op.total_area, coordinates  # lambda_FEM * area
    if mass is None:  # eq. (4) with the paper's A and time unit
        ddt = ddt_descriptor(eigenvalues, eigenvectors, preset, None)
    else:
        values, functions = surface_eigenpairs(op, eigenvalues, eigenvectors, preset.n_vertices)
        if averaged is not None and preset.ddt_mass == "averaged":
            values = in_diffusion_time_units(averaged[0], preset.n_vertices)
            ddt = ddt_descriptor(values, functions, preset, mass, averaged[1])
        else:
            ddt = ddt_descriptor(values, functions, preset, mass)
    if averaged is not None and preset.spectrum_mass == "averaged":
        spectrum = averaged[0][1 : preset.spectrum_size + 1]
    else:
        spectrum = normalized_spectrum(op, eigenvalues, preset.spectrum_size)
    lap("eigen_ddt")
    singular_values = modal_gdm(
        gdm, preset.gdm_singular_values, mass, sample_areas, preset.normalize_scale
    )
    if not preset.normalize_scale:
        # Sec. 4.1: distances in the file's length unit, not the canonical frame's.
        singular_values = singular_values * np.sqrt(file_area / CANONICAL_AREA)
    lap("modal")
    parts, reach = np.zeros((0, 0), dtype=np.float16), np.zeros(0)
    if preset.has_parts:
        parts, reach = parts_descriptor(described, samples, gdm, ops.vertex_areas, preset)
        lap("parts")
    # In the file's frame: the canonical one may be a mirror image, which no rigid motion
    # undoes. A view is wound toward its sensor, and smoothed of its sensor's noise when
    # it shows any; anything else (smoothed above) is turned outward.
    voxel = VIEW_VOXEL if two_sided_view else ANCHOR_VOXEL
    gridded = view_denoised(scanned.mesh) if two_sided_view else source
    grid, unit = gridded_surface(gridded, 2 if two_sided_view else 1, voxel, two_sided_view)
    lap("surface")
    return ShapeDescriptor(
        preset=preset.name,
        preset_version=preset.version,
        gdm=singular_values,
        ddt=ddt,
        spectrum=spectrum,
        input_vertices=mesh.n_vertices,
        input_faces=mesh.n_faces,
        vertices=described.n_vertices,
        timings=timings,
        parts=parts,
        parts_reach=reach,
        longest_open_loop=open_loop,
        area=area,
        facing_share=facing,
        kept_area_fraction=scanned.kept_area_fraction if scanned.mesh is not mesh else None,
        surface=grid,
        surface_unit=unit,
        surface_voxel=voxel,
        surface_smoothed=gridded is not scanned.mesh,
    )


def describe_file(
    source: str | Path | bytes,
    preset: Preset,
    filename: str | None = None,
    *,
    max_faces: int = DEFAULT_MAX_FACES,
) -> ShapeDescriptor:
    """Load, clean and describe a mesh file (path, or bytes plus its file name).

    Raises
    ------
    worker.engine.errors.MeshError
        When the file cannot be described; its ``message`` is for the user.
    """
    return load_and_describe(source, preset, filename, max_faces=max_faces)[1]


def load_and_describe(
    source: str | Path | bytes,
    preset: Preset,
    filename: str | None = None,
    *,
    max_faces: int = DEFAULT_MAX_FACES,
) -> tuple[Mesh, ShapeDescriptor]:
    """:func:`describe_file`, also returning the cleaned mesh (for what else is made
    of it, such as previews, without reading the file twice)."""
    start = time.perf_counter()
    cleaned = read_mesh(source, filename, max_faces=max_faces)
    load_seconds = time.perf_counter() - start
    descriptor = describe_mesh(cleaned.mesh, preset)
    # Of the file's surface: a range scan's shortcuts may leave pieces apart (describe_mesh).
    descriptor.kept_area_fraction = cleaned.kept_area_fraction * (
        descriptor.kept_area_fraction or 1.0
    )
    if cleaned.cloud is not None:
        descriptor.input_points = cleaned.cloud.points
        descriptor.input_grid = cleaned.cloud.grid
        descriptor.input_support = cleaned.cloud.support
        descriptor.input_hidden = cleaned.cloud.hidden
    descriptor.timings = {"load": load_seconds, **descriptor.timings}
    descriptor.timings["total"] = sum(descriptor.timings.values())
    return cleaned.mesh, descriptor
