"""The paper's evaluation protocol (sec. 4) on a labelled mesh collection.

Two halves:

* Orchestration (I/O): :func:`read_labels` reads ``labels.csv``;
  :func:`compute_descriptors` describes every mesh in worker processes, with the
  ShapeDNA baseline on the same resampled mesh, through an on-disk cache;
  :func:`run_evaluation` ties it together and writes the report files.
* Pure functions on arrays: :func:`modality_dissimilarity`,
  :func:`dissimilarity_matrices`, :func:`score_dissimilarity`, :func:`build_report`,
  :func:`render_markdown`. They make every number of the report and are tested
  directly.

Protocol (also written into every report, see :func:`protocol_text`):

* verification over all unordered pairs (ROC, EER);
* identification with a gallery of the first instance of each class in natural
  file-name order, every other object a probe (CMC, R1RR);
* leave-one-out all-to-all retrieval (NN, first/second tier, E-measure, DCG, mAP).

For D2 (eq. 9) the ``sigma_i`` are the standard deviations of descriptor element
``i`` over *all* evaluated objects: in the all-to-all protocol the whole set is the
gallery. The paper does not say which set it used.
"""

from __future__ import annotations

import ast
import csv
import hashlib
import json
import os
import platform
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import metrics
from .compare import fuse, gallery_sigma, mean_normalized_manhattan, normalized_euclidean
from .errors import MeshError
from .mesh_io import load_mesh
from .pipeline import ShapeDescriptor, describe_file
from .presets import MODALITIES, Preset
from .resample import resample_mesh
from .shapedna_baseline import SHAPEDNA_K, ShapeDNA, shapedna, shapedna_dissimilarity

BASELINE = "shapedna"

#: Rows of the report, in table order: key -> (title, members, fusion rule).
#: ``members`` are modalities, or the baseline; ``rule`` is None for a single one.
ROWS: dict[str, tuple[str, tuple[str, ...], str | None]] = {
    "gdm": ("GDM", ("gdm",), None),
    "ddt": ("DDT", ("ddt",), None),
    "spectrum": ("Spectrum", ("spectrum",), None),
    "gdm+ddt sum": ("GDM+DDT sum", ("gdm", "ddt"), "sum"),
    "gdm+ddt product": ("GDM+DDT product", ("gdm", "ddt"), "product"),
    "gdm+ddt+spectrum sum": ("GDM+DDT+Spectrum sum", ("gdm", "ddt", "spectrum"), "sum"),
    "gdm+ddt+spectrum product": (
        "GDM+DDT+Spectrum product",
        ("gdm", "ddt", "spectrum"),
        "product",
    ),
    BASELINE: ("ShapeDNA (lapy)", (BASELINE,), None),
}

#: Table columns: key in a row's scores -> header.
COLUMNS: dict[str, str] = {
    "nn": "NN",
    "r1rr": "R1RR",
    "eer": "EER",
    "first_tier": "FT",
    "second_tier": "ST",
    "e_measure": "E",
    "dcg": "DCG",
    "map": "mAP",
}

#: FAR values at which the report states the FRR.
FAR_OPERATING_POINTS = (0.001, 0.01, 0.05, 0.1)
#: The ROC stored in report.json is thinned to at most this many points.
ROC_POINTS_STORED = 400


class EvaluationError(ValueError):
    """The evaluation cannot run on this input; the message says why."""


# --------------------------------------------------------------------------- labels


@dataclass(frozen=True)
class LabeledMesh:
    """One object of the evaluated set: file name (as in labels.csv), class, path."""

    name: str
    label: str
    path: Path


def read_labels(
    labels_csv: str | Path, dataset_dir: str | Path, per_class_limit: int | None = None
) -> list[LabeledMesh]:
    """Read ``labels.csv`` (columns ``file,class``; files relative to ``dataset_dir``).

    Parameters
    ----------
    labels_csv : path of the CSV file, with a header row naming ``file`` and ``class``.
    dataset_dir : directory the file names are relative to.
    per_class_limit : keep only the first ``per_class_limit`` files of each class in
        natural file-name order (at least 2, so every class keeps a genuine pair).

    Returns
    -------
    list of LabeledMesh in natural file-name order.

    Raises
    ------
    EvaluationError
        On a missing column, a missing file, a repeated file, or fewer than two classes.
    """
    dataset_dir = Path(dataset_dir)
    if per_class_limit is not None and per_class_limit < 2:
        raise EvaluationError("--limit must be at least 2 meshes per class")
    with open(labels_csv, newline="") as handle:
        reader = csv.DictReader(handle)
        fields = [f.strip().lower() for f in (reader.fieldnames or [])]
        if "file" not in fields or "class" not in fields:
            raise EvaluationError(
                f"{labels_csv} needs a header row with 'file' and 'class' columns, got {fields}"
            )
        rows = [{k.strip().lower(): (v or "").strip() for k, v in row.items()} for row in reader]
    meshes = [
        LabeledMesh(name=r["file"], label=r["class"], path=dataset_dir / r["file"])
        for r in rows
        if r["file"]
    ]
    repeated = [name for name, count in Counter(m.name for m in meshes).items() if count > 1]
    if repeated:
        raise EvaluationError(f"{labels_csv} lists files more than once: {repeated}")
    missing = [m.name for m in meshes if not m.path.is_file()]
    if missing:
        raise EvaluationError(f"files listed in {labels_csv} not found in {dataset_dir}: {missing}")
    meshes.sort(key=lambda m: metrics.natural_sort_key(m.name))
    if per_class_limit is not None:
        taken: Counter[str] = Counter()
        kept = []
        for m in meshes:
            if taken[m.label] < per_class_limit:
                taken[m.label] += 1
                kept.append(m)
        meshes = kept
    if len({m.label for m in meshes}) < 2:
        raise EvaluationError("the evaluation needs at least two classes")
    return meshes


# --------------------------------------------------------------------------- cache


def _local_imports(path: Path) -> set[str]:
    """Names of the sibling ``worker`` modules a module's source imports (anywhere in it)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.ImportFrom):
            if node.level == 1:  # from .x import y / from . import x
                found.update([node.module] if node.module else [a.name for a in node.names])
            elif node.level == 0 and (node.module or "").startswith("worker."):
                found.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            found.update(a.name.split(".")[1] for a in node.names if a.name.startswith("worker."))
    return {name.split(".")[0] for name in found}


def engine_fingerprint() -> str:
    """sha256 of the source of every ``worker`` module a cached entry depends on.

    The modules are found by following imports from :mod:`worker.pipeline` and
    :mod:`worker.shapedna_baseline`, so editing the engine (even without a preset
    version bump) never serves stale descriptors, while editing the service, the
    metrics or this harness keeps the cache.
    """
    package = Path(__file__).parent
    todo, seen = ["pipeline", "shapedna_baseline"], set()
    while todo:
        name = todo.pop()
        path = package / f"{name}.py"
        if name in seen or not path.is_file():
            continue
        seen.add(name)
        todo.extend(_local_imports(path))
    digest = hashlib.sha256()
    for name in sorted(seen):
        digest.update(name.encode())
        digest.update((package / f"{name}.py").read_bytes())
    return digest.hexdigest()


def cache_namespace(preset: Preset) -> str:
    """Directory name of a preset's cache entries.

    ``<name>-v<version>-<digest>``: the digest covers every preset field and the
    engine source (:func:`engine_fingerprint`), so a preset edited without a
    version bump, or an edited pipeline, gets a fresh namespace.
    """
    digest = hashlib.sha256()
    digest.update(json.dumps(preset.to_dict(), sort_keys=True, default=list).encode())
    digest.update(engine_fingerprint().encode())
    return f"{preset.name}-v{preset.version}-{digest.hexdigest()[:12]}"


@dataclass
class DescriptorCache:
    """Descriptors on disk as npz, keyed by sha256(file bytes) within a preset namespace.

    Layout: ``<root>/<cache_namespace(preset)>/<sha256>.descriptor.npz`` and
    ``<sha256>.shapedna-k<k>.npz`` for the baseline (same resampled mesh, so the
    same namespace).
    """

    root: Path
    preset: Preset

    @property
    def directory(self) -> Path:
        return Path(self.root) / cache_namespace(self.preset)

    def _path(self, sha256: str, kind: str) -> Path:
        suffix = "descriptor" if kind == "descriptor" else f"{BASELINE}-k{SHAPEDNA_K}"
        return self.directory / f"{sha256}.{suffix}.npz"

    def load_descriptor(self, sha256: str) -> ShapeDescriptor | None:
        path = self._path(sha256, "descriptor")
        if not path.is_file():
            return None
        descriptor = ShapeDescriptor.from_npz_bytes(path.read_bytes())
        same = (descriptor.preset, descriptor.preset_version) == (
            self.preset.name,
            self.preset.version,
        )
        return descriptor if same else None

    def load_baseline(self, sha256: str) -> ShapeDNA | None:
        path = self._path(sha256, BASELINE)
        return ShapeDNA.from_npz_bytes(path.read_bytes()) if path.is_file() else None

    def store(self, sha256: str, kind: str, data: bytes) -> None:
        """Write atomically, so an interrupted run never leaves a truncated entry."""
        path = self._path(sha256, kind)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# --------------------------------------------------------------------------- computing


@dataclass
class _Job:
    """What a worker process returns for one mesh (npz bytes, or why it failed)."""

    descriptor: bytes | None = None
    baseline: bytes | None = None
    error: str | None = None


def _single_threaded_blas() -> None:
    """Give each worker process one BLAS thread.

    ``--jobs`` processes with OpenBLAS's default of one thread per core
    oversubscribe the machine; on a shared 2-core machine that made describing a
    mesh about 10 times slower (measured: 2.4 s against 20-27 s for wolf0).
    """
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


def _describe_job(path: str, preset: Preset, need_descriptor: bool, need_baseline: bool) -> _Job:
    """Describe one mesh file; runs in a worker process, so it only takes picklable data."""
    data = Path(path).read_bytes()
    name = Path(path).name
    job = _Job()
    try:
        if need_descriptor:
            job.descriptor = describe_file(data, preset, filename=name).to_npz_bytes()
        if need_baseline:
            # The same load and resampling describe_file does (both deterministic),
            # so the baseline sees exactly the mesh the descriptors were made from.
            mesh = resample_mesh(load_mesh(data, name), preset.n_vertices)
            job.baseline = shapedna(mesh.vertices, mesh.faces).to_npz_bytes()
    except MeshError as exc:
        job.error = exc.message
    except Exception as exc:  # one mesh's crash must not lose the others' work
        job.error = f"internal error: {type(exc).__name__}: {exc}"
    return job


@dataclass
class ComputedSet:
    """Descriptors of the meshes that could be described, in input order."""

    meshes: list[LabeledMesh]
    descriptors: list[ShapeDescriptor]
    baselines: list[ShapeDNA]
    failures: dict[str, str] = field(default_factory=dict)
    stats: dict[str, float] = field(default_factory=dict)


def compute_descriptors(
    meshes: Sequence[LabeledMesh],
    preset: Preset,
    cache_root: str | Path,
    jobs: int = 1,
    progress: bool = True,
) -> ComputedSet:
    """Descriptors and ShapeDNA of every mesh, from the cache or computed in parallel.

    Parameters
    ----------
    meshes : the objects to describe.
    preset : the descriptor parameters.
    cache_root : cache directory (created if missing).
    jobs : worker processes, each with one BLAS thread; 1 computes in this process.
    progress : show a tqdm progress bar (on a terminal).

    Returns
    -------
    ComputedSet; meshes the engine refuses are left out and listed in ``failures``.
    """
    from tqdm import tqdm

    cache = DescriptorCache(Path(cache_root), preset)
    start = time.perf_counter()
    hashes = [file_sha256(m.path) for m in meshes]
    descriptors: list[ShapeDescriptor | None] = [cache.load_descriptor(h) for h in hashes]
    baselines: list[ShapeDNA | None] = [cache.load_baseline(h) for h in hashes]
    todo = [i for i in range(len(meshes)) if descriptors[i] is None or baselines[i] is None]
    cache_seconds = time.perf_counter() - start
    failures: dict[str, str] = {}

    def collect(i: int, job: _Job) -> None:
        if job.error is not None:
            failures[meshes[i].name] = job.error
            return
        if job.descriptor is not None:
            cache.store(hashes[i], "descriptor", job.descriptor)
            descriptors[i] = ShapeDescriptor.from_npz_bytes(job.descriptor)
        if job.baseline is not None:
            cache.store(hashes[i], BASELINE, job.baseline)
            baselines[i] = ShapeDNA.from_npz_bytes(job.baseline)

    start = time.perf_counter()
    bar = tqdm(total=len(todo), desc=f"describe ({preset.name})", unit="mesh", disable=not progress)
    args = [
        (str(meshes[i].path), preset, descriptors[i] is None, baselines[i] is None) for i in todo
    ]
    if jobs <= 1 or len(todo) <= 1:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1):
            for i, a in zip(todo, args, strict=True):
                collect(i, _describe_job(*a))
                bar.update()
    elif todo:
        workers = min(jobs, len(todo))
        with ProcessPoolExecutor(max_workers=workers, initializer=_single_threaded_blas) as pool:
            futures = {pool.submit(_describe_job, *a): i for i, a in zip(todo, args, strict=True)}
            for future in as_completed(futures):
                try:
                    job = future.result()
                except Exception as exc:  # a worker process died (e.g. out of memory)
                    job = _Job(error=f"worker process failed: {type(exc).__name__}: {exc}")
                collect(futures[future], job)
                bar.update()
    bar.close()
    compute_seconds = time.perf_counter() - start

    keep = [i for i in range(len(meshes)) if meshes[i].name not in failures]
    return ComputedSet(
        meshes=[meshes[i] for i in keep],
        descriptors=[descriptors[i] for i in keep],  # type: ignore[misc]
        baselines=[baselines[i] for i in keep],  # type: ignore[misc]
        failures=failures,
        stats={
            "meshes": len(meshes),
            "from_cache": len(meshes) - len(todo),
            "computed": len(todo) - len(failures),
            "failed": len(failures),
            "hash_and_cache_seconds": cache_seconds,
            "compute_seconds": compute_seconds,
            "jobs": jobs,
            "cache_directory": str(cache.directory),
        },
    )


# --------------------------------------------------------------------------- dissimilarities


def modality_dissimilarity(vectors: np.ndarray, dissimilarity: str) -> tuple[np.ndarray, dict]:
    """All-to-all dissimilarity of one modality with D1 (eq. 8) or D2 (eq. 9).

    Parameters
    ----------
    vectors : (n, M) float, one flat descriptor per object.
    dissimilarity : ``"D1"`` or ``"D2"``.

    Returns
    -------
    matrix : (n, n) float, symmetric, zero diagonal.
    info : how it was made; for D2 it holds ``sigma`` (M,), the per-element standard
        deviation over all ``n`` objects (the all-to-all protocol's gallery).
    """
    x = np.atleast_2d(np.asarray(vectors, dtype=np.float64))
    if dissimilarity == "D1":
        d = mean_normalized_manhattan(x, x)
        info: dict = {"dissimilarity": "D1"}
    elif dissimilarity == "D2":
        sigma = gallery_sigma(x)
        d = normalized_euclidean(x, x, sigma)
        info = {"dissimilarity": "D2", "sigma": sigma, "sigma_over": "all evaluated objects"}
    else:
        raise ValueError(f"unknown dissimilarity {dissimilarity!r}; use 'D1' or 'D2'")
    d = 0.5 * (d + d.T)  # exact symmetry: D2's expansion differs from d.T by rounding
    np.fill_diagonal(d, 0.0)
    return d, info


def dissimilarity_matrices(
    vectors: Mapping[str, np.ndarray],
    preset: Preset,
    baseline: np.ndarray | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """Every row of the report as an all-to-all dissimilarity matrix.

    Parameters
    ----------
    vectors : modality -> (n, M) float, for every modality in ``MODALITIES``.
    preset : gives the dissimilarity (D1/D2) and the fusion weights.
    baseline : (n, k) float, ShapeDNA descriptors; the baseline row is left out if None.

    Returns
    -------
    matrices : row key (see ``ROWS``) -> (n, n) float.
    info : row key -> how the matrix was made.

    Notes
    -----
    Fusion combines the raw per-modality matrices with the preset's weights:
    sum ``sum_m w_m D_m``, product ``prod_m D_m ** w_m``. The product's ranking does
    not depend on each modality's scale; the sum's does (with D2 the modality with
    more elements weighs more), exactly as the paper's rules are stated.
    """
    per_modality: dict[str, np.ndarray] = {}
    matrices: dict[str, np.ndarray] = {}
    info: dict[str, dict] = {}
    for modality in MODALITIES:
        per_modality[modality], info[modality] = modality_dissimilarity(
            vectors[modality], preset.dissimilarity
        )
    for key, (_, members, rule) in ROWS.items():
        if key == BASELINE:
            if baseline is not None:
                matrices[key] = shapedna_dissimilarity(baseline)
                info[key] = {
                    "dissimilarity": "euclidean (lapy.shapedna.compute_distance, dist='euc')"
                }
            continue
        if rule is None:
            matrices[key] = per_modality[members[0]]
            continue
        weights = {m: preset.weight(m) for m in members}
        matrices[key] = fuse({m: per_modality[m] for m in members}, rule, weights)
        info[key] = {"fusion": rule, "weights": weights}
    return matrices, info


# --------------------------------------------------------------------------- scores


def _thin(far: np.ndarray, frr: np.ndarray, points: int) -> tuple[list[float], list[float]]:
    if far.size <= points:
        return far.tolist(), frr.tolist()
    idx = np.unique(np.round(np.geomspace(1, far.size, points)).astype(int) - 1)
    idx = np.union1d(idx, np.linspace(0, far.size - 1, points // 4).astype(int))
    return far[idx].tolist(), frr[idx].tolist()


def score_dissimilarity(
    dissimilarity: np.ndarray,
    labels: Sequence[str],
    names: Sequence[str],
    gallery_idx: np.ndarray,
    probe_idx: np.ndarray,
) -> dict:
    """Every metric of one all-to-all dissimilarity matrix.

    Parameters
    ----------
    dissimilarity : (n, n) float, symmetric.
    labels, names : (n,) class and file name of each object.
    gallery_idx, probe_idx : the identification split (:func:`metrics.first_instance_split`).

    Returns
    -------
    dict with the table's numbers (``nn``, ``r1rr``, ``eer``, ``first_tier``,
    ``second_tier``, ``e_measure``, ``dcg``, ``map``, all fractions in [0, 1]),
    ``cmc`` (g,), ``roc`` (thinned far/frr lists), ``frr_at_far``, and the errors:
    ``nn_errors`` and ``rank1_errors`` (which object was mistaken for which).
    """
    d = np.asarray(dissimilarity, dtype=np.float64)
    labels = np.asarray([str(x) for x in labels])
    retrieval = metrics.retrieval_scores(d, labels)
    far, frr, _ = metrics.roc_curve(d, labels)
    cmc = metrics.cmc_curve(d, labels, gallery_idx, probe_idx)
    roc_far, roc_frr = _thin(far, frr, ROC_POINTS_STORED)
    # FRR at a FAR operating point: the lowest FRR among thresholds with FAR <= target.
    frr_at_far = {str(t): float(frr[far <= t].min()) for t in FAR_OPERATING_POINTS}

    masked = d + np.diag(np.full(len(d), np.inf))
    nearest = np.argmin(masked, axis=1)  # ties -> lower index, as metrics' retrieval
    nn_errors = [
        {"query": names[i], "class": labels[i], "nearest": names[j], "nearest_class": labels[j]}
        for i, j in enumerate(nearest)
        if labels[i] != labels[j]
    ]
    scores = d[np.ix_(probe_idx, gallery_idx)]
    best = np.argmin(scores, axis=1)
    rank1_errors = [
        {
            "probe": names[p],
            "class": labels[p],
            "matched": names[gallery_idx[b]],
            "matched_class": labels[gallery_idx[b]],
        }
        for p, b in zip(probe_idx, best, strict=True)
        if labels[gallery_idx[b]] != labels[p]
    ]
    return {
        **retrieval,
        "r1rr": float(cmc[0]),
        "eer": metrics.equal_error_rate(d, labels),
        "cmc": cmc.tolist(),
        "roc": {"far": roc_far, "frr": roc_frr},
        "frr_at_far": frr_at_far,
        "nn_errors": nn_errors,
        "rank1_errors": rank1_errors,
    }


# --------------------------------------------------------------------------- report


def protocol_text(preset: Preset, n_objects: int, n_classes: int, gallery: Sequence[str]) -> dict:
    """The protocol in words, for report.json and report.md."""
    sigma = (
        "D2 (eq. 9), sigma_i = standard deviation of descriptor element i over all "
        f"{n_objects} evaluated objects (all-to-all protocol: the whole set is the gallery)"
        if preset.dissimilarity == "D2"
        else "D1 (eq. 8), mean normalized Manhattan distance"
    )
    weights = ", ".join(f"{m}={preset.weight(m):g}" for m in MODALITIES)
    return {
        "objects": n_objects,
        "classes": n_classes,
        "dissimilarity": sigma,
        "fusion": (
            "sum = sum_m w_m D_m, product = prod_m D_m ** w_m over the raw per-modality "
            f"matrices, preset weights ({weights})"
        ),
        "preset_score": "+".join(preset.fused_modalities) + f" {preset.fusion}",
        "verification": (
            f"all {n_objects * (n_objects - 1) // 2} unordered pairs; genuine = same class; "
            "ROC = FRR against FAR over the threshold; EER where FRR = FAR"
        ),
        "identification": (
            f"gallery = first instance of each class in natural file-name order "
            f"({n_classes} objects: {', '.join(gallery)}); probes = the other "
            f"{n_objects - n_classes}; CMC with pessimistic ties; R1RR = CMC at rank 1"
        ),
        "retrieval": (
            "leave-one-out, each object queries the other n-1; NN, first tier, second "
            "tier, E-measure (top 32), normalized DCG, mean average precision; ties "
            "broken by file order"
        ),
        "baseline": (
            f"ShapeDNA via lapy on the same resampled mesh ({preset.n_vertices} vertices): "
            f"compute_shapedna(k={SHAPEDNA_K}), normalize_ev(method='geometry') "
            "(times surface area), reweight_ev (lambda_i / i), compute_distance(dist='euc')"
        ),
    }


def _mean_timings(timings: Sequence[Mapping[str, float]]) -> dict[str, float]:
    keys = sorted({k for t in timings for k in t})
    return {k: float(np.mean([t[k] for t in timings if k in t])) for k in keys}


def build_report(
    computed: ComputedSet,
    preset: Preset,
    *,
    command: str = "",
    environment: Mapping[str, str] | None = None,
    dataset: str = "",
) -> tuple[dict, dict[str, np.ndarray]]:
    """Dissimilarities and metrics of every row, as one JSON-ready dict.

    Parameters
    ----------
    computed : the described set (:func:`compute_descriptors`).
    preset : the preset the descriptors were made with.
    command, environment, dataset : recorded as given.

    Returns
    -------
    report : dict, see report.json.
    matrices : row key -> (n, n) dissimilarity matrix.
    """
    start = time.perf_counter()
    names = [m.name for m in computed.meshes]
    labels = [m.label for m in computed.meshes]
    vectors = {m: np.stack([d.vector(m) for d in computed.descriptors]) for m in MODALITIES}
    baseline = np.stack([b.descriptor for b in computed.baselines])
    matrices, info = dissimilarity_matrices(vectors, preset, baseline)
    gallery_idx, probe_idx = metrics.first_instance_split(names, labels)
    rows = {}
    for key, matrix in matrices.items():
        title, members, rule = ROWS[key]
        rows[key] = {
            "title": title,
            "members": list(members),
            "rule": rule,
            **{k: v for k, v in info.get(key, {}).items() if k != "sigma"},
            **score_dissimilarity(matrix, labels, names, gallery_idx, probe_idx),
        }
    metrics_seconds = time.perf_counter() - start
    classes = Counter(labels)
    gallery = [names[i] for i in gallery_idx]
    d2_sigma = {m: info[m]["sigma"].tolist() for m in MODALITIES if "sigma" in info[m]}
    report = {
        "dataset": dataset,
        "command": command,
        "preset": preset.to_dict(),
        "protocol": protocol_text(preset, len(names), len(classes), gallery),
        "objects": [
            {"file": n, "class": c, "gallery": n in gallery}
            for n, c in zip(names, labels, strict=True)
        ],
        "class_sizes": dict(sorted(classes.items())),
        "failures": computed.failures,
        "rows": rows,
        "d2_sigma": d2_sigma,
        "timings": {
            **computed.stats,
            "metrics_seconds": metrics_seconds,
            "descriptor_stage_seconds_mean": _mean_timings(
                [d.timings for d in computed.descriptors]
            ),
            "shapedna_seconds_mean": float(np.mean([b.seconds for b in computed.baselines])),
            "note": (
                "per-mesh stage times are those recorded when each descriptor was "
                "computed (possibly in an earlier run, under other load)"
            ),
        },
        "environment": dict(environment or {}),
    }
    return report, matrices


def _pct(value: float, digits: int) -> str:
    return f"{100.0 * value:.{digits}f}"


def _confusion_summary(errors: Sequence[Mapping[str, str]], true_key: str, got_key: str) -> str:
    pairs = Counter((e[true_key], e[got_key]) for e in errors)
    return ", ".join(f"{a}->{b} x{c}" for (a, b), c in sorted(pairs.items(), key=lambda x: -x[1]))


def render_markdown(report: Mapping) -> str:
    """report.md: the protocol, the table (percent) and which classes were confused."""
    protocol = report["protocol"]
    preset = report["preset"]
    lines = [
        f"# Evaluation: preset `{preset['name']}` v{preset['version']}",
        "",
        f"Dataset: `{report['dataset']}`, {protocol['objects']} objects, "
        f"{protocol['classes']} classes "
        f"({', '.join(f'{k} {v}' for k, v in report['class_sizes'].items())}).",
        "",
        f"Command: `{report['command'] or '(not recorded)'}`",
        "",
        "All numbers in percent. NN, FT, ST, E, DCG, mAP: leave-one-out retrieval; "
        "R1RR: identification; EER: verification (lower is better). "
        f"The preset's own score is **{protocol['preset_score']}**.",
        "",
        "| | " + " | ".join(COLUMNS.values()) + " |",
        "|---|" + "---:|" * len(COLUMNS),
    ]
    for row in report["rows"].values():
        cells = [_pct(row[k], 2 if k == "eer" else 1) for k in COLUMNS]
        lines.append(f"| {row['title']} | " + " | ".join(cells) + " |")
    lines += ["", "## Protocol", ""]
    lines += [f"- **{key}**: {text}" for key, text in protocol.items()]
    lines += ["", "## Errors", "", "| | NN errors (class->nearest) | R1 errors (class->match) |"]
    lines.append("|---|---|---|")
    for row in report["rows"].values():
        nn = _confusion_summary(row["nn_errors"], "class", "nearest_class") or "none"
        r1 = _confusion_summary(row["rank1_errors"], "class", "matched_class") or "none"
        lines.append(f"| {row['title']} | {nn} | {r1} |")
    if report["failures"]:
        lines += ["", "## Meshes left out", ""]
        lines += [f"- `{name}`: {why}" for name, why in report["failures"].items()]
    timings = report["timings"]
    lines += [
        "",
        "## Timings",
        "",
        f"{timings['meshes']} meshes: {timings['from_cache']} from cache, "
        f"{timings['computed']} computed in {timings['compute_seconds']:.1f} s "
        f"with {timings['jobs']} worker process(es); metrics {timings['metrics_seconds']:.1f} s. "
        "Mean seconds per mesh when computed: "
        + ", ".join(f"{k} {v:.2f}" for k, v in timings["descriptor_stage_seconds_mean"].items())
        + f"; ShapeDNA {timings['shapedna_seconds_mean']:.2f}.",
        "",
        "![CMC](cmc.png) ![ROC](roc.png)",
        "",
    ]
    return "\n".join(lines)


def environment_info() -> dict[str, str]:
    """Versions that can change the numbers."""
    import lapy
    import scipy

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "lapy": lapy.__version__,
        "engine_fingerprint": engine_fingerprint()[:16],
    }


def run_evaluation(
    dataset_dir: str | Path,
    labels_csv: str | Path,
    preset: Preset,
    *,
    out_dir: str | Path,
    cache_root: str | Path,
    jobs: int = 1,
    per_class_limit: int | None = None,
    command: str = "",
    environment: Mapping[str, str] | None = None,
    progress: bool = True,
    plot: Callable[[Mapping, Path], None] | None = None,
) -> dict:
    """Describe, compare and score a labelled collection; write the report to ``out_dir``.

    Writes ``report.json``, ``report.md``, ``cmc.png`` and ``roc.png``.

    Returns
    -------
    The report dict (as in report.json).
    """
    meshes = read_labels(labels_csv, dataset_dir, per_class_limit)
    computed = compute_descriptors(meshes, preset, cache_root, jobs=jobs, progress=progress)
    if len({m.label for m in computed.meshes}) < 2:
        raise EvaluationError(
            f"fewer than two classes left after {len(computed.failures)} meshes failed"
        )
    env = {**environment_info(), **(environment or {})}
    report, _ = build_report(
        computed, preset, command=command, environment=env, dataset=str(dataset_dir)
    )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if plot is None:
        from .report_plots import plot_report as plot
    start = time.perf_counter()
    plot(report, out)
    report["timings"]["plot_seconds"] = time.perf_counter() - start
    (out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "report.md").write_text(render_markdown(report))
    return report
