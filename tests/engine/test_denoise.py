"""A view's roughness and its noise share against a plain per-sample fit, the roughness the
same at any sampling of a smooth surface and far above it with a depth camera's noise;
Taubin's filter against trimesh's and a plain loop; a view smoothed only when it is rough
with noise, not with a coarse sampling; any other surface only when noise crumpled it."""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from worker.engine.compare import preset_dissimilarity
from worker.engine.denoise import (
    CRUMPLED_KEPT,
    CUBIC_TERMS,
    NOISE_LIKE,
    QUADRIC_TERMS,
    ROUGH_VIEW,
    ROUGHNESS_NEIGHBOURS,
    ROUGHNESS_SAMPLES,
    TAUBIN_GROW,
    TAUBIN_SHRINK,
    denoised,
    roughness,
    surface_fits,
    taubin_smoothed,
    view_denoised,
)
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.mesh_io import Mesh, face_areas
from worker.engine.pipeline import describe_mesh
from worker.engine.presets import DEFAULT_PRESET, MODALITIES, get_preset
from worker.evaluation.partial import decimated, noisy_surface, single_view, with_depth_noise
from worker.evaluation.samples import sample_mesh
from worker.evaluation.variants import noisy

DIRECTION = np.array([0.0, 1.0, 0.0])


def fits_reference(vertices: np.ndarray) -> tuple[float, float]:
    """Each sample's neighbours by sorting all distances, their frame by an eigen-
    decomposition of the covariance, the quadric and the cubic by ``lstsq``, one sample at
    a time."""
    points = np.asarray(vertices, dtype=np.float64)
    rng = np.random.default_rng(0)
    centres = rng.choice(len(points), size=min(ROUGHNESS_SAMPLES, len(points)), replace=False)
    k = ROUGHNESS_NEIGHBOURS
    relative, shares = [], []
    for centre in centres:
        order = np.argsort(np.linalg.norm(points - points[centre], axis=1), kind="stable")
        near = points[order[:k]]
        near = near - near.mean(axis=0)
        axes = np.linalg.eigh(near.T @ near)[1][:, ::-1]
        x, y, z = (near @ axes).T
        square = {}
        for terms in (QUADRIC_TERMS, CUBIC_TERMS):
            basis = np.column_stack([x**i * y**j for i, j in terms])
            residual = z - basis @ np.linalg.lstsq(basis, z, rcond=None)[0]
            square[len(terms)] = float(residual @ residual)
        quadric, cubic = square[len(QUADRIC_TERMS)], square[len(CUBIC_TERMS)]
        relative.append(np.sqrt(quadric / k) / np.sqrt(np.max(x * x + y * y)))
        shares.append(
            np.sqrt((cubic / (k - len(CUBIC_TERMS))) / (quadric / (k - len(QUADRIC_TERMS))))
        )
    return float(np.median(relative)), float(np.median(shares))


def bumps(n: int, noise: float) -> Mesh:
    """A bumpy height field (``sin 2x cos 2y`` over 6 x 6) on an ``n`` x ``n`` grid, each
    vertex moved in height by Gaussian noise of ``noise`` times the grid's spacing."""
    u = np.linspace(-3.0, 3.0, n)
    x, y = (a.ravel() for a in np.meshgrid(u, u))
    z = 0.5 * np.sin(2 * x) * np.cos(2 * y)
    z += np.random.default_rng(0).normal(scale=noise * (u[1] - u[0]), size=z.shape)
    corner = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)).ravel()
    faces = np.vstack(
        [np.c_[corner, corner + 1, corner + n], np.c_[corner + 1, corner + n + 1, corner + n]]
    )
    return Mesh(np.c_[x, y, z], faces)


def fine(mesh: Mesh) -> Mesh:
    """``mesh`` subdivided once (four triangles each), as a finer scan samples it."""
    finer = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).subdivide()
    return Mesh(np.asarray(finer.vertices), np.asarray(finer.faces))


def area(mesh: Mesh) -> float:
    return float(face_areas(mesh.vertices, mesh.faces).sum())


@functools.cache
def views(name: str, subdivided: bool) -> tuple[Mesh, Mesh]:
    """A sample figure's view along ``DIRECTION`` (of the figure subdivided, or not) and
    the same view with depth noise of 0.25% of the figure's diagonal."""
    mesh = sample_mesh(name, 0)
    mesh = fine(mesh) if subdivided else mesh
    view = single_view(mesh, DIRECTION)
    return view, with_depth_noise(view, mesh, DIRECTION, 0.25, np.random.default_rng(0))


def test_the_fits_equal_a_plain_fit_on_random_and_real_surfaces():
    rng = np.random.default_rng(1)
    for vertices in (
        rng.normal(size=(300, 3)),
        sample_mesh("quadruped", 0).vertices,
        views("quadruped", False)[1].vertices,
    ):
        expected = fits_reference(vertices)
        assert surface_fits(vertices) == pytest.approx(expected, rel=1e-9)
        assert roughness(vertices) == surface_fits(vertices)[0]


def test_roughness_is_scale_free_and_low_on_a_smooth_surface_at_any_sampling():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    finer = trimesh.creation.icosphere(subdivisions=4)
    coarse_value = roughness(np.asarray(sphere.vertices))
    assert roughness(100.0 * np.asarray(sphere.vertices)) == pytest.approx(coarse_value)
    for surface in (sphere, finer):
        assert roughness(np.asarray(surface.vertices)) < ROUGH_VIEW / 5
    assert roughness(np.zeros((6, 3))) == 0.0  # too few for a quadric
    assert surface_fits(sphere.vertices[:10])[1] == 0.0  # too few for a cubic


@pytest.mark.parametrize("name", ["quadruped", "biped", "hand"])
def test_a_depth_cameras_noise_makes_a_view_rough_and_its_sampling_does_not(name):
    """A sample figure's view, coarse and subdivided, stays under :data:`ROUGH_VIEW`; with
    depth noise of 0.25% of the diagonal (as the partiality protocol's ``view-noise-0.25``)
    each is above it."""
    for subdivided in (False, True):
        assert roughness(views(name, subdivided)[0].vertices) < ROUGH_VIEW
    assert roughness(views(name, True)[1].vertices) > ROUGH_VIEW


def test_only_a_rough_view_is_smoothed():
    clean, noisy = views("quadruped", True)
    assert view_denoised(clean) is clean
    smoothed = view_denoised(noisy)
    np.testing.assert_array_equal(smoothed.faces, noisy.faces)
    assert roughness(smoothed.vertices) < ROUGH_VIEW < roughness(noisy.vertices)
    # The noise crumpled the view; smoothed, its area is the noiseless view's again.
    assert area(noisy) > 1.1 * area(clean)
    assert area(smoothed) == pytest.approx(area(clean), rel=0.03)


def test_a_coarse_sampling_of_a_curved_surface_is_rough_but_not_noise():
    """Bumps on a coarse grid leave a quadric as much residual as noise does on a finer
    one; the cubic takes most of the first and none of the second, so only the noisy
    grid is smoothed."""
    coarse, noisy = bumps(20, 0.0), bumps(40, 0.3)
    (coarse_rough, coarse_share), (noisy_rough, noisy_share) = map(
        surface_fits, (coarse.vertices, noisy.vertices)
    )
    assert min(coarse_rough, noisy_rough) > ROUGH_VIEW
    assert coarse_share < NOISE_LIKE / 2 and noisy_share > NOISE_LIKE
    assert view_denoised(coarse) is coarse
    smoothed = view_denoised(noisy)
    assert roughness(smoothed.vertices) < ROUGH_VIEW
    # what is left of the noise, against the bumps it stood on
    assert np.abs(smoothed.vertices[:, 2] - bumps(40, 0.0).vertices[:, 2]).mean() < 0.5 * (
        np.abs(noisy.vertices[:, 2] - bumps(40, 0.0).vertices[:, 2]).mean()
    )


def test_a_coarse_noiseless_surface_is_rough_and_noise_like_but_not_crumpled():
    """A sample figure decimated to a fifth of its faces reads as rough with noise (its
    triangles are large against its curvature), as the tessellation protocol's slight noise
    does; as a view it would be smoothed. Taubin's filter leaves either nearly all its area,
    so neither is smoothed; noise of 0.5% of the diagonal crumples the figure and is.
    (0.25% is 0.13 of an edge on these 2,500 vertices, near that slight noise: kept 0.91.)"""
    mesh = sample_mesh("quadruped", 0)
    coarse = decimated(mesh, 0.2)
    slight = noisy(mesh, np.random.default_rng(0))
    crumpled = noisy_surface(mesh, 0.5, np.random.default_rng(0))
    for surface in (coarse, slight, crumpled):
        rough, share = surface_fits(surface.vertices)
        assert rough > ROUGH_VIEW and share > NOISE_LIKE
        assert view_denoised(surface) is not surface
    assert denoised(coarse) is coarse and denoised(slight) is slight
    assert area_kept(coarse) > area_kept(slight) > CRUMPLED_KEPT > area_kept(crumpled)
    smoothed = denoised(crumpled)
    np.testing.assert_array_equal(smoothed.vertices, taubin_smoothed(crumpled).vertices)


def area_kept(surface: Mesh) -> float:
    smoothed = taubin_smoothed(surface)
    return float(
        face_areas(smoothed.vertices, smoothed.faces).sum()
        / face_areas(surface.vertices, surface.faces).sum()
    )


def test_a_noisy_whole_is_described_smoothed_near_its_clean_self():
    """A sample figure with noise of 1% of its diagonal (the partiality protocol's
    ``noise-1``) is smoothed before it is described: each modality lies within a third of
    the distance to the clean figure that the noisy one unsmoothed does (the preset
    without ``smooth_noise``), and its area within 15% of the clean one's (the noise
    crumples it to 2.7 times); the clean figure is described as it is."""
    preset = get_preset(DEFAULT_PRESET)
    assert preset.smooth_noise
    mesh = sample_mesh("quadruped", 0)
    noisy_figure = noisy_surface(mesh, 1.0, np.random.default_rng(0))
    clean, smoothed = describe_mesh(mesh, preset), describe_mesh(noisy_figure, preset)
    unsmoothed = describe_mesh(noisy_figure, replace(preset, smooth_noise=False))
    assert smoothed.surface_smoothed
    assert clean.surface_smoothed is False and unsmoothed.surface_smoothed is False
    for m in MODALITIES:

        def to_clean(d: ShapeDescriptor, m: str = m) -> float:
            return float(
                preset_dissimilarity(m, d.vector(m)[None], clean.vector(m)[None], preset)[0, 0]
            )

        assert to_clean(smoothed) < to_clean(unsmoothed) / 3, m
    assert smoothed.area == pytest.approx(clean.area, rel=0.15)
    assert unsmoothed.area > 2 * clean.area


def taubin_reference(mesh: Mesh, steps: int) -> np.ndarray:
    """Taubin's filter vertex by vertex, each vertex's neighbours gathered face by face."""
    neighbours: list[set[int]] = [set() for _ in range(mesh.n_vertices)]
    for face in mesh.faces.tolist():
        for corner in face:
            neighbours[corner].update(v for v in face if v != corner)
    vertices = mesh.vertices.copy()
    for step in range(steps):
        factor = TAUBIN_SHRINK if step % 2 == 0 else -TAUBIN_GROW
        moved = vertices.copy()
        for v, around in enumerate(neighbours):
            if around:
                moved[v] += factor * (vertices[sorted(around)].mean(axis=0) - vertices[v])
        vertices = moved
    return vertices


def test_taubin_equals_trimesh_on_a_closed_surface_and_a_plain_loop_on_an_open_one():
    """On a closed surface the filter is trimesh's; on an open one (a view of the
    quadruped, with a vertex on no face) the plain loop's, a boundary vertex averaging all
    its neighbours (trimesh's operator leaves one out) and the lonely vertex kept."""
    rng = np.random.default_rng(0)
    sphere = trimesh.creation.icosphere(subdivisions=3)
    noisy = Mesh(sphere.vertices + rng.normal(scale=0.02, size=sphere.vertices.shape), sphere.faces)
    theirs = trimesh.Trimesh(noisy.vertices, noisy.faces, process=False)
    # no-untyped-call: trimesh's smoothing filters carry no annotations.
    trimesh.smoothing.filter_taubin(theirs, iterations=10)  # type: ignore[no-untyped-call]
    np.testing.assert_allclose(taubin_smoothed(noisy, 10).vertices, theirs.vertices, atol=1e-12)

    view = views("quadruped", False)[0]
    lonely = Mesh(np.vstack([view.vertices, [[9.0, 9.0, 9.0]]]), view.faces)
    smoothed = taubin_smoothed(lonely, 5)
    np.testing.assert_allclose(smoothed.vertices, taubin_reference(lonely, 5), atol=1e-12)
    np.testing.assert_array_equal(smoothed.faces, lonely.faces)
    assert smoothed.vertices[-1].tolist() == [9.0, 9.0, 9.0]
