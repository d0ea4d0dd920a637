"""What a person sees of a described mesh: a small 3D preview and a PNG thumbnail.

Made by the descriptor job from the cleaned upload (not from the descriptors), so
the web page can show a gallery of thumbnails and the query beside a match in 3D
without ever sending the original files (which can be 50 MB).

* preview: the mesh decimated by quadric error to at most ``PREVIEW_FACES``
  triangles, turned to the engine's canonical frame (principal axes: largest spread
  along x, least along z, limbs down; a rotation, never a mirror image), so that every
  preview is drawn in one frame whatever the file's own axes, centred and scaled to a
  unit bounding radius, as binary glTF (GLB; its node is named ``CANONICAL_NODE``),
  which three.js's ``GLTFLoader`` reads;
* thumbnail: a ``THUMBNAIL_PIXELS`` square PNG, flat-shaded, seen along the canonical
  z axis (the least extent: the largest outline) with y up, as the page first shows the
  preview, drawn back to front (painter's algorithm, matplotlib's Agg canvas; no GPU,
  no display).

Both are drawn from the mesh :func:`preview_mesh` makes (decimated and turned once).
"""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # imported where it is used: the service loads this module too
    from worker.engine.mesh_io import Mesh

#: What the functions below import on first use (kept out of this module's own import,
#: which the service loads too): a process that makes previews for many jobs, such as
#: the jobs' fork server, imports them once instead of once per job (trimesh 0.14 s,
#: matplotlib 0.27 s).
IMPORTS = (
    "fast_simplification",
    "trimesh",
    "matplotlib.backends.backend_agg",
    "matplotlib.collections",
    "matplotlib.figure",
)
PREVIEW_FACES = 4000
#: The preview's glTF node: the page draws a preview so named as it is (canonical
#: frame), and turns one made before (the file's own axes, z up) to stand upright.
CANONICAL_NODE = "canonical-frame"
THUMBNAIL_PIXELS = 256
#: Flat colour of the thumbnails' surface, and the light's direction (towards the viewer,
#: up and to the left).
SURFACE_RGB = np.array([0.55, 0.66, 0.80])
LIGHT = np.array([-0.4, 0.5, 0.77])


def preview_mesh(mesh: Mesh, max_faces: int = PREVIEW_FACES) -> Mesh:
    """The mesh with at most ``max_faces`` triangles, in its canonical frame (turned,
    not mirrored), centred, within the unit sphere."""
    from worker.engine.mesh_io import Mesh

    vertices, faces = mesh.vertices, mesh.faces
    if len(faces) > max_faces:
        import fast_simplification

        vertices, faces = fast_simplification.simplify(
            vertices, faces.astype(np.int32), target_count=max_faces
        )
    vertices = _turned(np.asarray(vertices, dtype=np.float64), np.asarray(faces))
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    radius = float(np.linalg.norm(vertices - centre, axis=1).max()) or 1.0
    return Mesh(vertices=(vertices - centre) / radius, faces=np.asarray(faces, dtype=np.int64))


def _turned(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``vertices`` in the canonical frame of :func:`canonical_frame`, whose axes' signs
    may make a mirror image (the descriptors do not mind; a person would): then the
    least axis is flipped, making it a rotation."""
    from worker.engine.mesh_io import Mesh, canonical_frame

    turned = canonical_frame(Mesh(vertices=vertices, faces=faces)).vertices
    # The frame is affine: the linear part, fitted from the vertices, says if it mirrors.
    before, after = vertices - vertices.mean(axis=0), turned - turned.mean(axis=0)
    linear = np.linalg.lstsq(before, after, rcond=None)[0]
    if np.linalg.det(linear) < 0:
        turned[:, 2] = -turned[:, 2]
    # The frame's second axis points to its heavier tail (third moment), where limbs
    # are: drawn downwards, as legs stand (a half turn about x, still no mirror).
    turned[:, 1:] = -turned[:, 1:]
    return turned


def preview_glb(small: Mesh) -> bytes:
    """The preview mesh ``small`` (:func:`preview_mesh`) as binary glTF (vertices as
    float32), one node named ``CANONICAL_NODE``."""
    import trimesh

    scene = trimesh.Scene()
    scene.add_geometry(
        trimesh.Trimesh(small.vertices, small.faces, process=False), node_name=CANONICAL_NODE
    )
    # no-untyped-call: Scene.export has no annotations (Trimesh.export has).
    data = scene.export(file_type="glb")  # type: ignore[no-untyped-call]
    assert isinstance(data, bytes)  # export's type covers every format; GLB is bytes
    return data


def thumbnail_png(small: Mesh, pixels: int = THUMBNAIL_PIXELS) -> bytes:
    """A flat-shaded PNG of the preview mesh ``small`` (:func:`preview_mesh`), seen
    along its canonical z axis (x right, y up, z towards the viewer)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    triangles = small.vertices[small.faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    # Two-sided lighting (files do not agree on face orientation).
    shade = 0.25 + 0.75 * np.abs(normals @ (LIGHT / np.linalg.norm(LIGHT)))
    order = np.argsort(triangles[:, :, 2].mean(axis=1))  # far to near
    colours = np.clip(shade[order, None] * SURFACE_RGB, 0.0, 1.0)
    fig = Figure(figsize=(1, 1), dpi=pixels)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.add_collection(
        PolyCollection(
            triangles[order, :, :2],
            facecolors=colours,
            edgecolors=colours,
            linewidths=0.2,
            antialiased=False,
        )
    )
    extent = 1.05 * float(np.abs(small.vertices[:, :2]).max())
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent, extent)
    ax.set_aspect("equal")
    ax.axis("off")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=pixels, transparent=True)
    return buffer.getvalue()
