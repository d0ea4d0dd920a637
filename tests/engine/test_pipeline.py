"""Whole-pipeline invariances (issue 2) with stated tolerances.

Differences are relative Euclidean: ``|a - b| / |a|`` per modality. Vertex order
and rigid motion leave the descriptor (numerically) unchanged; uniform scale and a
different resolution of the same surface change it by a few percent at most
(quadric decimation then picks other vertices); a genuinely different shape
changes it more than that.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np
import pytest
import trimesh
from conftest import (
    bent_cylinder,
    example,
    faceted_wire,
    helical_spring,
    random_rotation,
    with_a_far_half_copy,
)

from worker.engine.compare import mean_normalized_manhattan
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.mesh_io import (
    Mesh,
    clean_mesh,
    clean_surface,
    face_areas,
    load_mesh,
)
from worker.engine.pipeline import describe_file, describe_mesh
from worker.engine.presets import DEFAULT_PRESET, SIZE, Preset, get_preset
from worker.engine.scans import organized_surface
from worker.engine.surface_points import ANCHOR_VOXEL
from worker.evaluation.partial import far_viewpoint, grid_mesh, range_image
from worker.evaluation.samples import (
    DEPTH_DIRECTION,
    PARTIAL_SOURCE,
    depth_scan,
    pcd_bytes,
    sample_mesh,
)

pytestmark = pytest.mark.slow  # whole pipelines on the examples and generated meshes

MODALITIES = ("gdm", "ddt", "spectrum")
EXACT = 1e-6  # vertex permutation
RIGID = 1e-6  # rotation, translation and scale (the canonical frame removes them)
SAME_SURFACE = 0.03  # twice the resolution
AREA = 1e-12  # the recorded area against the mesh's, relative (one sum of the same terms)
RESAMPLED_AREA = 0.01  # a clean surface's resampling against the file's own area


def _difference(a: ShapeDescriptor, b: ShapeDescriptor, modality: str) -> float:
    x, y = a.vector(modality), b.vector(modality)
    return float(np.linalg.norm(x - y) / np.linalg.norm(x))


@pytest.fixture(scope="module")
def figure() -> Mesh:
    return load_mesh(example("quadruped-0"))


@pytest.fixture(scope="module")
def figure_descriptor(figure, small_preset) -> ShapeDescriptor:
    return describe_mesh(figure, small_preset)


def test_descriptor_shapes_and_record(figure, figure_descriptor, small_preset):
    d = figure_descriptor
    assert d.gdm.shape == (small_preset.gdm_singular_values,)
    assert d.ddt.shape == small_preset.ddt_core_shape
    assert d.spectrum.shape == (small_preset.spectrum_size,)
    assert (d.preset, d.preset_version) == (small_preset.name, small_preset.version)
    assert abs(d.vertices - small_preset.n_vertices) <= 0.03 * small_preset.n_vertices
    assert np.all(np.diff(d.gdm) <= 0) and np.all(d.ddt >= 0)
    assert set(d.timings) == {"resample", "gdm", "eigen_ddt", "modal", "surface"}
    # the file's surface gridded for rigid verification, in units of sqrt(its area)
    assert d.surface.dtype == np.float16 and d.surface.shape[1] == 6 and len(d.surface) > 1000
    area = face_areas(figure.vertices, figure.faces).sum()
    assert d.surface_voxel == ANCHOR_VOXEL and d.surface_unit == pytest.approx(np.sqrt(area))
    # centred, about a unit across (the quadruped is 1.6 units long)
    assert np.abs(d.surface[:, :3].astype(float).mean(axis=0)).max() < 0.05
    np.testing.assert_allclose(np.linalg.norm(d.surface[:, 3:].astype(float), axis=1), 1, atol=2e-3)


def test_vertex_permutation(figure, figure_descriptor, small_preset):
    perm = np.random.default_rng(0).permutation(figure.n_vertices)
    permuted = Mesh(figure.vertices[perm], np.argsort(perm)[figure.faces])
    d = describe_mesh(permuted, small_preset)
    for m in MODALITIES:
        assert _difference(figure_descriptor, d, m) <= EXACT


@pytest.mark.parametrize("scale", [1e-30, 0.2, 1.0, 5.0, 1e30])
def test_rigid_motion_and_scale(figure, figure_descriptor, small_preset, scale):
    """The canonical frame makes them exact: the same surface in other units or
    another orientation is the same descriptor (before it, quadric decimation picked
    other vertices: up to 3% at x5, 8% at 1e30)."""
    rng = np.random.default_rng(1)
    rotated = figure.vertices @ random_rotation(rng).T
    moved = Mesh((rotated + [3.0, -2.0, 7.0]) * scale, figure.faces)
    d = describe_mesh(moved, small_preset)
    for m in MODALITIES:
        assert _difference(figure_descriptor, d, m) <= RIGID


def test_same_surface_at_twice_the_resolution(figure, figure_descriptor, small_preset):
    finer = clean_mesh(*trimesh.remesh.subdivide(figure.vertices, figure.faces))
    assert finer.n_vertices > 3 * figure.n_vertices
    d = describe_mesh(finer, small_preset)
    for m in MODALITIES:
        assert _difference(figure_descriptor, d, m) <= SAME_SURFACE


def test_bent_cylinder_is_closer_than_a_different_shape(small_preset):
    def describe(t: trimesh.Trimesh) -> ShapeDescriptor:
        return describe_mesh(clean_mesh(t.vertices, t.faces), small_preset)

    straight = describe(bent_cylinder(0.0))
    bent = describe(bent_cylinder(1.5))
    capsule = describe(trimesh.creation.capsule(height=6.0, radius=1.2, count=[40, 40]))
    for m in MODALITIES:
        assert _difference(straight, bent, m) < _difference(straight, capsule, m)
    assert _difference(straight, bent, "gdm") < 0.05


def test_the_area_is_recorded_in_the_files_units(figure, figure_descriptor, small_preset):
    """The size is the described surface's area (its resampling) in the file's units:
    the same surface in other units has another size (and the same shape)."""
    area = float(face_areas(figure.vertices, figure.faces).sum())
    assert figure_descriptor.area == pytest.approx(area, rel=RESAMPLED_AREA)
    np.testing.assert_allclose(
        figure_descriptor.vector(SIZE), [np.sqrt(figure_descriptor.area)], rtol=AREA
    )
    doubled = describe_mesh(Mesh(2.0 * figure.vertices, figure.faces), small_preset)
    assert doubled.area == pytest.approx(4.0 * figure_descriptor.area, rel=RIGID)
    for m in MODALITIES:
        assert _difference(figure_descriptor, doubled, m) <= RIGID


def test_a_noisy_scan_keeps_its_size(figure, small_preset):
    """Noise crumples a fine surface, 8 times its area at a sigma of 0.5% of the diagonal
    on 40,000 vertices; the size is its resampling's, which stays the clean surface's."""
    fine = figure
    for _ in range(2):
        fine = clean_mesh(*trimesh.remesh.subdivide(fine.vertices, fine.faces))
    diagonal = float(np.linalg.norm(np.ptp(fine.vertices, axis=0)))
    shift = np.random.default_rng(0).normal(scale=0.005 * diagonal, size=fine.vertices.shape)
    noisy = Mesh(fine.vertices + shift, fine.faces)
    crumpled = (
        face_areas(noisy.vertices, noisy.faces).sum() / face_areas(fine.vertices, fine.faces).sum()
    )
    assert crumpled > 5
    clean = describe_mesh(fine, small_preset)
    assert describe_mesh(noisy, small_preset).area == pytest.approx(clean.area, rel=0.05)


def test_describe_file_records_the_area_of_the_part_it_describes(small_preset):
    """A file of two separate parts: the size is the kept part's, not the file's."""
    mesh, both = with_a_far_half_copy(example("quadruped-0"))
    d = describe_file(both, small_preset, "two.off")
    alone = describe_file(mesh.export(file_type="off").encode(), small_preset, "one.off")
    assert d.area == pytest.approx(alone.area, rel=RIGID)
    assert d.area == pytest.approx(mesh.area, rel=RESAMPLED_AREA)  # 4/5 of the file's


def test_a_descriptor_stored_before_the_area_has_no_size(figure_descriptor):
    old = figure_descriptor.to_json()
    del old["area"]
    restored = ShapeDescriptor.from_json(old)
    assert restored.area is None
    with pytest.raises(ValueError, match="describe the mesh again"):
        restored.vector(SIZE)
    with pytest.raises(KeyError, match="unknown modality"):
        restored.vector("colour")


def test_the_sec_4_1_preset_keeps_the_scale_and_the_surface_presets_do_not(figure):
    """Sec. 4.1 (``smeets2010-tosca``): the GDM's singular values are in the file's
    length unit, so a copy scaled by 2 has twice them, while the DDT (the paper's ``A``
    and time unit) is the same; the default's descriptors do not move. At few vertices
    to stay fast: the scale handling does not depend on them."""
    tosca = replace(get_preset("smeets2010-tosca"), n_vertices=400)
    default = replace(get_preset(DEFAULT_PRESET), n_vertices=400, gdm_samples=100)
    doubled = Mesh(2.0 * figure.vertices, figure.faces)
    one, two = describe_mesh(figure, tosca), describe_mesh(doubled, tosca)
    np.testing.assert_allclose(two.gdm, 2.0 * one.gdm, rtol=RIGID)
    assert _difference(one, two, "gdm") > 0.5
    assert _difference(one, two, "ddt") <= RIGID
    one, two = describe_mesh(figure, default), describe_mesh(doubled, default)
    for m in MODALITIES:
        assert _difference(one, two, m) <= RIGID


def test_descriptor_round_trips(figure_descriptor):
    partial = replace(figure_descriptor, kept_area_fraction=0.625)
    scanned = replace(
        figure_descriptor,
        input_points=1583,
        input_grid=(77, 56),
        input_support=2704,
        surface_smoothed=True,
    )
    for original in (figure_descriptor, partial, scanned):
        for restored in (
            ShapeDescriptor.from_json(original.to_json()),
            ShapeDescriptor.from_npz_bytes(original.to_npz_bytes()),
        ):
            for m in MODALITIES:
                np.testing.assert_array_equal(restored.vector(m), original.vector(m))
            assert restored.preset == original.preset
            assert restored.timings == original.timings
            assert restored.kept_area_fraction == original.kept_area_fraction
            assert restored.area == original.area
            assert restored.input_points == original.input_points
            assert restored.input_grid == original.input_grid
            assert restored.input_support == original.input_support
            assert restored.surface_smoothed == original.surface_smoothed
            np.testing.assert_array_equal(restored.vector(SIZE), original.vector(SIZE))
    # A descriptor stored before the kept share was recorded reads as not known.
    old = figure_descriptor.to_json()
    del old["kept_area_fraction"], old["input_points"], old["input_grid"]
    del old["input_support"], old["surface_smoothed"]
    restored = ShapeDescriptor.from_json(old)
    assert restored.kept_area_fraction is None and restored.surface_smoothed is None
    assert restored.input_points is None and restored.input_grid is None
    assert restored.input_support is None


def test_describe_file_times_every_stage(small_preset):
    d = describe_file(example("quadruped-1"), small_preset)
    assert list(d.timings) == ["load", "resample", "gdm", "eigen_ddt", "modal", "surface", "total"]
    assert d.timings["total"] == pytest.approx(sum(v for k, v in d.timings.items() if k != "total"))
    assert d.kept_area_fraction == 1.0  # one connected surface
    # A mesh, not a cloud.
    assert d.input_points is None and d.input_grid is None and d.input_support is None


def test_a_file_of_separate_parts_describes_its_largest_and_says_so(small_preset):
    """quadruped-0 with a far, smaller copy of itself in the same file: the quadruped is
    what is described (the same descriptor as its own file), and the descriptor says
    which share of the file's surface that is."""
    mesh, both = with_a_far_half_copy(example("quadruped-0"))
    d = describe_file(both, small_preset, "two.off")
    alone = describe_file(mesh.export(file_type="off").encode(), small_preset, "one.off")
    assert d.kept_area_fraction == pytest.approx(0.8, rel=1e-6)  # 1 / (1 + 0.5^2)
    for m in MODALITIES:
        assert _difference(d, alone, m) < 1e-6


def test_a_range_scan_written_as_a_mesh_describes_as_its_organized_cloud(small_preset):
    """SHREC'17 wrote its range scans as meshes, the depth grid triangulated with the
    shortcuts that span each occlusion gap: such a mesh is described without them, its
    largest piece, as the same scan read as a depth camera's organized cloud is."""
    mesh = load_mesh(example("quadruped-0"))
    # Seen from the front, along its body (a camera orbiting y): legs hide legs.
    points, direction, _ = range_image(mesh, np.random.default_rng(2), "y")
    as_mesh = grid_mesh(points)
    cloud = clean_surface(*organized_surface(points, far_viewpoint(mesh, direction)))
    assert as_mesh.n_faces > cloud.mesh.n_faces and cloud.kept_area_fraction < 0.95
    d = describe_mesh(as_mesh, small_preset)
    read_as_cloud = describe_mesh(cloud.mesh, small_preset)
    for m in MODALITIES:
        assert _difference(d, read_as_cloud, m) < EXACT
    assert d.area == pytest.approx(read_as_cloud.area, rel=AREA)
    assert d.kept_area_fraction == pytest.approx(cloud.kept_area_fraction, rel=1e-9)
    assert describe_mesh(mesh, small_preset).kept_area_fraction is None  # not a grid
    # Uploaded as a file (its coordinates as text): the share is of the file's surface.
    off = trimesh.Trimesh(as_mesh.vertices, as_mesh.faces, process=False).export(file_type="off")
    uploaded = describe_file(off.encode(), small_preset, "scan.off")
    assert uploaded.kept_area_fraction == pytest.approx(cloud.kept_area_fraction, rel=1e-6)


@pytest.mark.parametrize("frame", ["camera", "turned", "world", "turned, moved"])
def test_a_view_s_points_without_their_grid_describe_as_its_organized_cloud(frame):
    """The quadruped's left side seen by a depth camera (6,000 pixels on it): its points
    in another order, in the camera's frame, turned about the camera, or in the mesh's
    frame, turned, without the grid (an XYZ file, on its pixel lattice in a frame found
    from the points, :func:`~worker.engine.scans.sensor_axes`), describe as the organized
    cloud (a PCD) split along one or the other of its squares' diagonals (whichever way
    the lattice found is turned): nearer one of them than the two are to each other, in
    every modality of the default. The reading adds nothing to the scan's own
    tessellation noise. So too with each point moved a tenth of a pixel at random, near
    its lattice (:func:`~worker.engine.scans.snapped_steps`; Delaunay's triangulation of
    such points leaves out a fifth of the triangles, across gaps the noise opens)."""
    preset = get_preset(DEFAULT_PRESET)
    grid, viewpoint = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 6000)
    if frame == "turned, moved":
        pitch = np.nanmedian(np.linalg.norm(np.diff(grid, axis=1), axis=2))
        noise = np.random.default_rng(2).normal(scale=0.1 * pitch / np.sqrt(3), size=grid.shape)
        grid = grid + noise
    organized = describe_file(pcd_bytes(grid, viewpoint), preset, "scan.pcd")
    other_diagonals = describe_file(pcd_bytes(grid[:, ::-1].copy(), viewpoint), preset, "scan.pcd")
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    shuffled = seen[np.random.default_rng(0).permutation(len(seen))]
    if frame != "world":
        shuffled = shuffled - viewpoint
    if frame != "camera":
        shuffled = shuffled @ random_rotation(np.random.default_rng(1)).T
    xyz = "\n".join(f"{x!r} {y!r} {z!r}" for x, y, z in shuffled.tolist()).encode()
    points = describe_file(xyz, preset, "scan.xyz")
    assert points.input_points == organized.input_points and points.input_grid is None
    assert points.single_view and organized.single_view
    for m in MODALITIES:

        def distance(one: ShapeDescriptor, other: ShapeDescriptor, m: str = m) -> float:
            x, y = one.vector(m), other.vector(m)
            return float(mean_normalized_manhattan(x[None], y[None])[0, 0])

        nearer = min(distance(points, organized), distance(points, other_diagonals))
        assert nearer < distance(organized, other_diagonals), m


def _bumpy_ellipsoid(sphere: trimesh.Trimesh, axes=(3.0, 2.0, 1.0)) -> Mesh:
    """A smooth asymmetric surface, radial over a tessellated sphere."""
    unit = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    x, y, z = unit.T
    radius = 1.0 + 0.15 * np.sin(3 * x + 2 * y + 1.5 * z)
    return clean_mesh(unit * radius[:, None] * np.asarray(axes), sphere.faces)


def test_the_surface_measure_sees_the_surface_not_the_triangles():
    """Issue 9: one surface tessellated uniformly and densely at the poles (a UV
    sphere's fans of 128 needles) against a differently proportioned surface. The
    paper's vertex matrices move more with the tessellation than between the two
    surfaces; weighted by area, the GDM moves a twelfth as much. The spectrum with
    the averaged mass moves 0.0007 against 0.025 for the other surface (0.0039 with
    eq. (3)'s lumped mass)."""
    uniform = trimesh.creation.icosphere(subdivisions=5)
    polar = trimesh.creation.uv_sphere(count=[64, 128])

    def distance(preset, modality, a, b) -> float:
        x, y = describe_mesh(a, preset).vector(modality), describe_mesh(b, preset).vector(modality)
        return float(mean_normalized_manhattan(x[None], y[None])[0, 0])

    same = (_bumpy_ellipsoid(uniform), _bumpy_ellipsoid(polar))
    other = (_bumpy_ellipsoid(uniform), _bumpy_ellipsoid(uniform, (3.0, 1.7, 1.0)))
    surface, paper = get_preset("smeets2010-surface"), get_preset("smeets2010-shrec")
    assert distance(surface, "gdm", *same) < min(0.02, distance(surface, "gdm", *other) / 4)
    assert distance(surface, "ddt", *same) < distance(surface, "ddt", *other) / 4
    assert distance(surface, "spectrum", *same) < distance(surface, "spectrum", *other) / 20
    assert distance(paper, "gdm", *same) > distance(paper, "gdm", *other)


def described_cylinder(preset: Preset, height: float, sections: int) -> ShapeDescriptor:
    """trimesh's cylinder of radius 0.5 (a CAD export of ``sections`` strips), described."""
    c = trimesh.creation.cylinder(radius=0.5, height=height, sections=sections)
    return describe_mesh(clean_mesh(c.vertices, c.faces), preset)


def assert_facets_nearer(
    coarse: ShapeDescriptor, fine: ShapeDescriptor, other: ShapeDescriptor, share: float
) -> None:
    """In every modality the fine export is nearer its coarse one than ``share`` of the
    other shape's distance to it (D1)."""
    for modality in MODALITIES:
        x, y, z = (d.vector(modality)[None] for d in (coarse, fine, other))
        facets = float(mean_normalized_manhattan(x, y)[0, 0])
        assert facets < share * float(mean_normalized_manhattan(x, z)[0, 0]), modality


def test_a_cad_cylinder_is_its_cylinder_whatever_its_facets():
    """A CAD-style cylinder at 24 and at 96 strips against a cylinder a quarter
    taller: decimation left the strips' elements a quarter of the height long, and
    every modality moved with the facets as much as with the height (0.65, 0.70,
    1.87 of it); with the edges bounded, 0.14, 0.07, 0.10 at v8 and 0.15, 0.09, 0.14 at
    v9 (the 96 strips reach the vertex budget); 0.05, 0.02, 0.03 at v19 (the bound's
    further decimation no longer stalls on the split strips: 2,788 vertices)."""
    preset = get_preset("smeets2010-surface")
    cylinder = partial(described_cylinder, preset)

    coarse, fine, taller = cylinder(2.0, 24), cylinder(2.0, 96), cylinder(2.5, 48)
    for modality in MODALITIES:
        x, y, z = (d.vector(modality)[None] for d in (coarse, fine, taller))
        facets = float(mean_normalized_manhattan(x, y)[0, 0])
        height = min(mean_normalized_manhattan(x, z)[0, 0], mean_normalized_manhattan(y, z)[0, 0])
        assert facets < height / 4, modality


def test_a_finely_faceted_cad_cylinder_is_its_coarse_exports_cylinder():
    """2,048 strips, as a fine chordal tolerance exports a cylinder, against 48 and a
    cylinder a quarter taller: decimation could not thin the slivers and every modality
    moved with the facets more than with the height (1.18, 2.65, 8.4 of it, at 10,000
    vertices). Thinned from its clustered vertices: 0.13, 0.25, 0.30."""
    preset = get_preset("smeets2010-surface")
    cylinder = partial(described_cylinder, preset)

    coarse, fine, taller = cylinder(2.0, 48), cylinder(2.0, 2048), cylinder(2.5, 48)
    assert fine.vertices <= 1.5 * preset.n_vertices
    assert_facets_nearer(coarse, fine, taller, 0.5)


def test_a_finely_faceted_thin_wire_is_its_coarse_exports_wire():
    """A spring of wire about two tiling edges thick, 1,024 sides against 24 and a spring
    of 3.5 turns: the fine one's slivers stalled the decimation, and clustered in cubes of
    one tiling edge its wire folded (0.93 of the area), so it was described at all its
    37,890 vertices, every modality as far from the coarse one as the other spring or
    farther (0.109, 0.062, 0.483 against 0.077, 0.083, 0.153). Clustered in cubes of half
    one: 0.016, 0.019, 0.032."""
    preset = get_preset("smeets2010-surface")

    def spring(turns: float, sides: int) -> ShapeDescriptor:
        return describe_mesh(clean_mesh(*faceted_wire(turns, sides)), preset)

    coarse, fine, longer = spring(3.0, 24), spring(3.0, 1024), spring(3.5, 24)
    assert fine.vertices <= 1.25 * preset.n_vertices
    assert_facets_nearer(coarse, fine, longer, 0.5)


def test_a_single_view_describes_as_its_whole_when_its_far_side_mirrors_its_near_one():
    """An ellipsoid's upper half, as a camera above it sees it: two-sided (the default),
    every modality within a tenth of the ellipsoid's distance to a narrower one (GDM
    0.007, DDT 0.011, spectrum 0.003 against 0.082, 0.191, 0.040); described as it is, each
    farther from its whole than the narrower ellipsoid (0.27, 0.43, 0.21)."""
    sphere = trimesh.creation.icosphere(subdivisions=5)
    whole = clean_mesh(sphere.vertices * [3.0, 2.0, 1.0], sphere.faces)
    other = clean_mesh(sphere.vertices * [3.0, 1.7, 1.0], sphere.faces)
    view = clean_mesh(whole.vertices, whole.faces[whole.vertices[whole.faces][:, :, 2].mean(1) > 0])
    preset = get_preset("smeets2010-surface")
    assert preset.two_sided_views
    one_sided = replace(preset, two_sided_views=False)

    def distance(a: ShapeDescriptor, b: ShapeDescriptor, modality: str) -> float:
        x, y = a.vector(modality)[None], b.vector(modality)[None]
        return float(mean_normalized_manhattan(x, y)[0, 0])

    seen, described = describe_mesh(whole, preset), describe_mesh(view, preset)
    as_it_is, narrower = describe_mesh(view, one_sided), describe_mesh(other, preset)
    assert described.single_view and described.vertices > 0.9 * preset.n_vertices
    # Its size is the view's, one sheet.
    view_area = float(face_areas(view.vertices, view.faces).sum())
    assert described.area == pytest.approx(view_area, rel=RESAMPLED_AREA)
    for m in MODALITIES:
        apart = distance(seen, narrower, m)
        assert distance(seen, described, m) < apart / 10, m
        assert distance(seen, as_it_is, m) > apart, m


def test_scan_gaps_close_before_the_surface_is_described():
    """Three holes of 0.3% of the area each, as a scanner leaves them: with its holes
    the surface's Neumann spectrum moved 0.016 from the intact one, 60% of its distance
    to a differently proportioned surface (0.025); the default closes them first, and
    every modality then stays well under a tenth of that distance."""
    sphere = trimesh.creation.icosphere(subdivisions=5)
    intact = _bumpy_ellipsoid(sphere)
    other = _bumpy_ellipsoid(sphere, (3.0, 1.7, 1.0))
    tri = trimesh.Trimesh(intact.vertices, intact.faces, process=False)
    centroids, keep = tri.triangles_center, np.ones(len(intact.faces), dtype=bool)
    for centre in intact.vertices[[0, 4000, 9000]]:
        nearest = np.argsort(np.linalg.norm(centroids - centre, axis=1))
        keep[nearest[np.cumsum(tri.area_faces[nearest]) <= 0.003 * tri.area]] = False
    holed = clean_mesh(intact.vertices, intact.faces[keep])
    closing = get_preset("smeets2010-surface")
    assert closing.max_hole_perimeter is not None
    with_holes = replace(closing, max_hole_perimeter=None)

    def distance(preset, modality, a, b) -> float:
        x, y = describe_mesh(a, preset).vector(modality), describe_mesh(b, preset).vector(modality)
        return float(mean_normalized_manhattan(x[None], y[None])[0, 0])

    for m in MODALITIES:
        closed = distance(closing, m, intact, holed)
        assert closed < distance(with_holes, m, intact, holed) / 2.5
        assert closed < distance(closing, m, intact, other) / 8


def test_a_thin_helical_spring_describes():
    """Issue 9: closed thin helical springs failed with 'ArpackError: Could not build
    an Arnoldi factorization'. The trigger was the heat step underflowing along the
    700-edge-long wire (NaN distances, then ARPACK on a NaN matrix)."""
    vertices, faces = helical_spring()
    d = describe_mesh(clean_mesh(vertices, faces), get_preset("smeets2010-surface"))
    for m in MODALITIES:
        assert np.all(np.isfinite(d.vector(m))) and np.all(d.vector(m) > 0)
