"""Point clouds of one view: organized ones (a depth camera's PCD) triangulated by their
grid, others as seen from their sensor, the gaps between occluding and occluded surfaces
left open; points that are not one view (a whole object's) read as the view that sees
most of them."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import trimesh
from conftest import e57_scan, random_rotation

from worker.engine import mesh_io, scans
from worker.engine.errors import PointCloudError, UnreadableMeshError
from worker.engine.mesh_io import Mesh, read_mesh
from worker.engine.scans import (
    SHADOW_DEGREES,
    Cloud,
    grid_faces,
    grid_sight,
    lzf_decompress,
    organized_surface,
    read_e57,
    read_pcd,
    unshadowed,
    view_frame,
    viewed_surface,
)
from worker.evaluation.partial import edge_graph, range_image, voxel_means
from worker.evaluation.samples import (
    DEPTH_DIRECTION,
    FLOOR_ELEVATION,
    PARTIAL_SOURCE,
    depth_scan,
    floor_scan,
    pcd_gz_bytes,
    sample_mesh,
    seen_from_left,
)
from worker.evaluation.variants import subdivided

HEIGHT, WIDTH = 30, 40


def camera_grid(depth: np.ndarray) -> np.ndarray:
    """(h, w, 3) what a pinhole camera at the origin looking along +z sees at ``depth``
    (h, w) (``nan``: nothing), a pixel's ray ``(u, v, 1)`` 0.02 apart."""
    height, width = depth.shape
    v, u = np.mgrid[0:height, 0:width] * 0.02
    rays = np.stack([u - u.mean(), v - v.mean(), np.ones_like(u)], axis=-1)
    return rays * depth[..., None]


def two_planes() -> tuple[np.ndarray, int]:
    """A near plane (depth 1) over the left ``near`` columns in front of a far one (depth
    3): the cloud, and ``near``."""
    near = 15
    depth = np.full((HEIGHT, WIDTH), 3.0)
    depth[:, :near] = 1.0
    return camera_grid(depth), near


def framed(points: np.ndarray) -> np.ndarray:
    """``points`` (h, w, 3) with the frame's outermost pixels blank, as a camera framing an
    object sees nothing around it: no plane runs out of the frame, so none is left out as
    a floor or a wall (:func:`~worker.engine.scans.without_support`)."""
    inside = np.full_like(points, np.nan)
    inside[1:-1, 1:-1] = points[1:-1, 1:-1]
    return inside


#: A 6 x 8 grid's fields in turn (``soa_fields(small_grid())``) as liblzf 3.6 compresses
#: them (python-lzf 0.2.6's ``lzf.compress``): literal runs, copies of 3 to 183 bytes
#: from 4 to 296 bytes back, overlapping ones among them.
LIBLZF_SMALL_GRID = bytes.fromhex(
    "040000c07f00e012030f295c0fbecdccccbd8fc275bd0ad7a3bc2003003c200b003d2013003d201b003e"
    "2003e01c1fe00363e02b3f2033e00c7fe00357e00b0b4037e0130320cf40d3e01303003c2023003ce003"
    "5b400fc003205b003de013034127e01303e00357e00d0b010040e03d03e0035fe03f53604700ff2007e0"
    "ae030100ff"
)


def small_grid() -> np.ndarray:
    """(6, 8, 3) a plane seen by a camera, its first row and three pixels saw nothing."""
    points = camera_grid(np.full((6, 8), 2.0))
    points[0, :] = np.nan
    points[3, 2:5] = np.nan
    return points


def soa_fields(points: np.ndarray) -> bytes:
    """``binary_compressed``'s raw layout: each field's values in turn (x, y, z as float32,
    then a constant rgb)."""
    flat = points.reshape(-1, 3).astype("<f4")
    colour = np.full(len(flat), 0xFF000000, dtype="<u4")
    return b"".join(np.ascontiguousarray(column).tobytes() for column in flat.T) + colour.tobytes()


def lzf_literals(raw: bytes) -> bytes:
    """``raw`` as a valid LZF stream of literal runs only (32 bytes each at most)."""
    return b"".join(
        bytes([len(run) - 1]) + run for run in (raw[a : a + 32] for a in range(0, len(raw), 32))
    )


def pcd(
    points: np.ndarray,
    data: str = "ascii",
    viewpoint=(0.0, 0.0, 0.0),
    orientation=(1.0, 0.0, 0.0, 0.0),
) -> bytes:
    """``points`` (h, w, 3) as a PCD file with an extra ``rgb`` field, stored as ``data``
    (``binary_compressed`` by literal runs only, :func:`lzf_literals`), its sensor at
    ``viewpoint`` turned by the quaternion ``orientation`` (w x y z)."""
    height, width = points.shape[:2]
    pose = " ".join(map(str, [*viewpoint, *orientation]))
    header = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\n"
        f"COUNT 1 1 1 1\nWIDTH {width}\nHEIGHT {height}\n"
        f"VIEWPOINT {pose}\nPOINTS {width * height}\n"
        f"DATA {data}\n"
    )
    flat = points.reshape(-1, 3)
    if data == "ascii":
        rows = "".join(f"{x!r} {y!r} {z!r} 4278190080\n" for x, y, z in flat.tolist())
        return (header + rows).encode()
    if data == "binary_compressed":
        raw = soa_fields(points)
        compressed = lzf_literals(raw)
        return header.encode() + struct.pack("<II", len(compressed), len(raw)) + compressed
    records = np.zeros(len(flat), dtype=[("xyz", "<f4", (3,)), ("rgb", "<u4")])
    records["xyz"], records["rgb"] = flat, 0xFF000000
    return header.encode() + records.tobytes()


def test_an_occluding_edge_leaves_no_triangle_across_the_gap():
    points, near = two_planes()
    vertices, faces = organized_surface(points, np.zeros(3))
    on_near = np.isclose(vertices[:, 2], 1.0)
    assert not np.any(on_near[faces].any(axis=1) & ~on_near[faces].all(axis=1))
    # Every square of either plane is kept: two triangles each.
    assert len(faces) == 2 * (HEIGHT - 1) * (near - 1 + WIDTH - near - 1)
    # The grid alone (SHREC'17's range scans) joins the planes by a strip of shortcuts.
    joined = grid_faces(np.ones((HEIGHT, WIDTH), dtype=bool))
    assert len(joined) == len(faces) + 2 * (HEIGHT - 1)


def test_a_surface_seen_obliquely_keeps_every_triangle():
    """A plane tilted 45 degrees from the camera's axis: the rays meet it at 24 degrees or
    more, and only edges within SHADOW_DEGREES of a ray are dropped."""
    height, width = HEIGHT, WIDTH
    v, u = np.mgrid[0:height, 0:width] * 0.02
    u, v = u - u.mean(), v - v.mean()
    # The plane z = 2 + x tan(45 deg) met by the ray (u, v, 1): t = 2 / (1 - u tan 45).
    depth = 2.0 / (1.0 - u * np.tan(np.radians(45.0)))
    assert SHADOW_DEGREES < 20.0
    vertices, faces = organized_surface(camera_grid(depth), np.zeros(3))
    assert len(vertices) == height * width
    assert len(faces) == 2 * (height - 1) * (width - 1)


def orthographic_two_planes(rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`two_planes` seen by an orthographic camera along +z (pixels 0.02 apart), in
    a ``rotation``: the grid's points (h * w, 3), its triangles with the shortcuts across
    the gap (as SHREC'17's range scans were written) and the near plane's columns."""
    near = 15
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH] * 0.02
    depth = np.where(np.arange(WIDTH)[None, :] < near, 1.0, 3.0) * np.ones((HEIGHT, 1))
    points = np.stack([u, v, depth], axis=-1).reshape(-1, 3) @ rotation.T + 5.0
    return points, grid_faces(np.ones((HEIGHT, WIDTH), dtype=bool)), near


def test_a_range_scan_written_as_a_mesh_has_its_line_of_sight():
    """Every triangle of an orthographic grid projects to half a pixel along the rays:
    its line of sight is found from the triangles alone, and the rule along it leaves
    the shortcuts out as an organized cloud's viewpoint does."""
    rotation = random_rotation(np.random.default_rng(3))
    points, faces, near = orthographic_two_planes(rotation)
    sight = grid_sight(points, faces)
    assert sight is not None
    assert abs(float(sight @ rotation[:, 2])) == pytest.approx(1.0, abs=1e-9)
    kept = unshadowed(points, faces, sight=sight)
    assert np.count_nonzero(~kept) == 2 * (HEIGHT - 1)  # the strip across the gap
    far_viewpoint = points.mean(axis=0) + 1e3 * rotation[:, 2]
    assert np.array_equal(kept, unshadowed(points, faces, far_viewpoint))


def test_meshes_that_are_not_an_orthographic_grid_have_no_line_of_sight():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    upper = sphere.faces[sphere.triangles_center[:, 2] > 0.2]  # faces one way, unevenly
    perspective, _ = two_planes()  # a pinhole camera's pixels grow with their depth
    for points, faces in (
        (sphere.vertices, sphere.faces),
        (sphere.vertices, upper),
        (perspective.reshape(-1, 3), grid_faces(np.ones((HEIGHT, WIDTH), dtype=bool))),
        (sphere.vertices, upper[:3]),  # three triangles fit any direction exactly
    ):
        assert grid_sight(np.asarray(points), np.asarray(faces)) is None


@pytest.mark.parametrize(("noise", "grid"), [(0.0, True), (0.00002, True), (0.0002, False)])
def test_a_sample_of_the_triangles_decides_as_all_of_them_do(noise, grid, monkeypatch):
    """grid_sight tries a seeded sample of a large mesh's triangles first: the grid found
    (or not: noise across the view spreads the areas by 0.2% / 2%) as by every triangle,
    and the same sight. Noise along the sight moves no projected area."""
    rng = np.random.default_rng(4)
    rotation = random_rotation(rng)
    points, faces, _ = orthographic_two_planes(rotation)
    along = points + 0.01 * rng.standard_normal((len(points), 1)) * rotation[:, 2]
    assert grid_sight(along, faces) is not None
    points = points + noise * rng.standard_normal(points.shape)
    sphere = trimesh.creation.icosphere(subdivisions=4)
    assert min(len(faces), len(sphere.faces)) > 4 * scans.GRID_TRIAL  # the sample decides
    sampled = [grid_sight(points, faces), grid_sight(sphere.vertices, sphere.faces)]
    monkeypatch.setattr(scans, "GRID_TRIAL", 10**9)  # every triangle only
    every = [grid_sight(points, faces), grid_sight(sphere.vertices, sphere.faces)]
    assert (sampled[0] is not None) == (every[0] is not None) == grid
    if sampled[0] is not None:
        assert np.allclose(sampled[0], every[0])
    assert sampled[1] is None and every[1] is None


def test_pixels_that_saw_nothing_are_left_out():
    points, _ = two_planes()
    points[5:9, 20:30] = np.nan
    vertices, faces = organized_surface(points, np.zeros(3))
    assert len(vertices) == HEIGHT * WIDTH - 4 * 10 and np.isfinite(vertices).all()
    assert faces.max() == len(vertices) - 1


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
def test_a_pcd_file_is_read_as_its_grid_triangulated_from_its_viewpoint(data):
    points = framed(two_planes()[0])
    vertices, faces, grid = read_pcd(pcd(points, data))
    assert_read_as(points, vertices, faces, grid)
    # The shadows are seen from the file's viewpoint.
    aside = np.array([0.0, 1e6, 0.0])
    faces_aside = read_pcd(pcd(points, data, viewpoint=aside))[1]
    np.testing.assert_array_equal(faces_aside, organized_surface(points, aside)[1])
    assert len(faces_aside) != len(faces)


def test_pixels_that_saw_nothing_written_at_the_sensor_are_left_out():
    """Cameras' software writes a pixel that saw nothing as the point (0, 0, 0), the
    sensor itself in its frame (Kinect's and RealSense's point clouds): no surface it saw
    lies there. The floor scene in its camera's frame, a tenth of its pixels missing,
    written so, as an organized PCD and as a PLY of every pixel's point, is read as it is
    with those pixels not a number and left out: the same points, triangles and floor
    (not, from the PLY, points partly behind the sensor read from afar with their
    floor)."""
    grid, viewpoint = floor_scan(sample_mesh(*PARTIAL_SOURCE))
    grid = (grid - viewpoint) @ view_frame(seen_from_left(FLOOR_ELEVATION)).T
    grid[np.random.default_rng(0).uniform(size=grid.shape[:2]) < 0.1] = np.nan
    missing = ~np.isfinite(grid).all(axis=2)
    zeros = np.where(missing[..., None], 0.0, grid)
    zeros_read, missing_read = read_pcd(pcd(zeros, "binary")), read_pcd(pcd(grid, "binary"))
    assert zeros_read[2] == missing_read[2] and missing_read[2].support
    assert triangles(*zeros_read[:2]) == triangles(*missing_read[:2])

    def ply(points: np.ndarray) -> bytes:
        return trimesh.PointCloud(points).export(file_type="ply")

    zeros_read, missing_read = (
        read_mesh(ply(points), "scan.ply") for points in (zeros.reshape(-1, 3), grid[~missing])
    )
    assert zeros_read.cloud == missing_read.cloud and missing_read.cloud.support
    assert triangles(zeros_read.mesh.vertices, zeros_read.mesh.faces) == triangles(
        missing_read.mesh.vertices, missing_read.mesh.faces
    )


def test_lzf_decompresses_what_liblzf_compressed():
    raw = soa_fields(small_grid())
    assert lzf_decompress(LIBLZF_SMALL_GRID, len(raw)) == raw
    for damaged, size in [
        (LIBLZF_SMALL_GRID, len(raw) - 1),  # more than the header says
        (LIBLZF_SMALL_GRID, len(raw) + 1),  # fewer
        (LIBLZF_SMALL_GRID[:-3], len(raw)),  # truncated
        (bytes([0x20, 0x00]), 3),  # a copy from before the start
    ]:
        with pytest.raises((ValueError, IndexError)):
            lzf_decompress(damaged, size)


def test_pcl_binary_compressed_file_is_read():
    """PCL's layout: the sizes, then liblzf's bytes of each field's values in turn."""
    points = small_grid()
    header = pcd(points, "binary").split(b"DATA")[0] + b"DATA binary_compressed\n"
    raw = len(soa_fields(points))
    data = header + struct.pack("<II", len(LIBLZF_SMALL_GRID), raw) + LIBLZF_SMALL_GRID
    vertices, faces, grid = read_pcd(data)
    assert grid == Cloud(48 - 8 - 3, (8, 6), 0)
    want_vertices, want_faces = organized_surface(points.astype(np.float32), np.zeros(3))
    np.testing.assert_allclose(vertices, want_vertices, rtol=1e-6)
    np.testing.assert_array_equal(faces, want_faces)
    with pytest.raises(UnreadableMeshError, match="damaged or truncated"):
        read_pcd(data[:-5])
    with pytest.raises(UnreadableMeshError, match="expands to more than"):
        read_pcd(data, max_bytes=raw - 1)


def assert_read_as(points: np.ndarray, vertices, faces, grid) -> np.ndarray:
    """That a file's surface is ``points``' (stored in single precision, :func:`framed`)
    triangulated from the origin; returns the triangles."""
    assert grid == Cloud((HEIGHT - 2) * (WIDTH - 2), (WIDTH, HEIGHT), 0)
    want_vertices, want_faces = organized_surface(points.astype(np.float32), np.zeros(3))
    np.testing.assert_allclose(vertices, want_vertices, rtol=1e-6)
    np.testing.assert_array_equal(faces, want_faces)
    return want_faces


def test_a_gzipped_pcd_is_read_as_a_mesh():
    points = framed(two_planes()[0])
    cleaned = read_mesh(pcd_gz_bytes(points, np.zeros(3)), "scan.pcd.gz")
    # The larger piece, the far plane (the near one is separate once the gap is open).
    assert cleaned.mesh.n_vertices == (HEIGHT - 2) * (WIDTH - 16)
    assert np.allclose(cleaned.mesh.vertices[:, 2], 3.0, atol=1e-6)
    assert 0.5 < cleaned.kept_area_fraction < 1.0
    # The file's, not the piece's.
    assert cleaned.cloud == Cloud((HEIGHT - 2) * (WIDTH - 2), (WIDTH, HEIGHT), 0)


def triangles(vertices: np.ndarray, faces: np.ndarray) -> set[tuple[tuple[float, ...], ...]]:
    """A surface's triangles as sets of their corners' coordinates, whatever their order."""
    return {tuple(sorted(map(tuple, vertices[face].round(9).tolist()))) for face in faces}


def point_pairs(first: np.ndarray, second: np.ndarray) -> set[frozenset[tuple[float, ...]]]:
    """The pairs of points ``first`` and ``second`` (..., 3) hold at the same place, both
    finite, as sets of their coordinates."""
    both = np.isfinite(first).all(axis=-1) & np.isfinite(second).all(axis=-1)
    return {
        frozenset((tuple(a), tuple(b)))
        for a, b in zip(first[both].round(9).tolist(), second[both].round(9).tolist(), strict=True)
    }


def grid_steps(grid: np.ndarray) -> set[frozenset[tuple[float, ...]]]:
    """An organized cloud's (h, w, 3) steps between neighbouring pixels along its rows and
    columns (:func:`point_pairs`): the same whichever way the grid is turned or
    mirrored."""
    return point_pairs(grid[:, :-1], grid[:, 1:]) | point_pairs(grid[:-1], grid[1:])


@pytest.fixture
def walls_kept(monkeypatch):
    """The two planes fill the points' rectangle, so read without their grid the far one
    is a wall behind the near one, left out (tests/engine/test_support.py); the tests of
    how a lattice is found and triangulated keep it."""
    monkeypatch.setattr(scans, "without_support", lambda points, viewpoint: (points, 0))


@pytest.mark.usefixtures("walls_kept")
@pytest.mark.parametrize("frame", ["camera", "turned", "turned, moved", "off the lattice"])
def test_a_cloud_without_its_grid_is_triangulated_as_its_grid_is(frame, monkeypatch):
    """The two planes' points in random order, from the same viewpoint, make the grid's
    surface: every point, no triangle across the gap between the planes, none over the
    pixels that saw nothing; a grid's square split along either diagonal (four points on
    a circle), so the same area in as many triangles. Each faces the sensor. In the
    camera's frame the points lie on its pixel lattice (:func:`scans.sensor_grid`);
    turned away from it they lie on it in a frame found from them
    (:func:`scans.sensor_axes`); moved within their planes by up to a tenth of a pixel, near
    it (:func:`scans.snapped_steps`, the pitch from the frame's steps); moved by a
    hundredth of a pixel and not read near a lattice (as if moved farther), the Delaunay
    triangulation of their image makes the same surface (no pixel missing: there the
    grid leaves a hole that Delaunay's reading may close)."""
    points, _ = two_planes()
    points[5:9, 20:30] = np.nan  # a hole the far plane's grid leaves open
    if frame != "off the lattice":  # Delaunay's reading may close a missing pixel's hole
        points[2, 3] = np.nan
    if frame in ("turned, moved", "off the lattice"):
        most = 0.1 if frame == "turned, moved" else 1e-2
        jitter = np.random.default_rng(5).uniform(-most, most, size=(HEIGHT, WIDTH, 2))
        points[..., :2] += 0.02 * points[..., 2:] * jitter
    if frame == "off the lattice":
        monkeypatch.setattr(scans, "snapped_steps", lambda values, pitch: None)
    turned = frame.startswith("turned")
    turn = random_rotation(np.random.default_rng(3)) if turned else np.eye(3)
    points = points @ turn.T
    grid_vertices, grid_triangles = organized_surface(points, np.zeros(3))
    shuffled = points.reshape(-1, 3)[np.random.default_rng(0).permutation(HEIGHT * WIDTH)]
    finite = shuffled[np.isfinite(shuffled).all(axis=1)]
    assert (scans.sensor_grid(finite, np.zeros(3)) is None) == (frame != "camera")
    frames = list(scans.sensor_axes(finite, np.zeros(3)))
    exact = [scans.sensor_grid(finite, np.zeros(3), axes) for axes, _, _ in frames]
    assert any(lattice is not None for lattice in exact) == (frame in ("camera", "turned"))
    snapped = [
        scans.sensor_grid(finite, np.zeros(3), axes, steps=steps) for axes, _, steps in frames
    ]
    assert any(lattice is not None for lattice in snapped) == (frame != "off the lattice")
    vertices, faces, _ = viewed_surface(shuffled, np.zeros(3))
    assert {tuple(v) for v in vertices.tolist()} == {tuple(v) for v in grid_vertices.tolist()}
    assert len(vertices) == len(grid_vertices) and len(faces) == len(grid_triangles)
    corners = vertices[faces]
    depths = (corners @ turn)[:, :, 2]
    assert np.allclose(depths.min(axis=1), depths.max(axis=1))  # one plane
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    grid_corners = grid_vertices[grid_triangles]
    grid_normals = np.cross(
        grid_corners[:, 1] - grid_corners[:, 0], grid_corners[:, 2] - grid_corners[:, 0]
    )
    area = np.linalg.norm(normals, axis=1).sum()
    assert area == pytest.approx(np.linalg.norm(grid_normals, axis=1).sum(), rel=1e-9)
    assert (np.einsum("ij,ij->i", normals, -corners.mean(axis=1)) > 0).all()
    # A PCD without a grid (HEIGHT 1) is read so from its VIEWPOINT.
    moved = np.array([0.5, -2.0, 7.0])
    read, read_faces, cloud = read_pcd(pcd((shuffled + moved).reshape(1, -1, 3), viewpoint=moved))
    # Off the lattice, its 1,200 points fill too few cells to be looked at for a floor.
    support = None if frame == "off the lattice" else 0
    assert cloud == Cloud(len(grid_vertices), None, support)
    assert len(read_faces) == len(grid_triangles)
    assert triangles(read - moved, read_faces) == triangles(vertices, faces)


def test_lattice_steps_number_a_sensor_s_columns_and_refuse_other_values():
    """Columns 0.02 apart, each value rounded as float32 or six digits of text would,
    two columns missing: each value's column. Values off a lattice, all equal, or each
    column's values at two places 0.35 of the pitch apart: none. Values rounded by more
    than a hundred-thousandth of their span: their lattice only when told the rounding."""
    rng = np.random.default_rng(0)
    columns = np.concatenate([np.arange(12), [14, 15, 19]])
    steps = rng.choice(columns, 400)
    values = -0.3 + 0.02 * steps + rng.normal(scale=1e-8, size=400)
    assert np.array_equal(scans.lattice_steps(values), steps - steps.min())
    assert np.array_equal(scans.lattice_steps(values[::-1]), (steps - steps.min())[::-1])
    assert scans.lattice_steps(rng.uniform(size=400)) is None
    assert scans.lattice_steps(np.full(10, 0.5)) is None
    spread = values + 0.007 * (rng.uniform(size=400) > 0.5)
    assert scans.lattice_steps(spread) is None
    # 300 columns, each value rounded by up to 2% of the pitch (float32 far from the
    # frame's origin): their lattice when that rounding is allowed for, the pitch fitted
    # to all the columns (the least gap between two is 4% off, 12 columns off at the end).
    steps = rng.integers(0, 300, size=3000)
    values = 0.02 * steps + rng.uniform(-4e-4, 4e-4, size=3000)
    assert np.array_equal(scans.lattice_steps(values, rounding=8e-4), steps - steps.min())
    assert scans.lattice_steps(values) is None


def test_snapped_steps_read_values_moved_off_their_columns():
    """300 columns 0.02 apart, some missing, each value moved by up to 0.3 of a pitch (a
    view smoothed after the scan, or written with few decimals): each value's column,
    the pitch given 3% off, and so for a patch of 1,024 values over 30 columns. Values
    moved by up to 0.45 of a pitch, or on no lattice: none (their own lattice is none of
    :func:`scans.lattice_steps`')."""
    rng = np.random.default_rng(0)
    for size, count in ((30_000, 300), (1024, 30)):
        columns = np.setdiff1d(np.arange(count), [7, 8, 12, 120, 121, 122, 250])
        steps = rng.choice(columns, size)
        values = 1.5 + 0.02 * steps + rng.uniform(-0.006, 0.006, size=size)
        assert scans.lattice_steps(values) is None
        for pitch in (0.02, 0.0206, 0.0194):
            assert np.array_equal(scans.snapped_steps(values, pitch), steps - steps.min())
        far = 1.5 + 0.02 * steps + rng.uniform(-0.009, 0.009, size=size)
        assert scans.snapped_steps(far, 0.02) is None
        assert scans.snapped_steps(rng.uniform(0.0, 6.0, size=size), 0.02) is None


@pytest.mark.usefixtures("walls_kept")
@pytest.mark.parametrize("frame", ["camera", "x backwards", "orthographic along y"])
def test_points_on_a_camera_s_lattice_are_read_by_its_grid(frame):
    """A view's points in another order, in a frame where the camera looks along an axis
    (a pinhole camera along +z, one along -x, the depth example's orthographic grid
    along y): the organized cloud's own triangles, each facing the sensor; the same as
    float32 and six-digit text, and with noise along the rays (a depth camera's). Turned
    out of that frame, or points sharing pixels (a voxel grid's, a whole object's): no
    lattice."""
    if frame == "orthographic along y":
        grid, viewpoint = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 2000)
        grid = grid - viewpoint
    else:
        grid, _ = two_planes()
        grid[5:9, 20:30] = np.nan
        if frame == "x backwards":
            grid = np.stack([-grid[..., 2], grid[..., 0], grid[..., 1]], axis=-1)
    want = triangles(*organized_surface(grid, np.zeros(3)))
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    shuffled = seen[np.random.default_rng(0).permutation(len(seen))]
    for points in (
        shuffled,
        shuffled.astype(np.float32).astype(float),
        np.array([[float(f"{c:.6g}") for c in row] for row in shuffled.tolist()]),
    ):
        lattice = scans.sensor_grid(points, np.zeros(3))
        assert lattice is not None and np.isfinite(lattice).all(axis=2).sum() == len(points)
        vertices, faces, _ = viewed_surface(points, np.zeros(3))
        assert triangles(vertices, faces) == triangles(*organized_surface(lattice, np.zeros(3)))
        corners = vertices[faces]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        assert (np.einsum("ij,ij->i", normals, -corners.mean(axis=1)) > 0).all()
    assert triangles(*viewed_surface(shuffled, np.zeros(3))[:2]) == want
    if frame == "camera":  # a depth camera's noise moves each point along its own ray
        noisy = (
            grid * (1.0 + 0.01 * np.random.default_rng(1).normal(size=grid.shape[:2]))[..., None]
        )
        points = noisy.reshape(-1, 3)[np.random.default_rng(0).permutation(HEIGHT * WIDTH)]
        points = points[np.isfinite(points).all(axis=1)]
        assert scans.sensor_grid(points, np.zeros(3)) is not None
        assert triangles(*viewed_surface(points, np.zeros(3))[:2]) == triangles(
            *organized_surface(noisy, np.zeros(3))
        )
    turned = shuffled @ random_rotation(np.random.default_rng(1)).T
    assert scans.sensor_grid(turned, np.zeros(3)) is None
    voxels = np.stack(np.meshgrid(*[np.arange(6.0)] * 3), axis=-1).reshape(-1, 3) + 10.0
    assert scans.sensor_grid(voxels, np.zeros(3)) is None


@pytest.mark.parametrize("frame", ["camera", "mesh"])
@pytest.mark.parametrize("rounding", [0.55, 0.7, 0.9])
def test_a_view_written_with_coordinates_rounded_finer_than_its_pixels_is_read_by_its_grid(
    frame, rounding
):
    """The depth example's 1,583 points (an orthographic grid along y) written with
    every coordinate rounded to 0.55 .. 0.9 of a pixel (whole millimetres from a scanner
    whose pixels lie 1.1 .. 1.8 mm apart), in the camera's frame and in the mesh's: each
    lies on its own node of the rounding's lattice, columns of it empty between them.
    Closed up, that lattice is the grid: every triangle joins neighbouring pixels, and
    there are as many as the grid's (read by that lattice unclosed, a piece of 4 or 9
    points was kept at 0.5 and 0.7; by the rounded points' Delaunay triangulation, half
    the triangles at 0.7)."""
    grid, viewpoint = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 1500)
    pitch = float(np.nanmedian(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    points = seen - viewpoint if frame == "camera" else seen
    rounded = np.round(points / (rounding * pitch)) * (rounding * pitch)
    shuffled = rounded[np.random.default_rng(0).permutation(len(seen))]
    vertices, faces, _ = scans.one_view(shuffled, np.zeros(3))
    number = {tuple(point): k for k, point in enumerate(rounded.tolist())}
    read = np.array([number[tuple(point)] for point in vertices.tolist()])
    pixel = np.argwhere(np.isfinite(grid).all(axis=2))  # each seen point's row and column
    corners = pixel[read[faces]]
    reach = np.abs(corners - np.roll(corners, 1, axis=1)).max(axis=2)
    assert (reach == 1).all()  # every edge joins neighbouring pixels
    assert len(faces) >= 0.98 * len(organized_surface(grid, viewpoint)[1])


@pytest.mark.parametrize("frame", ["camera", "turned"])
def test_points_written_more_than_once_are_read_once(frame):
    """The depth example's points with a third of them written twice more (frames
    merged, an export's repeats), in another order: the same surface as the points
    once (the code before refused them: the copies hid behind one another)."""
    grid, viewpoint = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 1500)
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()] - viewpoint
    if frame == "turned":
        seen = seen @ random_rotation(np.random.default_rng(1)).T
    rng = np.random.default_rng(0)
    repeated = np.repeat(seen[rng.choice(len(seen), len(seen) // 3, replace=False)], 2, axis=0)
    points = np.vstack([seen, repeated])[rng.permutation(len(seen) + len(repeated))]
    assert triangles(*scans.one_view(points, np.zeros(3))[:2]) == triangles(
        *scans.one_view(seen, np.zeros(3))[:2]
    )


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_written_once_keeps_each_point_once_in_the_order_written(dtype):
    """Against a plain reference (each point's first appearance, by its coordinates):
    clouds with no point repeated, some repeated many times, and grid points (whose
    coordinates repeat one by one, never all three)."""
    rng = np.random.default_rng(0)
    grid = np.stack(np.meshgrid(np.arange(30.0), np.arange(20.0), [1.0]), axis=-1)
    for points in (
        rng.normal(size=(500, 3)),
        rng.normal(size=(200, 3))[rng.integers(0, 200, size=700)],
        grid.reshape(-1, 3)[rng.permutation(600)],
    ):
        points = points.astype(dtype)
        first: dict[tuple[float, ...], int] = {}
        for k, point in enumerate(points.tolist()):
            first.setdefault(tuple(point), k)
        assert np.array_equal(scans.written_once(points), points[sorted(first.values())])


def test_closed_up_numbers_the_columns_a_rounding_left_empty_between():
    """Columns 1.4 apart rounded to whole numbers (0, 1, 3, 4, 6, ...), any order: the
    sensor's columns in turn. None empty: the steps as they are. One empty (a gap of
    the view's own), or columns on no wider lattice: none."""
    sensor = np.random.default_rng(0).permutation(np.repeat(np.arange(40), 3))
    assert np.array_equal(scans.closed_up(np.round(1.4 * sensor).astype(np.int64)), sensor)
    assert np.array_equal(scans.closed_up(sensor), sensor)
    assert scans.closed_up(np.where(sensor < 20, sensor, sensor + 1)) is None
    assert scans.closed_up(np.where(sensor < 20, sensor, sensor + 5)) is None


def test_a_stray_point_far_off_snaps_to_no_lattice():
    """Values on columns 0.02 apart but for one written 1e35 away (a damaged file): no
    lattice they lie near (its step would pass any integer's range)."""
    values = 0.02 * np.arange(200.0)
    values[17] = 1e35
    assert scans.snapped_steps(values, 0.02) is None


@pytest.mark.usefixtures("walls_kept")
@pytest.mark.parametrize(
    "case",
    [
        "pinhole turned about itself",
        "orthographic turned about itself",
        "mesh's frame",
        "mesh's frame, moved",
    ],
)
def test_a_view_s_pixel_lattice_is_found_in_any_frame(case, monkeypatch):
    """Points of one view written out of their sensor's frame, in another order, as
    float32: the two planes seen by a pinhole camera at the origin turned about it; the
    depth example's orthographic grid, its camera far away at the origin, turned about
    it; the same grid in its mesh's frame, the camera elsewhere. On no lattice in their
    own frame, they lie on one in a frame found from them (:func:`scans.sensor_axes`,
    its line of sight the sensor's to 2e-4: float32 rounds points a thousand times their
    extent from the origin to a hundredth of a pixel), and that lattice is the grid
    itself (the same steps between the same points, whichever way it is turned): the
    view is read without a Delaunay triangulation, its every edge a step or a diagonal of
    the grid, none along the sensor's rays, every triangle facing the camera (in the
    mesh's frame the origin, the sensor a file without one names, stands behind the view:
    the side is the silhouette's, :func:`scans.sensor_side`). Each point moved a tenth of
    a pixel at random, as smoothing after the scan moves it, the view lies on no lattice
    but near one: its nodes are found from the steps the frame was fitted to
    (:func:`scans.snapped_steps`), and the view is read on the same grid."""
    turn = random_rotation(np.random.default_rng(4))
    if case == "pinhole turned about itself":
        grid, _ = two_planes()
        grid[5:9, 20:30] = np.nan
        sight, camera = turn @ [0.0, 0.0, 1.0], np.zeros(3)
    else:
        grid, camera = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 2000)
        sight = turn @ np.array(DEPTH_DIRECTION) / np.linalg.norm(DEPTH_DIRECTION)
        if case == "orthographic turned about itself":
            grid, camera = grid - camera, np.zeros(3)
        camera = turn @ camera
    grid = (grid @ turn.T).astype(np.float32).astype(float)
    if case == "mesh's frame":  # the origin behind the view, the camera before it
        behind = 3.0 * float(np.ptp(grid[np.isfinite(grid).all(axis=2)], axis=0).max()) * sight
        grid, camera = grid + behind, camera + behind
    moved = case == "mesh's frame, moved"
    if moved:
        pitch = np.nanmedian(np.linalg.norm(np.diff(grid, axis=0), axis=2))
        noise = np.random.default_rng(2).normal(size=grid.shape)
        grid = grid + 0.1 * pitch / np.sqrt(3) * noise
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    points = seen[np.random.default_rng(0).permutation(len(seen))]
    assert scans.sensor_grid(points, np.zeros(3)) is None
    frames = list(scans.sensor_axes(points, np.zeros(3)))
    exact = [scans.sensor_grid(points, np.zeros(3), frame) for frame, _, _ in frames]
    snapped = [
        scans.sensor_grid(points, np.zeros(3), frame, steps=steps) for frame, _, steps in frames
    ]
    assert any(found is not None for found in exact) != moved
    lattice, frame = next(
        (found, frame)
        for found, (frame, _, _) in zip(snapped if moved else exact, frames, strict=True)
        if found is not None
    )
    off = min(np.linalg.norm(frame[:, 2] - sight), np.linalg.norm(frame[:, 2] + sight))
    assert off < (1e-2 if moved else 2e-4)
    assert np.isfinite(lattice).all(axis=2).sum() == len(points)
    assert grid_steps(lattice) == grid_steps(grid)

    def no_delaunay(*args, **kwargs):
        raise AssertionError("a Delaunay triangulation")

    monkeypatch.setattr("scipy.spatial.Delaunay", no_delaunay)
    vertices, faces, _ = scans.one_view(points, np.zeros(3))
    assert len(vertices) == len(points) and np.unique(faces).size > 0.95 * len(points)
    edges = point_pairs(vertices[faces], vertices[np.roll(faces, 1, axis=1)])
    diagonals = point_pairs(grid[:-1, :-1], grid[1:, 1:]) | point_pairs(
        grid[:-1, 1:], grid[1:, :-1]
    )
    assert edges <= grid_steps(grid) | diagonals
    if case == "pinhole turned about itself":
        assert unshadowed(vertices, faces, np.zeros(3)).all()
    else:
        assert unshadowed(vertices, faces, sight=sight).all()
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (np.einsum("ij,ij->i", normals, camera - corners.mean(axis=1)) > 0).all()


def reference_grid(
    points: np.ndarray, frame: np.ndarray, steps: scans.Pairs | None = None
) -> np.ndarray | None:
    """:func:`scans.sensor_grid` along ``frame``'s third axis, the sensor at the origin,
    plainly: every point's image tried at once, no trial first."""
    rays = points @ frame
    depth = rays[:, 2]
    rounding = scans.FLOAT32_SPREAD * float(np.linalg.norm(points, axis=1).max())
    images = [(rays[:, :2], rounding)]
    if (depth > 0.0).all() or (depth < 0.0).all():
        images.insert(0, (rays[:, :2] / depth[:, None], 0.0))
    for image, rounding in images:
        if steps is None:
            rows = scans.lattice_steps(image[:, 1], rounding)
            columns = scans.lattice_steps(image[:, 0], rounding)
        else:
            step = np.abs(image[steps[1]] - image[steps[0]])
            along = [step[:, k] > 2.0 * step[:, 1 - k] for k in (0, 1)]
            if min(a.sum() for a in along) < 10:
                continue
            pitch = [float(np.median(step[along[k], k])) for k in (0, 1)]
            rows = scans.snapped_steps(image[:, 1], pitch[1])
            columns = scans.snapped_steps(image[:, 0], pitch[0])
        if rows is None or columns is None:
            continue
        rows, columns = scans.closed_up(rows), scans.closed_up(columns)
        if rows is None or columns is None:
            continue
        height, width = int(rows.max()) + 1, int(columns.max()) + 1
        pixel = rows * width + columns
        if height * width > scans.LATTICE_MAX_FILL * len(points) or (
            np.unique(pixel).size < len(points)
        ):
            continue
        grid = np.full((height * width, 3), np.nan)
        grid[pixel] = points
        return grid.reshape(height, width, 3)
    return None


@pytest.mark.parametrize("moved", [0.0, 0.05, 0.5])
def test_a_lattice_s_trials_only_refuse_sooner(moved):
    """:func:`scans.sensor_grid` tries a frame on a sample of the points (a lattice) or
    on a patch of them (near a lattice) before it makes every point's image: in every
    frame a search finds, it gives the grid the plain reading of every point at once
    gives, or none where that gives none. The depth example at 30,000 pixels turned and
    written as float32: on its lattice, each point moved a twentieth of a pixel (near
    it), and half a pixel (on none)."""
    grid, camera = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 30000)
    grid = grid - camera
    if moved:
        pitch = np.nanmedian(np.linalg.norm(np.diff(grid, axis=0), axis=2))
        noise = np.random.default_rng(2).normal(size=grid.shape)
        grid = grid + moved * pitch / np.sqrt(3) * noise
    turn = random_rotation(np.random.default_rng(4))
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    points = (seen @ turn.T).astype(np.float32).astype(float)
    points = points[np.random.default_rng(0).permutation(len(points))]
    frames = list(scans.sensor_axes(points, np.zeros(3)))
    trials = scans.LatticeTrials(points, np.zeros(3))
    found = 0
    for frame, _, steps in frames:
        for given in (None, steps):
            want = reference_grid(points, frame, given)
            got = scans.sensor_grid(points, np.zeros(3), frame, (2,), given, trials)
            assert (got is None) == (want is None)
            if want is not None:
                assert np.array_equal(got, want, equal_nan=True)
                found += 1
    assert (found > 0) == (moved < 0.5)


def on_a_found_lattice(points: np.ndarray) -> bool:
    """Whether a frame :func:`scans.sensor_axes` finds from ``points``' steps (no sensor
    placed) holds them exactly on a pixel lattice."""
    return any(
        scans.sensor_grid(points, np.zeros(3), frame, along=(2,)) is not None
        for frame, _, _ in scans.sensor_axes(points, np.zeros(3))
    )


def test_a_scan_seen_from_far_off_its_line_of_sight_is_found_in_rounds(monkeypatch):
    """A range scan of the quadruped (SHREC'17's orbiting camera) in its mesh's frame,
    the first rounds started from the direction it spreads least in, 54 degrees off its
    line of sight: each round reads its steps across the sight the last one found, and a
    later round finds its lattice (:data:`scans.AXES_ROUNDS`); the first alone does not."""
    points, direction, _ = range_image(sample_mesh("quadruped", 0), np.random.default_rng(3))
    seen = points.reshape(-1, 3)[np.isfinite(points).all(axis=2).ravel()]
    seen = seen[np.random.default_rng(0).permutation(len(seen))]
    assert np.degrees(np.arccos(abs(scans.least_spread(seen) @ direction))) > 45
    monkeypatch.setattr(scans, "unfolded_sight", scans.least_spread)
    assert on_a_found_lattice(seen)
    monkeypatch.setattr(scans, "AXES_ROUNDS", 1)
    assert not on_a_found_lattice(seen)


def mesh_frame_scan(pose: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A range scan of the quadruped's ``pose`` (SHREC'17's orbiting camera, ``seed``) in
    its mesh's frame, no sensor placed: its organized cloud, its points in a fixed random
    order, its line of sight and its pitch."""
    grid, direction, pitch = range_image(
        sample_mesh("quadruped", pose), np.random.default_rng(seed)
    )
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    return grid, seen[np.random.default_rng(0).permutation(len(seen))], direction, pitch


@pytest.mark.parametrize("pose", [0, 1, 2])
def test_a_long_narrow_view_is_found_along_the_sight_it_overlaps_itself_least_in(pose):
    """The quadruped's scan seen from its side and below (the seed's orbit), in its mesh's
    frame: long and narrow, it spreads least 80 degrees off its line of sight, and the
    rounds started there found no lattice (and the points, seen from there, were refused).
    Seen along their :func:`scans.unfolded_sight` they hardly overlap, and its rounds find
    the scanner's lattice: the view is read as its grid (its triangles to 1%, edges near
    the shadow rule's angle judged along the sight found), every point on a triangle."""
    grid, seen, direction, _ = mesh_frame_scan(pose, 1)

    def off(sight: np.ndarray) -> float:
        return float(np.degrees(np.arccos(min(1.0, abs(sight @ direction)))))

    assert off(scans.least_spread(seen)) > 80
    assert off(scans.unfolded_sight(seen)) < 20
    assert on_a_found_lattice(seen)
    vertices, faces, _ = scans.one_view(seen, np.zeros(3))
    _, grid_faces = organized_surface(grid, scans.guessed_viewpoint(seen, direction))
    assert len(vertices) == len(seen)
    assert len(faces) == pytest.approx(len(grid_faces), rel=0.01)  # a shadowed edge or two


def test_a_voxel_filtered_view_in_its_mesh_s_frame_is_read_from_afar_along_its_sight():
    """The quadruped's scan thinned by a voxel filter of two pixels (on no lattice) in its
    mesh's frame, no sensor placed, spreading least 41 degrees off its line of sight: seen
    from there 28% of its points hid behind others and it was refused; seen from afar along
    its :func:`scans.unfolded_sight` every one lies on the surface, each triangle facing
    one way."""
    _, seen, direction, pitch = mesh_frame_scan(0, 0)
    means = voxel_means(seen, 2 * pitch)
    vertices, faces, _ = scans.one_view(means, np.zeros(3))
    assert len(vertices) == len(means) and np.unique(faces).size > 0.99 * len(means)
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    facing = np.sign(normals @ direction)
    assert abs(facing.sum()) > 0.99 * len(faces)


def test_median_edges_are_each_point_s_middle_edge():
    """:func:`scans.median_edges` against a plain loop over the points: the Delaunay
    triangulation of random points far from the origin (their numbers' offsets must not
    blur their lengths), and a point on no edge."""
    from scipy.spatial import Delaunay

    image = 1e3 + np.random.default_rng(0).random((3000, 2))
    indptr, indices = Delaunay(image).vertex_neighbor_vertices
    indptr = np.concatenate([indptr, [indptr[-1]]])  # one more point, on no edge
    image = np.concatenate([image, [[0.0, 0.0]]])
    want = np.full(len(image), np.inf)
    for point in range(len(image) - 1):
        others = indices[indptr[point] : indptr[point + 1]]
        lengths = np.sort(np.linalg.norm(image[others] - image[point], axis=1))
        want[point] = lengths[(len(lengths) - 1) // 2]
    np.testing.assert_allclose(scans.median_edges(image, (indptr, indices)), want, rtol=1e-9)


def test_the_rounds_stop_when_noise_turns_the_sight_and_no_lattice_draws_it_in():
    """The depth example's view turned about its camera, each point moved half a pixel at
    random (near no lattice): each round turns the orthographic line of sight by a
    fraction of a degree, as far as the round before, and the rounds stop there
    (:data:`scans.AXES_STALL_DEGREES`) instead of running all :data:`scans.AXES_ROUNDS`.
    A grid on its lattice still settles on it (the scans read in their mesh's frame
    above)."""
    grid, camera = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 6000)
    pitch = np.nanmedian(np.linalg.norm(np.diff(grid, axis=1), axis=2))
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()] - camera
    moved = seen + np.random.default_rng(2).normal(scale=0.5 * pitch / np.sqrt(3), size=seen.shape)
    points = moved @ random_rotation(np.random.default_rng(1)).T
    frames = [frame for frame, _, _ in scans.sensor_axes(points, np.zeros(3))]
    assert len(frames) < 2 + scans.AXES_ROUNDS // 2
    assert all(scans.sensor_grid(points, np.zeros(3), f, along=(2,)) is None for f in frames)


def test_a_voxel_filtered_view_keeps_its_surface(monkeypatch):
    """The depth example's view filtered to one point per voxel of two pixels (each
    voxel's mean, as point-cloud tools thin a scan), turned about its camera: on no
    lattice, read by Delaunay's triangulation of its image, it covers what its organized
    cloud covers as seen from the camera (to 4%, the voxels' means lying a little inside
    the silhouette) and no more (no gap bridged). A gap is an edge long against its
    corners' own spacing (their median edges): the nearest neighbour's distance, the
    spacing before, is short where the means crowd, and the view kept about half its
    surface."""
    grid, camera = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 6000)
    sight = np.array(DEPTH_DIRECTION) / np.linalg.norm(DEPTH_DIRECTION)
    pitch = np.nanmedian(np.linalg.norm(np.diff(grid, axis=1), axis=2))
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    means = voxel_means(seen, 2 * pitch)
    turn = random_rotation(np.random.default_rng(6))
    points = (means - camera) @ turn.T

    def covered(vertices: np.ndarray, faces: np.ndarray, direction: np.ndarray) -> float:
        corners = vertices[faces]
        doubled = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        return float(np.abs(doubled @ direction).sum() / 2)

    def no_lattice(*args, **kwargs):
        raise AssertionError("read on a lattice")

    monkeypatch.setattr(scans, "organized_surface", no_lattice)
    vertices, faces, _ = viewed_surface(points, np.zeros(3))
    assert len(vertices) == len(means) and np.unique(faces).size > 0.95 * len(means)
    whole = covered(*organized_surface(grid, camera), sight)
    share = covered(vertices, faces, turn @ sight) / whole
    assert 0.96 < share < 1.01


@pytest.mark.parametrize("turn_seed", [2, 5])  # the least spread's axis toward the camera, away
def test_one_view_written_in_another_frame_is_seen_from_where_it_is_thinnest(
    turn_seed, monkeypatch
):
    """The depth example's view written in its mesh's frame and turned, each point moved
    a thousandth of a pixel at random (off any lattice, and not read near one, as if
    moved farther; seen from the origin, most of its points hide behind others): read as
    seen from afar along the direction the points spread least in, the organized cloud's
    surface (every point on it, the same area to 0.5%), every triangle facing the camera
    whichever way that direction's sign fell (the silhouette's side,
    :func:`scans.sensor_side`)."""
    grid, camera = depth_scan(sample_mesh(*PARTIAL_SOURCE), np.array(DEPTH_DIRECTION), 2000)
    pitch = np.nanmedian(np.linalg.norm(np.diff(grid, axis=0), axis=2))
    grid = grid + np.random.default_rng(1).normal(scale=1e-3 * pitch, size=grid.shape)
    turn = random_rotation(np.random.default_rng(turn_seed))
    grid, camera = grid @ turn.T, turn @ camera
    sight = turn @ np.array(DEPTH_DIRECTION)
    vertices, faces = organized_surface(grid, scans.guessed_viewpoint(grid.reshape(-1, 3), sight))
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()]
    shuffled = seen[np.random.default_rng(0).permutation(len(seen))]
    monkeypatch.setattr(scans, "snapped_steps", lambda values, pitch: None)  # as if farther
    assert all(
        scans.sensor_grid(shuffled, np.zeros(3), f, steps=steps) is None
        for f, _, steps in scans.sensor_axes(shuffled, np.zeros(3))
    )
    with pytest.raises(PointCloudError, match=r"not one view from the sensor at \(0, 0, 0\)"):
        viewed_surface(shuffled, np.zeros(3))
    read, read_faces, _ = scans.one_view(shuffled, np.zeros(3))
    used = np.unique(read_faces).size
    assert len(read) == len(seen) and used >= np.unique(faces).size - 0.01 * len(seen)

    def area(points: np.ndarray, triangles: np.ndarray) -> float:
        corners = points[triangles]
        doubled = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        return float(np.linalg.norm(doubled, axis=1).sum() / 2)

    assert area(read, read_faces) == pytest.approx(area(vertices, faces), rel=0.005)
    corners = read[read_faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (np.einsum("ij,ij->i", normals, camera - corners.mean(axis=1)) > 0).all()
    text = "\n".join(f"{x!r} {y!r} {z!r}" for x, y, z in shuffled.tolist()).encode()
    assert read_mesh(text, "view.xyz").cloud == Cloud(len(seen))


@pytest.mark.usefixtures("walls_kept")
def test_a_pcd_without_its_grid_is_read_in_its_sensor_s_frame(monkeypatch):
    """A PCD of HEIGHT 1 whose points were moved out of the camera's frame, its VIEWPOINT
    the camera's position and orientation (a quaternion, PCL's ``w x y z``): the lattice
    is found in the camera's frame, the organized cloud's own triangles. With the
    identity orientation the points lie on no lattice in the frame given, and the
    camera's frame is found from them (:func:`scans.sensor_axes`): the same pixels'
    grid. A VIEWPOINT that is not numbers is refused with a sentence."""
    quarter_turn = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])  # about z
    np.testing.assert_allclose(scans._rotation(2 * quarter_turn) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    orientation = np.array([0.9, 0.3, -0.2, 0.25])
    turn = scans._rotation(orientation)
    np.testing.assert_allclose(turn @ turn.T, np.eye(3), atol=1e-12)
    points, _ = two_planes()
    points[5:9, 20:30] = np.nan
    position = np.array([0.5, -2.0, 7.0])
    moved = points @ turn.T + position
    seen = moved.reshape(-1, 3)[np.random.default_rng(0).permutation(HEIGHT * WIDTH)]
    found = []
    search = scans.sensor_grid
    monkeypatch.setattr(
        scans, "sensor_grid", lambda *a, **k: found.append(search(*a, **k)) or found[-1]
    )
    read, faces, cloud = read_pcd(pcd(seen.reshape(1, -1, 3), "binary", position, orientation))
    assert found[-1] is not None and cloud == Cloud(len(read), None, 0)
    single = moved.astype(np.float32).astype(float)
    assert triangles(read, faces) == triangles(*organized_surface(single, position))
    found.clear()
    read, faces, _ = read_pcd(pcd(seen.reshape(1, -1, 3), "binary", position))
    assert found[0] is None and found[-1] is not None and len(read) == HEIGHT * WIDTH - 40
    assert grid_steps(found[-1]) == grid_steps(single)
    assert triangles(read, faces) == triangles(*organized_surface(found[-1], position))
    bad = pcd(seen.reshape(1, -1, 3), viewpoint=position).replace(b"VIEWPOINT 0.5", b"VIEWPOINT x")
    with pytest.raises(UnreadableMeshError, match="VIEWPOINT is not seven numbers"):
        read_mesh(bad, "scan.pcd")


@pytest.mark.parametrize("direction", [(0, 0, 2), (1, 0, 0), (0.95, 0.3, 0), (-1, 2, -3)])
def test_a_view_s_frame_is_right_handed_and_looks_along_its_direction(direction):
    """The image plane's two axes and the view direction: orthonormal rows, the third
    the direction made a unit vector, the frame right-handed (the viewed surface's
    winding relies on it), whichever axis the direction lies near; several directions'
    frames at once, each as its own."""
    frame = view_frame(np.array(direction, dtype=float))
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(frame[2], np.array(direction) / np.linalg.norm(direction))
    assert np.linalg.det(frame) == pytest.approx(1.0)
    several = np.array([direction, (0, 0, 1), (1, 0.5, 0)], dtype=float)
    for stacked, one in zip(view_frame(several), several, strict=True):
        np.testing.assert_array_equal(stacked, view_frame(one))


@pytest.mark.usefixtures("walls_kept")
def test_points_in_a_text_file_or_a_mesh_file_without_faces_are_read_as_one_view():
    """XYZ, PTS and CSV (a header or a count line, more columns, commas) and a PLY of
    vertices alone: the points as seen from the origin of their frame."""
    points, _ = two_planes()
    flat = points.reshape(-1, 3)
    want = triangles(*viewed_surface(flat, np.zeros(3))[:2])
    rows = [f"{x!r} {y!r} {z!r}" for x, y, z in flat.tolist()]
    files = {
        "scan.xyz": "\n".join(f"{row} 0.1 0.2 0.9" for row in rows),
        "scan.pts": f"{len(rows)}\n" + "\n".join(f"{row} 17 255 255 255" for row in rows),
        "scan.csv": "x,y,z\n" + "\n".join(row.replace(" ", ",") for row in rows),
        "scan.ply": trimesh.PointCloud(flat).export(file_type="ply", encoding="ascii"),
    }
    single = triangles(*viewed_surface(flat.astype(np.float32).astype(float), np.zeros(3))[:2])
    for name, text in files.items():
        cleaned = read_mesh(text.encode() if isinstance(text, str) else text, name)
        assert cleaned.cloud == Cloud(HEIGHT * WIDTH, None, 0), name
        # The larger piece, the far plane, as the grid's.
        assert cleaned.mesh.n_vertices == HEIGHT * (WIDTH - 15), name
        surface = triangles(cleaned.mesh.vertices, cleaned.mesh.faces)
        assert surface <= (single if name == "scan.ply" else want), name  # PLY: float32
    with pytest.raises(UnreadableMeshError, match="x, y and z as numbers"):
        read_mesh(b"1 2 3\n4 5 six\n", "scan.xyz")


@pytest.mark.parametrize(
    ("header", "order"),
    [
        (",x,y,z", "ixyz"),  # a table written with its row numbers first (pandas)
        ("id;X;Y;Z;intensity", "ixyzn"),
        ("//X,Y,Z,R,G,B", "xyznnn"),  # CloudCompare
        ('"X","Y","Z","Intensity"', "xyzn"),  # PDAL
        ("z y x", "zyx"),
        ("a b c", "xyz"),  # no column named: the first three
    ],
)
def test_a_text_file_s_header_says_which_columns_hold_x_y_and_z(header, order):
    """The columns a header line names x, y and z are the points', in whatever order
    and among whatever other columns (the code before read the first three: a table's
    row numbers as x, its columns out of order as a mirror image)."""
    points = np.array([[1.5, 2.5, 3.5], [4.0, 5.0, 6.0], [7.0, 8.0, 9.25]])
    split = "," if "," in header else (";" if ";" in header else " ")
    rows = []
    for number, point in enumerate(points):
        value = {"i": float(number), "n": 7.0, **dict(zip("xyz", point, strict=True))}
        rows.append(split.join(repr(float(value[column])) for column in order))
    text = "\n".join([header, *rows]).encode()
    assert np.array_equal(mesh_io._parse_text_points(text), points)


def test_points_that_make_no_surface_are_refused_with_a_sentence():
    """A whole object's points hide one another from any one sensor (a file of them is
    read as the view that sees most of them: below); too few points make no surface, nor
    do points on one line, from anywhere: the sentence names the sensor the file gave."""
    sphere = trimesh.creation.icosphere(subdivisions=4).vertices
    with pytest.raises(PointCloudError, match="hide behind others, as a whole object"):
        viewed_surface(sphere, np.array([0.0, 0.0, 50.0]))
    with pytest.raises(PointCloudError, match="too few points"):
        read_mesh(b"0 0 1\n1 0 1\n", "two.xyz")
    line = np.array([[0.0, 0, 1], [1, 0, 1], [2, 0, 1], [3, 0, 1]])
    with pytest.raises(PointCloudError, match="on one line"):
        viewed_surface(line, np.zeros(3))
    text = "\n".join(f"{x!r} {y!r} {z!r}" for x, y, z in line.tolist()).encode()
    with pytest.raises(PointCloudError, match="lie on one line: no surface joins them"):
        read_mesh(text, "line.xyz")
    # A line's points written as float32 (a PLY's usual coordinates) lie some 1e-7 off it.
    along = np.outer(np.random.default_rng(0).normal(size=500), [1.0, 2.0, 3.0])
    rounded = trimesh.PointCloud(along.astype(np.float32)).export(file_type="ply")
    with pytest.raises(PointCloudError, match="lie on one line"):
        read_mesh(rounded, "line.ply")


@pytest.mark.parametrize("camera", [[0.0, 0.0, 6.0], [3.6, 4.8, 0.0], [-2.0, 4.0, 4.0]])
def test_hidden_point_removal_sees_the_cap_facing_its_camera(camera):
    """Katz, Tal and Basri's hidden point removal against the exact answer: of a unit
    sphere's points, a camera at c sees those in front of their tangent plane, p . c > 1,
    the cap above the horizon at 1 / |c| along c. The points it sees, in order and each
    once, lie within 0.05 of that cap (the method keeps a few grazing ones past the
    horizon), and it sees every point more than 0.05 above the horizon."""
    sphere = trimesh.creation.icosphere(subdivisions=4).vertices
    c = np.array(camera)
    seen = scans.visible_points(sphere, c)
    height, horizon = sphere @ c / np.linalg.norm(c), 1.0 / np.linalg.norm(c)
    assert np.array_equal(seen, np.unique(seen))
    assert height[seen].min() > horizon - 0.05
    assert np.isin(np.flatnonzero(height > horizon + 0.05), seen).all()


def test_a_whole_object_s_points_are_read_as_the_view_that_sees_most_of_them():
    """A sphere's points around the origin (some beside or behind a sensor there; from
    afar, no one view) are read as the view of a camera ``WHOLE_DISTANCE`` extents from
    their centre, six radii: the cap it sees, (1 - 1/6) / 2 of the points and a few
    grazing ones (:func:`test_hidden_point_removal_sees_the_cap_facing_its_camera`), the
    rest counted hidden and left out, every triangle facing the camera. Its rim, seen at a
    grazing angle, is left out as a camera's view leaves it (the shadow rule), so the
    surface is 0.65-0.8 of the cap's area."""
    sphere = trimesh.creation.icosphere(subdivisions=4).vertices
    text = "\n".join(f"{x!r} {y!r} {z!r}" for x, y, z in sphere.tolist()).encode()
    read = read_mesh(text, "object.xyz")
    cloud = read.cloud
    assert cloud is not None and cloud.grid is None and cloud.support is None
    assert cloud.hidden == len(sphere) - cloud.points
    assert (1 - 1 / 6) / 2 <= cloud.points / len(sphere) <= (1 - 1 / 6) / 2 + 0.03
    vertices, faces = read.mesh.vertices, read.mesh.faces
    sight = vertices.mean(axis=0) / np.linalg.norm(vertices.mean(axis=0))
    camera = scans.WHOLE_DISTANCE * np.ptp(sphere, axis=0).max() * sight
    assert (vertices @ sight > 1 / 6 - 0.05).all()
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (np.einsum("ij,ij->i", normals, camera - corners.mean(axis=1)) > 0).all()
    cap = 2 * np.pi * (1 - 1 / 6)
    assert 0.65 * cap < np.linalg.norm(normals, axis=1).sum() / 2 < 0.8 * cap


@pytest.mark.parametrize(("name", "pose"), [("quadruped", 0), ("biped", 2), ("spider", 1)])
def test_a_whole_object_s_view_joins_only_points_near_along_its_surface(name, pose):
    """A mesh's vertices as points, read as the view that sees most of them: its edges
    join points near along the mesh (the path along the mesh's own edges, which runs up to
    about twice the straight line on a coarse mesh, is within 3 times each edge's length
    for 98% of them, 3.5 times for 99%), not the sheets that touch in space behind or
    beside one another; the points it sees are the mesh's, each once."""
    from scipy.sparse.csgraph import dijkstra

    mesh = sample_mesh(name, pose)
    vertices, faces, cloud = scans.whole_view(mesh.vertices)
    index = {point: i for i, point in enumerate(map(tuple, mesh.vertices.tolist()))}
    own = np.array([index[point] for point in map(tuple, vertices.tolist())])
    assert np.unique(own).size == len(own) == cloud.points
    assert cloud.points + cloud.hidden == mesh.n_vertices
    corners = own[faces]
    edges = np.unique(np.sort(corners[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    starts, row = np.unique(edges[:, 0], return_inverse=True)
    along = dijkstra(edge_graph(mesh), directed=False, indices=starts)[row, edges[:, 1]]
    straight = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    ratio = along / straight
    assert np.mean(ratio > 3.0) <= 0.02 and np.percentile(ratio, 99) < 3.5


def seen_on_the_mesh(mesh: Mesh, camera: np.ndarray) -> np.ndarray:
    """(n,) whether each of ``mesh``'s vertices is seen from ``camera`` (3,): no triangle
    but its own crosses the segment between them (Moller and Trumbore's ray-triangle
    test, each vertex's ray against every triangle)."""
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    first, second = b - a, c - a
    seen = np.zeros(mesh.n_vertices, dtype=bool)
    for i, point in enumerate(mesh.vertices):
        ray = point - camera
        length = np.linalg.norm(ray)
        ray /= length
        across = np.cross(ray, second)
        det = np.einsum("ij,ij->i", first, across)
        inverse = 1.0 / np.where(np.abs(det) > 1e-12, det, np.inf)
        offset = camera - a
        u = np.einsum("ij,ij->i", offset, across) * inverse
        turned = np.cross(offset, first)
        v = turned @ ray * inverse
        t = np.einsum("ij,ij->i", second, turned) * inverse
        hits = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < length * (1 - 1e-4))
        seen[i] = not np.any(hits & ~(mesh.faces == i).any(axis=1))
    return seen


@pytest.mark.parametrize(("name", "pose"), [("quadruped", 2), ("biped", 2), ("hand", 2)])
def test_a_noisy_whole_s_view_holds_what_its_camera_sees(name, pose):
    """A mesh's vertices as points with Gaussian noise of 0.5% of their diagonal: the
    points :func:`whole_view` sees are those its camera sees of the mesh (traced against
    its triangles from where :func:`whole_camera` stands), 95% of them, and they hold at
    least 65% of those. Hidden point removal on the noisy points themselves held 46-54%
    (a noisy front looks to it like a rough hull); each seen on the plane of its nearest
    neighbours, as without noise (69-86% of the view, all of it truly seen)."""
    mesh = sample_mesh(name, pose)
    diagonal = np.linalg.norm(np.ptp(mesh.vertices, axis=0))
    noise = np.random.default_rng(0).normal(scale=0.005 * diagonal, size=mesh.vertices.shape)
    points = mesh.vertices + noise
    vertices, _, cloud = scans.whole_view(points)
    index = {point: i for i, point in enumerate(map(tuple, points.tolist()))}
    seen = np.zeros(mesh.n_vertices, dtype=bool)
    seen[[index[point] for point in map(tuple, vertices.tolist())]] = True
    assert np.count_nonzero(seen) == cloud.points
    truth = seen_on_the_mesh(mesh, scans.whole_camera(points))
    assert np.mean(truth[seen]) >= 0.95
    assert np.mean(seen[truth]) >= 0.65


def test_a_dense_cloud_is_thinned_by_a_voxel_filter():
    """:func:`thinned`: a sphere's 40,962 points to about 4,000 (within a tenth), each the
    mean of the points in its cube (its cube's points within a cube's diagonal of it);
    fewer points than asked for are returned as they are, each its own."""
    sphere = trimesh.creation.icosphere(subdivisions=6).vertices
    means, cube = scans.thinned(sphere, 4000)
    assert 3600 <= len(means) <= 4400 and cube.shape == (len(sphere),)
    counts = np.bincount(cube, minlength=len(means))
    assert counts.min() >= 1
    for k in range(3):
        assert np.allclose(np.bincount(cube, sphere[:, k]) / counts, means[:, k])
    reach = np.linalg.norm(sphere - means[cube], axis=1).max()
    spacing = np.sqrt(4 * np.pi / len(means))  # about the cubes' side on the unit sphere
    assert reach < np.sqrt(3) * 2 * spacing
    few, own = scans.thinned(sphere[:100], 4000)
    assert few is not None and np.array_equal(few, sphere[:100])
    assert np.array_equal(own, np.arange(100))


def _read_both_ways(monkeypatch, points):
    """:func:`one_view` of ``points`` from the origin, and what :func:`plainly_whole`
    said, then the same read with it saying no (every try made on all the points)."""
    said = []
    test = scans.plainly_whole

    def spied(*args):
        said.append(test(*args))
        return said[-1]

    monkeypatch.setattr(scans, "plainly_whole", spied)
    fast = scans.one_view(points, np.zeros(3))
    monkeypatch.setattr(scans, "plainly_whole", lambda *args: False)
    return fast, scans.one_view(points, np.zeros(3)), said


def test_a_dense_whole_is_read_as_one_without_every_point_tried_from_afar(monkeypatch):
    """A whole object's 39,970 points (the quadruped's mesh Loop-subdivided twice, moved off
    the origin) are plainly no view (:func:`plainly_whole`): read as a whole
    (:func:`whole_view`) without the try from afar on all of them, exactly as that try's
    failure would have them read; a dense view written away from its sensor, moved off
    its pixel lattice, is still tried from afar on all its points, and read as before."""
    rng = np.random.default_rng(3)
    mesh = sample_mesh(*PARTIAL_SOURCE)
    vertices = subdivided(subdivided(mesh)).vertices
    whole = vertices[rng.permutation(len(vertices))] @ random_rotation(rng) + 2.0
    tried = []
    full = scans.viewed_surface

    def counted(points, *args, **kwargs):
        tried.append(len(points))
        return full(points, *args, **kwargs)

    monkeypatch.setattr(scans, "viewed_surface", counted)
    fast, slow, said = _read_both_ways(monkeypatch, whole)
    assert said == [True] and len(whole) > 9 * scans.WHOLE_POINTS
    # read plainly whole: the first try alone; told no: the first try, then from afar
    assert tried.count(len(whole)) == 1 + 2
    for a, b in zip(fast, slow, strict=True):
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
    assert fast[2].hidden > 0

    grid, viewpoint = depth_scan(mesh, np.array(DEPTH_DIRECTION), 20000)
    seen = grid.reshape(-1, 3)[np.isfinite(grid).all(axis=2).ravel()] - viewpoint
    pitch = float(np.nanmedian(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
    moved = seen + rng.normal(scale=0.5 * pitch, size=seen.shape)
    view = moved[rng.permutation(len(moved))] @ random_rotation(rng) + 3.0 * np.ptp(seen)
    fast, slow, said = _read_both_ways(monkeypatch, view)
    assert said == [False] and len(view) > scans.WHOLE_POINTS
    for a, b in zip(fast, slow, strict=True):
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
    assert fast[2].hidden is None


def test_a_noisy_plane_s_points_are_moved_onto_it():
    """:func:`plane_projected`: points of a plane stay where they are; with noise across
    it, each is moved onto the plane of its nearest, the noise's spread cut by more than
    half; along the plane a point moves a tenth of the noise's sigma (the median; at most
    twice the sigma, where its neighbours' plane tilts)."""
    rng = np.random.default_rng(0)
    flat = np.column_stack([rng.uniform(size=(2000, 2)), np.zeros(2000)]) @ random_rotation(rng)
    assert np.allclose(scans.plane_projected(flat, 16), flat, atol=1e-12)
    noisy = np.column_stack([rng.uniform(size=(2000, 2)), rng.normal(scale=0.01, size=2000)])
    projected = scans.plane_projected(noisy, 16)
    assert np.std(projected[:, 2]) < 0.5 * np.std(noisy[:, 2])
    along = np.linalg.norm(projected[:, :2] - noisy[:, :2], axis=1)
    assert np.median(along) < 0.001 and along.max() < 0.02


@pytest.mark.parametrize(
    ("damage", "sentence"),
    [
        (lambda b: b.replace(b"DATA ascii", b"DATA lzma"), "ascii, binary or binary_compressed"),
        (lambda b: b.replace(b"FIELDS x y z rgb", b"FIELDS a b c rgb"), "no x, y and z"),
        (lambda b: b[: len(b) // 2], "damaged or truncated"),
        (lambda b: b.replace(b" 4278190080\n", b" red\n", 1), "damaged or truncated"),
        (lambda b: b.replace(b"WIDTH 40", b"WIDTH forty"), "not a whole number"),
        (lambda b: b.replace(b"COUNT 1 1 1 1", b"COUNT 1 1 1 one"), "not a whole number"),
        (lambda b: b.split(b"DATA")[0], "no DATA line"),
        (lambda b: b.replace(b"TYPE F F F U", b"TYPE F F F"), "disagree"),
    ],
)
def test_a_damaged_pcd_is_refused_with_a_sentence(damage, sentence):
    points, _ = two_planes()
    with pytest.raises(UnreadableMeshError, match=sentence):
        read_mesh(damage(pcd(points)), "scan.pcd")


def test_a_truncated_binary_pcd_is_refused():
    points, _ = two_planes()
    data = pcd(points, "binary")
    with pytest.raises(UnreadableMeshError, match="damaged or truncated"):
        read_mesh(data[:-100], "scan.pcd")


def test_a_structured_e57_scan_is_read_as_its_grid_from_the_scanner_s_position():
    points = framed(two_planes()[0])
    vertices, faces, grid = read_e57(e57_scan(points))
    want_faces = assert_read_as(points, vertices, faces, grid)
    # The scan's pose places its points, and its origin is where the scanner stood: the
    # same shadows, the whole moved.
    moved = np.array([5.0, -2.0, 1.0])
    vertices, faces, _ = read_e57(e57_scan(points + moved, moved))
    np.testing.assert_allclose(
        vertices - moved, organized_surface(points, np.zeros(3))[0], atol=1e-6
    )
    np.testing.assert_array_equal(faces, want_faces)
    assert read_mesh(e57_scan(points), "scan.e57").cloud == grid


def test_an_e57_file_that_is_not_one_structured_scan_is_refused_with_a_sentence():
    points, _ = two_planes()
    with pytest.raises(PointCloudError, match="no grid"):
        read_mesh(e57_scan(points, grid=False), "scan.e57")
    with pytest.raises(UnreadableMeshError, match="holds 2 scans; upload one scan per file"):
        read_mesh(e57_scan(points, scans=2), "scan.e57")
    data = e57_scan(points)
    for damaged in (b"not an e57 file at all", data[: len(data) // 2]):
        with pytest.raises(UnreadableMeshError, match="E57"):
            read_mesh(damaged, "scan.e57")
    with pytest.raises(UnreadableMeshError, match="too many to read here"):
        read_e57(data, max_bytes=1000)
