"""Resampling to the preset's vertex count: near the target, same surface, clean result."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import bent_cylinder, faceted_wire, random_rotation

from worker.engine import resample
from worker.engine.mesh_io import Mesh, canonical_frame, clean_mesh, load_mesh, tiling_edge
from worker.engine.resample import (
    MAX_REFINED_VERTICES,
    carry_resampling,
    clustered_vertices,
    needle_vertices,
    resample_mesh,
    shared_resampling,
    split_edges,
    split_long_edges,
)
from worker.engine.topology import edge_keys, euler_and_boundary, unique_rows


def area(mesh: Mesh) -> float:
    return float(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).area)


def assert_clean(mesh: Mesh) -> None:
    """Every vertex used, no degenerate or repeated face, finite coordinates."""
    assert np.isfinite(mesh.vertices).all()
    assert np.array_equal(np.unique(mesh.faces), np.arange(mesh.n_vertices))
    assert (mesh.faces[:, 0] != mesh.faces[:, 1]).all()
    assert (mesh.faces[:, 1] != mesh.faces[:, 2]).all()
    assert (mesh.faces[:, 2] != mesh.faces[:, 0]).all()
    first, _ = unique_rows(np.sort(mesh.faces, axis=1))
    assert len(first) == mesh.n_faces


@pytest.fixture(scope="module")
def sphere() -> Mesh:
    s = trimesh.creation.icosphere(subdivisions=5)  # 10,242 vertices
    return clean_mesh(s.vertices, s.faces)


@pytest.mark.parametrize("target", [500, 2500])
def test_decimation_lands_near_the_target(sphere, target):
    out = resample_mesh(sphere, target)
    # quadric decimation stops on a face budget: a few percent at most
    assert abs(out.n_vertices - target) <= 0.03 * target, out.n_vertices
    assert_clean(out)
    # a closed sphere stays a closed sphere, of about the same area
    assert euler_and_boundary(out.faces, out.n_vertices) == (2, 0)
    assert area(out) == pytest.approx(area(sphere), rel=0.02)


def test_a_small_mesh_is_subdivided_without_changing_its_surface():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))  # 8 vertices, 18 edges, 12 faces
    mesh = clean_mesh(box.vertices, box.faces)
    out = resample_mesh(mesh, 8 + 18)  # one midpoint subdivision is exactly the target
    assert out.n_vertices == 26 and out.n_faces == 4 * 12
    assert area(out) == pytest.approx(area(mesh), rel=1e-12)
    assert_clean(out)
    # past one subdivision, decimation brings the refined box to the target
    refined = resample_mesh(mesh, 60)
    assert abs(refined.n_vertices - 60) <= 3
    assert area(refined) == pytest.approx(22.0, rel=1e-9)  # a box's faces stay flat
    assert_clean(refined)


def edge_lengths(mesh: Mesh) -> np.ndarray:
    p = mesh.vertices[mesh.faces]
    return np.linalg.norm(p - p[:, [1, 2, 0]], axis=2).ravel()


@pytest.fixture(scope="module")
def cad_cylinder() -> Mesh:
    """A CAD-style cylinder: 48 strips, each two triangles the whole height long."""
    c = trimesh.creation.cylinder(radius=0.5, height=2.0, sections=48)
    return clean_mesh(c.vertices, c.faces)


def test_splitting_some_edges_keeps_the_surface_and_its_orientation(cad_cylinder):
    mesh = cad_cylinder
    keys = np.unique(edge_keys(mesh.faces, mesh.n_vertices))
    chosen = np.sort(np.random.default_rng(0).choice(keys, size=len(keys) // 3, replace=False))
    vertices, faces = split_edges(mesh.vertices, mesh.faces, chosen)
    out = Mesh(vertices=vertices, faces=faces)
    assert out.n_vertices == mesh.n_vertices + len(chosen)
    assert area(out) == pytest.approx(area(mesh), rel=1e-12)
    assert euler_and_boundary(out.faces, out.n_vertices) == (2, 0)
    assert_clean(out)
    # every face keeps the outward orientation of the face it came from
    normals = trimesh.Trimesh(out.vertices, out.faces, process=False).face_normals
    centers = out.vertices[out.faces].mean(axis=1)
    radial = np.c_[centers[:, :2], np.zeros(len(centers))]
    side = np.abs(centers[:, 2]) < 1.0 - 1e-9
    outward = np.where(side, np.einsum("ij,ij->i", normals, radial), normals[:, 2] * centers[:, 2])
    assert (outward > 0).all()


def test_all_edges_split_is_the_midpoint_subdivision():
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    mesh = clean_mesh(box.vertices, box.faces)
    out = resample_mesh(mesh, 26)  # exactly one subdivision
    vertices, faces = split_edges(mesh.vertices, mesh.faces, np.unique(edge_keys(mesh.faces, 8)))
    assert np.array_equal(out.vertices, vertices) and np.array_equal(out.faces, faces)


def test_decimation_leaves_a_cylinders_strips_long_and_the_bound_refines_them(cad_cylinder):
    target = 1000
    h = tiling_edge(area(cad_cylinder), target)
    plain = resample_mesh(cad_cylinder, target)
    # along the strips nothing holds a vertex: elements a quarter of the height long
    assert edge_lengths(plain).max() > 5 * h
    bounded = resample_mesh(cad_cylinder, target, max_edge=3.0)
    assert edge_lengths(bounded).max() <= 3.0 * h
    # Decimated further for the vertices the bound adds, the split strips are slivers
    # the decimation cannot thin: they are clustered, which cuts the rims' corners.
    assert area(bounded) == pytest.approx(area(plain), rel=0.01)
    assert euler_and_boundary(bounded.faces, bounded.n_vertices) == (2, 0)
    assert_clean(bounded)


def test_the_bounds_vertices_come_out_of_the_decimation(tosca_dir):
    wolf = load_mesh(tosca_dir / "wolf0.off.gz")
    target = 2500
    plain = resample_mesh(wolf, target)
    limit = 3.0 * tiling_edge(area(plain), target)
    split_only = split_long_edges(plain, limit, MAX_REFINED_VERTICES * target)
    assert split_only.n_vertices > plain.n_vertices + 40  # the bound alone adds 66
    bounded = resample_mesh(wolf, target, max_edge=3.0)
    assert abs(bounded.n_vertices - plain.n_vertices) <= 0.01 * target
    assert edge_lengths(bounded).max() <= limit
    assert area(bounded) == pytest.approx(area(plain), rel=0.01)
    assert euler_and_boundary(bounded.faces, bounded.n_vertices) == euler_and_boundary(
        plain.faces, plain.n_vertices
    )
    assert_clean(bounded)


def test_the_edge_bound_stops_at_its_vertex_budget_longest_edges_first():
    long_thin = trimesh.creation.cylinder(radius=0.5, height=20.0, sections=64)
    mesh = clean_mesh(long_thin.vertices, long_thin.faces)
    before = edge_lengths(mesh).max()
    out = split_long_edges(mesh, max_length=1e-3, max_vertices=5 * mesh.n_vertices)
    assert out.n_vertices == 5 * mesh.n_vertices
    assert edge_lengths(out).max() < before
    assert area(out) == pytest.approx(area(mesh), rel=1e-12)
    assert_clean(out)
    # through resample_mesh the budget is MAX_REFINED_VERTICES times the target
    bounded = resample_mesh(mesh, 500, max_edge=0.5)
    assert bounded.n_vertices <= MAX_REFINED_VERTICES * 500


def test_clustering_merges_a_cubes_vertices_at_their_mean_and_drops_what_collapses():
    """A unit square with a vertex 0.01 from a corner: in cubes of 0.6 the two share one,
    so the sliver between them goes and the square's two triangles stay."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.99, 0, 0]], float)
    faces = np.array([[0, 4, 2], [4, 1, 2], [0, 2, 3]])
    out = clustered_vertices(Mesh(vertices, faces), 0.6)
    assert out.n_vertices == 4 and out.n_faces == 2
    assert_clean(out)
    merged = out.vertices[np.abs(out.vertices[:, 0] - 0.995) < 1e-12]
    np.testing.assert_allclose(merged, [[0.995, 0.0, 0.0]])
    assert area(out) == pytest.approx(1.0 - 0.5 * 0.005, rel=1e-12)


def test_needle_vertices_are_the_corners_the_decimation_calls_needles():
    # Angles 1, 89.5, 89.5 degrees: one needle; 0.5, 0.5, 179: two needles and a cap.
    needle = np.array([[0.0, 0.0, 0.0], [1.0, -0.0087, 0.0], [1.0, 0.0087, 0.0]])
    cap = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.0087, 0.0]])
    faces = np.array([[0, 1, 2]])
    assert needle_vertices(needle, faces) == 1
    assert needle_vertices(cap, faces) == 3
    assert needle_vertices(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), faces) == 0


def test_a_wire_thinner_than_a_cube_is_clustered_in_smaller_cubes():
    """Cubes of one tiling edge fold the fine wire's section (0.93 of the area kept), so
    its decimation's stalled 37,890 vertices stood; in cubes of half one (0.99) it lands
    near the target (in its canonical frame, as the pipeline resamples it: the cubes'
    grid is the frame's). The bound's second decimation stalls too and clusters again
    (0.96): 0.95 of the area is left, a thinner section of the same wire, with a few
    edges where its sides met in one cube (24 of its 7,500 edges on one side only)."""
    wire, target = canonical_frame(clean_mesh(*faceted_wire())), 2500
    bounded = resample_mesh(wire, target, max_edge=3.0)
    assert bounded.n_vertices <= resample.STALLED_DECIMATION * target, bounded.n_vertices
    assert area(bounded) == pytest.approx(area(wire), rel=0.06)
    euler, boundary = euler_and_boundary(bounded.faces, bounded.n_vertices)
    assert euler == 2 and boundary <= 0.01 * 3 * bounded.n_vertices
    assert_clean(bounded)


@pytest.mark.parametrize("sections", [2048, 0])
def test_a_stall_foreseen_from_the_needles_skips_only_a_pass_that_stalls(monkeypatch, sections):
    """The decimation is not tried on a surface with more needle corners than it may leave:
    the resampling is the one it gives after the futile pass (the 2,048-strip cylinder, the
    fine wire)."""
    if sections:
        c = trimesh.creation.cylinder(radius=0.5, height=2.0, sections=sections)
        slivers, target = clean_mesh(c.vertices, c.faces), 1000
    else:
        slivers, target = clean_mesh(*faceted_wire()), 2500
    assert needle_vertices(slivers.vertices, slivers.faces) > 1.25 * target
    foreseen = resample_mesh(slivers, target, max_edge=3.0)
    monkeypatch.setattr(resample, "needle_vertices", lambda vertices, faces: 0)
    tried = resample_mesh(slivers, target, max_edge=3.0)
    np.testing.assert_array_equal(foreseen.vertices, tried.vertices)
    np.testing.assert_array_equal(foreseen.faces, tried.faces)


@pytest.mark.parametrize("target", [500, 1000])
def test_a_surface_of_slivers_is_thinned_from_its_clustered_vertices(target):
    """A cylinder finely faceted as CAD exports it (2,048 strips): quadric decimation
    refuses every collapse there (each would leave a needle corner) and kept all 4,098
    vertices, which the bound then refined to its budget. From its vertices clustered
    at one tiling edge it lands at the target, and the bound adds what a coarse export's
    strips need."""
    c = trimesh.creation.cylinder(radius=0.5, height=2.0, sections=2048)
    fine = clean_mesh(c.vertices, c.faces)
    plain = resample_mesh(fine, target)
    assert abs(plain.n_vertices - target) <= 0.03 * target, plain.n_vertices
    assert area(plain) == pytest.approx(area(fine), rel=0.01)
    assert euler_and_boundary(plain.faces, plain.n_vertices) == (2, 0)
    assert_clean(plain)
    bounded = resample_mesh(fine, target, max_edge=3.0)
    assert bounded.n_vertices <= 2 * target, bounded.n_vertices
    assert edge_lengths(bounded).max() <= 3.0 * tiling_edge(area(plain), target)
    assert_clean(bounded)


def _poses(bends: tuple[float, ...]) -> list[Mesh]:
    """Poses of one figure numbered alike: a bent cylinder at each bend (trimesh keeps
    the vertex order; the file numbering of :func:`read_numbered_mesh`)."""
    return [Mesh(t.vertices, t.faces) for t in (bent_cylinder(b) for b in bends)]


def test_one_resampling_of_a_figure_is_carried_to_its_poses_by_vertex_id():
    """Every pose takes the same triangles, and each vertex the same barycentric point
    of the triangle of the same ids in each pose: one triangulation of the figure, on
    each pose's surface."""
    poses = _poses((0.0, 1.0, 2.0))
    shared = shared_resampling(poses[1], 500)
    assert shared.source_vertices == poses[1].n_vertices
    assert abs(len(shared.corners) - 500) <= 0.03 * 500
    assert np.all(shared.weights >= 0.0)
    np.testing.assert_allclose(shared.weights.sum(axis=1), 1.0, rtol=1e-12)
    carried = [carry_resampling(p, shared) for p in poses]
    for pose, mesh in zip(poses, carried, strict=True):
        assert_clean(mesh)
        assert mesh.faces is shared.faces
        corners = pose.vertices[shared.corners]
        np.testing.assert_allclose(
            mesh.vertices, np.einsum("kc,kcx->kx", shared.weights, corners), rtol=1e-12
        )
        assert area(mesh) == pytest.approx(area(pose), rel=0.03)
    # The same points of the figure: a pose moved rigidly takes the moved resampling.
    rotation = random_rotation(np.random.default_rng(5))
    moved = Mesh(poses[2].vertices @ rotation.T + [1.0, -2.0, 3.0], poses[2].faces)
    np.testing.assert_allclose(
        carry_resampling(moved, shared).vertices,
        carried[2].vertices @ rotation.T + [1.0, -2.0, 3.0],
        atol=1e-12,
    )
    fewer = Mesh(poses[0].vertices[:-1], poses[0].faces[:10])
    with pytest.raises(ValueError, match="cannot take a resampling made on"):
        carry_resampling(fewer, shared)


def test_a_figure_below_the_target_keeps_every_vertex():
    pose = _poses((0.5,))[0]
    shared = shared_resampling(pose, 10 * pose.n_vertices)
    carried = carry_resampling(pose, shared)
    np.testing.assert_array_equal(carried.vertices, pose.vertices)
    np.testing.assert_array_equal(carried.faces, pose.faces)
