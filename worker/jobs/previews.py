"""What a person sees of a described mesh: a small 3D preview and a PNG thumbnail.

Made by the descriptor job from the cleaned upload (not from the descriptors), so
the web page can show a gallery of thumbnails and the query beside a match in 3D
without ever sending the original files (which can be 50 MB).

* preview: the mesh decimated by quadric error to at most ``PREVIEW_FACES``
  triangles, centred and scaled to a unit bounding radius, as binary glTF (GLB),
  which three.js's ``GLTFLoader`` reads;
* thumbnail: a ``THUMBNAIL_PIXELS`` square PNG, flat-shaded, seen along the file's
  coordinate axis of least extent (its largest outline), with +z up when z is in the
  picture and +y otherwise, drawn back to front (painter's algorithm, matplotlib's Agg
  canvas; no GPU, no display).

Both start from :func:`preview_mesh`, which leaves a preview mesh as it is: a caller
that makes both decimates once and passes the result (the same bytes come out).
"""

from __future__ import annotations

import io

import numpy as np

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
THUMBNAIL_PIXELS = 256
#: Flat colour of the thumbnails' surface, and the light's direction (towards the viewer,
#: up and to the left).
SURFACE_RGB = np.array([0.55, 0.66, 0.80])
LIGHT = np.array([-0.4, 0.5, 0.77])


def preview_mesh(mesh: Mesh, max_faces: int = PREVIEW_FACES) -> Mesh:
    """The mesh with at most ``max_faces`` triangles, centred, within the unit sphere."""
    vertices, faces = mesh.vertices, mesh.faces
    if len(faces) > max_faces:
        import fast_simplification

        vertices, faces = fast_simplification.simplify(
            vertices, faces.astype(np.int32), target_count=max_faces
        )
    vertices = np.asarray(vertices, dtype=np.float64)
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    radius = float(np.linalg.norm(vertices - centre, axis=1).max()) or 1.0
    return Mesh(vertices=(vertices - centre) / radius, faces=np.asarray(faces, dtype=np.int64))


def preview_glb(mesh: Mesh) -> bytes:
    """The preview as binary glTF (vertices as float32, smooth normals)."""
    import trimesh

    small = preview_mesh(mesh)
    data = trimesh.Trimesh(small.vertices, small.faces, process=False).export(file_type="glb")
    assert isinstance(data, bytes)  # export's type covers every format; GLB is bytes
    return data


def thumbnail_png(mesh: Mesh, pixels: int = THUMBNAIL_PIXELS) -> bytes:
    """A flat-shaded PNG of the preview, seen along its axis of least extent."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    small = preview_mesh(mesh)
    depth = int(np.argmin(np.ptp(small.vertices, axis=0)))
    up = 2 if depth != 2 else 1
    right = 3 - depth - up
    view = small.vertices[:, [right, up, depth]]
    if np.linalg.det(np.eye(3)[[right, up, depth]]) < 0:
        view[:, 2] = -view[:, 2]  # keep a right-handed view: z towards the viewer
    triangles = view[small.faces]
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
    extent = 1.05 * float(np.abs(view[:, :2]).max())
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent, extent)
    ax.set_aspect("equal")
    ax.axis("off")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=pixels, transparent=True)
    return buffer.getvalue()
