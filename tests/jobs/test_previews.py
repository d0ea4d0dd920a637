"""The previews a descriptor job makes: a small unit-size GLB in the canonical frame and a
PNG thumbnail seen along its axis of least extent."""

from __future__ import annotations

import io
import subprocess
import sys

import numpy as np
import trimesh
from PIL import Image
from scipy.spatial.transform import Rotation

from worker.engine.mesh_io import Mesh
from worker.jobs.previews import (
    CANONICAL_NODE,
    PREVIEW_FACES,
    THUMBNAIL_PIXELS,
    preview_glb,
    preview_mesh,
    thumbnail_png,
)


def _box(extents) -> Mesh:
    box = trimesh.creation.box(extents=extents).subdivide().subdivide().subdivide()
    box.apply_translation([5.0, -3.0, 7.0])
    return Mesh(vertices=np.asarray(box.vertices), faces=np.asarray(box.faces))


def _sphere() -> Mesh:
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=40.0)  # 20480 faces
    return Mesh(vertices=np.asarray(sphere.vertices), faces=np.asarray(sphere.faces))


def test_preview_is_decimated_centred_and_within_the_unit_sphere():
    sphere = _sphere()
    small = preview_mesh(sphere)
    assert len(sphere.faces) > PREVIEW_FACES >= len(small.faces) > 0.9 * PREVIEW_FACES
    radii = np.linalg.norm(small.vertices, axis=1)
    assert radii.max() <= 1.0 + 1e-12 and radii.min() > 0.97  # still a sphere, now unit


def test_a_small_mesh_is_kept_whole():
    box = _box((2.0, 0.2, 1.0))
    assert len(box.faces) <= PREVIEW_FACES
    small = preview_mesh(box)
    np.testing.assert_array_equal(small.faces, box.faces)
    np.testing.assert_allclose(0.5 * (small.vertices.min(0) + small.vertices.max(0)), 0, atol=1e-12)


def test_glb_reads_back_as_the_preview_mesh():
    sphere = _sphere()
    small = preview_mesh(sphere)
    read = trimesh.load(io.BytesIO(preview_glb(small)), file_type="glb", force="mesh")
    assert len(read.faces) == len(small.faces)
    np.testing.assert_allclose(
        np.sort(np.linalg.norm(read.vertices, axis=1)),
        np.sort(np.linalg.norm(small.vertices, axis=1)),
        atol=1e-6,
    )


def _silhouette(png: bytes) -> tuple[int, int]:
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))
    assert image.shape[:2] == (THUMBNAIL_PIXELS, THUMBNAIL_PIXELS)
    rows, cols = np.nonzero(image[:, :, 3] > 0)
    return int(np.ptp(rows)) + 1, int(np.ptp(cols)) + 1


def test_thumbnail_shows_the_largest_outline_across_in_any_file_orientation():
    # The same 2 by 1 by 0.2 box, however the file lays it: seen along its least extent,
    # the largest across, twice as wide as tall.
    for extents in ((2.0, 0.2, 1.0), (0.2, 1.0, 2.0), (1.0, 2.0, 0.2)):
        height, width = _silhouette(thumbnail_png(preview_mesh(_box(extents))))
        assert width > 0.8 * THUMBNAIL_PIXELS
        assert abs(width / height - 2.0) < 0.15, extents


def _lumpy() -> Mesh:
    """No symmetry at all: three spreads and three skews, so its frame is unique."""
    ball = trimesh.creation.icosphere(subdivisions=3)
    v = np.asarray(ball.vertices) * [3.0, 2.0, 1.0]
    v = v + 0.3 * v**2 * [1.0, -0.6, 0.8]
    return Mesh(vertices=v, faces=np.asarray(ball.faces))


def test_previews_are_drawn_in_one_frame_turned_never_mirrored():
    """A turned copy of a file previews the same (the page draws a query and its match
    in one frame), and the preview is the file turned, not its mirror image."""
    mesh = _lumpy()
    rotation = Rotation.random(random_state=4).as_matrix()
    turned = Mesh(vertices=mesh.vertices @ rotation.T * 7.0 + 2.0, faces=mesh.faces)
    np.testing.assert_allclose(
        preview_mesh(turned).vertices, preview_mesh(mesh).vertices, atol=1e-9
    )
    before = mesh.vertices - mesh.vertices.mean(0)
    after = preview_mesh(mesh).vertices
    linear = np.linalg.lstsq(before, after - after.mean(0), rcond=None)[0]
    assert np.linalg.det(linear) > 0
    glb = trimesh.load(io.BytesIO(preview_glb(preview_mesh(mesh))), file_type="glb")
    assert list(glb.graph.nodes_geometry) == [CANONICAL_NODE]


def test_thumbnail_is_shaded_not_a_flat_stencil():
    image = np.asarray(
        Image.open(io.BytesIO(thumbnail_png(preview_mesh(_sphere())))).convert("RGBA")
    )
    drawn = image[image[:, :, 3] > 0][:, :3].astype(int)
    assert len(drawn) > 0.5 * np.pi / 4 * THUMBNAIL_PIXELS**2  # the disc fills the square
    assert np.ptp(drawn.sum(axis=1)) > 100  # lit and unlit parts differ


def test_imports_names_every_package_the_previews_load():
    """What a fork server preloads for its jobs (worker/jobs/limits.py): a package
    missing from ``IMPORTS`` would be imported again by every job."""
    script = (
        "import importlib, sys\n"
        "import numpy as np\n"
        "from worker.engine.mesh_io import Mesh\n"
        "from worker.jobs.previews import IMPORTS, preview_glb, preview_mesh, thumbnail_png\n"
        "for name in IMPORTS:\n"
        "    importlib.import_module(name)\n"
        "# A torus of 24 x 12 quads, made with numpy alone (nothing the previews import).\n"
        "u, v = np.meshgrid(np.arange(24) * np.pi / 12, np.arange(12) * np.pi / 6, indexing='ij')\n"
        "r = 3 + np.cos(v)\n"
        "vertices = np.stack([r * np.cos(u), r * np.sin(u), np.sin(v)], -1).reshape(-1, 3)\n"
        "i, j = np.meshgrid(np.arange(24), np.arange(12), indexing='ij')\n"
        "a, b = i * 12 + j, (i + 1) % 24 * 12 + j\n"
        "c, d = (i + 1) % 24 * 12 + (j + 1) % 12, i * 12 + (j + 1) % 12\n"
        "faces = np.stack([a, b, c, a, c, d], -1).reshape(-1, 3)\n"
        "mesh = Mesh(vertices=vertices, faces=faces)\n"
        "before = {name.split('.')[0] for name in sys.modules}\n"
        "small = preview_mesh(mesh, max_faces=100)\n"
        "preview_glb(small), thumbnail_png(small)\n"
        "print(sorted({name.split('.')[0] for name in sys.modules} - before))\n"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=120
    ).stdout
    assert loaded.strip() == "[]"
