"""What the benchmarks, the experiments and the service tests share.

* the TOSCA meshes: labels, descriptors described once and cached (in the benchmarks'
  own cache, or in the evaluation cache that ``shapes evaluate`` fills), and a file's
  full-resolution spectrum;
* a throwaway service: ``python -m app`` on a fresh data directory (:func:`serving`), or
  its API and worker processes started one by one (:class:`Service`, what the service
  tests run);
* throwaway PostgreSQL and Redis servers on loopback ports (:class:`Postgres`,
  :class:`Redis`; Debian's ``postgresql`` and ``redis-server`` packages, which
  ``scripts/test.sh`` installs when missing).

Run the scripts as modules from the repository root (``python -m benchmarks.enroll``,
``python -m experiments.size_cue``), as ``scripts/test.sh`` runs the tests.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import IO, Any

import httpx
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from app.client import collection_prefix
from worker.engine.descriptor import ShapeDescriptor
from worker.engine.intrinsic import averaged_mass, surface_operators
from worker.engine.mesh_io import Mesh
from worker.engine.pipeline import describe_file, describe_mesh
from worker.engine.presets import DEFAULT_PRESET, MODALITIES, Preset, get_preset
from worker.evaluation.compute import ComputedSet, compute_descriptors
from worker.evaluation.datasets import (
    DEFAULT_CACHE,
    LabeledMesh,
    pose_set,
    read_labels,
    shared_dataset,
)
from worker.evaluation.run import described_copies
from worker.evaluation.variants import standing_name

REPO = Path(__file__).resolve().parents[1]
TOSCA = shared_dataset("tosca")
SCAPE = shared_dataset("scape")
#: The axis SCAPE's poses stand on, which the partiality protocol's range camera orbits
#: (the documented runs' ``shapes partiality --poses-up x``); TOSCA's files stand on z.
SCAPE_UP = "x"
#: The sample collection the repository bundles (``shapes samples`` writes it).
EXAMPLES = REPO / "examples"
CACHE = REPO / ".cache" / "tosca-descriptors"
#: Seconds the service gets to start, and a request or a mesh to finish.
TIMEOUT = 120.0
#: Seconds a throwaway Redis server gets to answer.
STARTUP_SECONDS = 60.0


# --------------------------------------------------------------------------- TOSCA


def tosca_labels() -> dict[str, str]:
    """File name -> class, from ``labels.csv``."""
    with open(TOSCA / "labels.csv", newline="") as fh:
        return {row["file"]: row["class"] for row in csv.DictReader(fh)}


def _describe(args: tuple[str, str]) -> tuple[str, bytes]:
    name, preset_name = args
    return name, describe_file(TOSCA / name, get_preset(preset_name)).to_npz_bytes()


def tosca_descriptors(preset_name: str, workers: int = 2) -> dict[str, ShapeDescriptor]:
    """Descriptors of all TOSCA meshes under ``preset_name`` (computed once, then cached)."""
    preset = get_preset(preset_name)
    cache = CACHE / f"{preset.name}-v{preset.version}"
    cache.mkdir(parents=True, exist_ok=True)
    names = sorted(tosca_labels())
    missing = [n for n in names if not (cache / f"{n}.npz").exists()]
    if missing:
        with ProcessPoolExecutor(workers) as pool:
            for name, blob in pool.map(_describe, [(n, preset_name) for n in missing]):
                (cache / f"{name}.npz").write_bytes(blob)
    return {n: ShapeDescriptor.from_npz_bytes((cache / f"{n}.npz").read_bytes()) for n in names}


def add_evaluation_cache_arguments(parser: argparse.ArgumentParser) -> None:
    """``--preset``, ``--cache`` (the evaluation cache) and ``--jobs``."""
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--jobs", type=int, default=2)


def evaluated_tosca(args: argparse.Namespace) -> tuple[Preset, ComputedSet]:
    """The TOSCA meshes described under ``args.preset`` through the evaluation cache
    (seconds after ``shapes evaluate`` has run with the same cache)."""
    preset = get_preset(args.preset)
    meshes = read_labels(TOSCA / "labels.csv", TOSCA)
    return preset, compute_descriptors(meshes, preset, args.cache, jobs=args.jobs)


def partiality_wholes() -> list[LabeledMesh]:
    """The partiality protocol's 154 wholes: TOSCA's meshes, then SCAPE's poses (one
    class), as ``shapes partiality --poses`` reads them."""
    return [*read_labels(TOSCA / "labels.csv", TOSCA), *pose_set(SCAPE)]


@cache
def partiality_standing() -> dict[str, str]:
    """File name -> the axis it stands on, for the wholes of :func:`partiality_wholes`
    not on z (SCAPE's poses, on ``SCAPE_UP``)."""
    return {m.name: SCAPE_UP for m in pose_set(SCAPE)}


def drawn_variant(variant: str, name: str) -> str:
    """The name the partiality protocol draws ``variant`` of the whole ``name`` under
    (:func:`~worker.evaluation.variants.make_variant`'s): around the axis it stands on."""
    return standing_name(variant, partiality_standing().get(name, "z"))


def partiality_copies(variant: str, preset: Preset, cache: Path, jobs: int) -> ComputedSet:
    """``variant``'s copies of :func:`partiality_wholes` as the protocol draws them (each
    around the axis its whole stands on), described through the partiality run's cache."""
    return described_copies(
        partiality_wholes(), variant, preset, cache, jobs=jobs, standing=partiality_standing()
    )


def evaluated_partiality_wholes(args: argparse.Namespace) -> tuple[Preset, ComputedSet]:
    """:func:`partiality_wholes` described under ``args.preset`` through the partiality
    run's cache (``args.cache``), as :func:`evaluated_tosca` does TOSCA."""
    preset = get_preset(args.preset)
    wholes = partiality_wholes()
    return preset, compute_descriptors(wholes, preset, args.cache, jobs=args.jobs, progress=False)


def first_of_each_class() -> list[str]:
    """The first file of every TOSCA class, in the order of ``labels.csv``."""
    firsts: dict[str, str] = {}
    for name, label in tosca_labels().items():
        firsts.setdefault(label, name)
    return list(firsts.values())


def full_resolution_spectra(
    mesh: Mesh, size: int, masses: tuple[str, ...] = ("lumped", "averaged")
) -> dict[str, np.ndarray]:
    """A file's own spectrum, at every vertex it has, with each mass named.

    Parameters
    ----------
    mesh : the file's mesh, not resampled.
    size : non-zero eigenvalues kept.
    masses : ``"lumped"`` (eq. 3's diagonal), ``"averaged"`` (the mean of the lumped
        and the consistent mass, :func:`worker.engine.intrinsic.averaged_mass`).

    Returns
    -------
    mass -> (size,) float, the smallest non-zero eigenvalues times the surface's area
    (the descriptor's scale), by shift-invert Lanczos.
    """
    intrinsic, ops = surface_operators(mesh.vertices, mesh.faces)
    area = float(ops.face_areas.sum())
    start = np.random.default_rng(0).standard_normal(intrinsic.n_vertices)
    shift = -1e-3 * 4 * np.pi / area  # below the spectrum, as in LaplaceBeltrami.shift
    stiffness = ops.stiffness.tocsc()
    spectra = {}
    for name in masses:
        if name == "lumped":
            mass = sp.csc_matrix(sp.diags(ops.vertex_areas))
        else:
            mass = averaged_mass(intrinsic, ops.face_areas).tocsc()
        values = sla.eigsh(stiffness, k=size + 1, M=mass, sigma=shift, v0=start)[0]
        spectra[name] = np.sort(values)[1:] * area
    return spectra


# --------------------------------------------------------------------------- the service


def free_port() -> int:
    """A loopback TCP port no one listens on (now)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@contextmanager
def serving(port: int, workers: int | None = None) -> Iterator[str]:
    """``python -m app`` on a fresh data directory, as a user runs it.

    Parameters
    ----------
    port : the API's port on 127.0.0.1.
    workers : enrollment consumers; None: the service's default.

    Yields
    ------
    The service's URL, once it answers ``/ready``; the service is stopped (SIGTERM,
    as Ctrl-C) and its data directory removed on exit.
    """
    extra = [] if workers is None else ["--workers", str(workers)]
    with tempfile.TemporaryDirectory(prefix="shapes-bench-") as tmp:
        command = ["-m", "app", "--port", str(port), "--data-dir", str(Path(tmp) / "data")]
        proc = subprocess.Popen(
            [sys.executable, *command, *extra],
            cwd=REPO,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            url = f"http://127.0.0.1:{port}"
            deadline = time.monotonic() + TIMEOUT
            while not _answers_ready(url):
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise SystemExit("the service did not start")
                time.sleep(0.3)
            yield url
        finally:
            proc.send_signal(signal.SIGTERM)
            proc.wait(60)


def _answers_ready(url: str) -> bool:
    try:
        return httpx.get(f"{url}/ready", timeout=2).status_code == 200
    except httpx.TransportError:
        return False


class Service:
    """The API process, its worker processes and an HTTP client, on one data directory.

    Nothing starts until asked (:meth:`start_api`, :meth:`start_worker`), so a caller
    can set ``env`` first (a database URL, the collector's interval). Each process logs
    to ``data_dir/logs``; :meth:`logs` gives their tails.
    """

    def __init__(self, data_dir: Path, meshes: Path = EXAMPLES) -> None:
        self.data_dir = data_dir
        self.meshes = meshes  # where :meth:`upload` and :meth:`query` find a mesh by name
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.env = dict(
            os.environ,
            SHAPES_DATA_DIR=str(data_dir),
            SHAPES_HEARTBEAT_SECONDS="1",
            # Long enough that a slow job on a loaded CI machine never looks dead.
            SHAPES_STALLED_AFTER_SECONDS="15",
            SHAPES_COLLECTOR_INTERVAL_SECONDS="0.2",
            SHAPES_MAX_UPLOAD_BYTES=str(1_000_000),
            SHAPES_QUERY_TIMEOUT_SECONDS="90",
            OMP_NUM_THREADS="1",
            OPENBLAS_NUM_THREADS="1",
        )
        self.api: subprocess.Popen[bytes] | None = None
        self.workers: dict[str, list[subprocess.Popen[bytes]]] = {"enroll": [], "query": []}
        self.client = httpx.Client(base_url=self.url, timeout=TIMEOUT)
        self._logs = data_dir / "logs"
        self._logs.mkdir(parents=True, exist_ok=True)

    def _spawn(self, args: list[str], name: str) -> subprocess.Popen[bytes]:
        # The child writes to the file for its whole life; the parent's handle is
        # closed when the Popen object goes.
        log: IO[bytes] = open(self._logs / f"{name}-{time.monotonic_ns()}.log", "wb")
        return subprocess.Popen(
            [sys.executable, *args], cwd=REPO, env=self.env, stdout=log, stderr=subprocess.STDOUT
        )

    def start_api(self) -> None:
        self.api = self._spawn(
            ["-m", "uvicorn", "app.main:app", "--host", "127.0.0.1", "--port", str(self.port)],
            "api",
        )
        self.wait_ready()

    def wait_ready(self) -> None:
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            assert self.api is not None and self.api.poll() is None, self.logs()
            try:
                if self.client.get("/ready").status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        raise AssertionError("the API did not become ready\n" + self.logs())

    def stop_api(self) -> None:
        if self.api is not None and self.api.poll() is None:
            self.api.send_signal(signal.SIGTERM)
            self.api.wait(60)
        self.api = None

    def start_worker(self, queue: str = "enroll") -> subprocess.Popen[bytes]:
        """A ``python -m worker`` consumer of the enrollment or the query queue."""
        worker = self._spawn(["-m", "worker", "--queue", queue], f"worker-{queue}")
        self.workers[queue].append(worker)
        return worker

    def stop_workers(self, queue: str | None = None) -> None:
        """Stop the consumers of ``queue`` (default: all), gracefully (SIGINT)."""
        stopping = [w for q, ws in self.workers.items() if queue in (None, q) for w in ws]
        for worker in stopping:
            if worker.poll() is None:
                worker.send_signal(signal.SIGINT)
        for worker in stopping:
            try:
                worker.wait(60)
            except subprocess.TimeoutExpired:
                worker.kill()
                worker.wait()
        for q in self.workers:
            if queue in (None, q):
                self.workers[q] = []

    def logs(self) -> str:
        out = []
        for path in sorted(self._logs.glob("*.log")):
            out.append(f"--- {path.name}\n{path.read_text(errors='replace')[-3000:]}")
        return "\n".join(out)

    def upload(
        self, name: str, label: str | None = None, *, collection: str | None = None, **fields: str
    ) -> httpx.Response:
        """Enroll the mesh ``name`` of :attr:`meshes` (e.g. ``"quadruped-0"``), in the
        default collection or ``collection``."""
        path = self.meshes / f"{name}.off.gz"
        data = {k: v for k, v in {"label": label, **fields}.items() if v is not None}
        with open(path, "rb") as fh:
            return self.client.post(
                f"{collection_prefix(collection)}/meshes",
                files={"file": (path.name, fh)},
                data=data,
            )

    def wait_mesh(
        self,
        mesh_id: int,
        statuses: tuple[str, ...] = ("ready", "failed"),
        *,
        collection: str | None = None,
    ) -> dict[str, Any]:
        """The mesh's resource once its status is one of ``statuses``."""
        deadline = time.monotonic() + TIMEOUT
        body: dict[str, Any] = {}
        while time.monotonic() < deadline:
            body = self.client.get(f"{collection_prefix(collection)}/meshes/{mesh_id}").json()
            if body["status"] in statuses:
                return body
            time.sleep(0.2)
        raise AssertionError(f"mesh {mesh_id} stuck at {body.get('status')}\n" + self.logs())

    def query(
        self, name: str, *, collection: str | None = None, **fields: object
    ) -> httpx.Response:
        """``POST /query`` with the mesh ``name`` of :attr:`meshes`."""
        path = self.meshes / f"{name}.off.gz"
        with open(path, "rb") as fh:
            return self.client.post(
                f"{collection_prefix(collection)}/query",
                files={"file": (path.name, fh)},
                data={k: str(v) for k, v in fields.items()},
            )

    def index_size(self) -> int:
        """Shapes in this API process's index, as ``/ready`` reports them."""
        check: str = self.client.get("/ready").json()["checks"]["index"]
        return int(check.removeprefix("ok (").split()[0])

    def close(self) -> None:
        self.stop_api()
        self.stop_workers()
        self.client.close()


def describing_children(worker: Service, timeout: float) -> list[int]:
    """The describing processes of ``worker``'s enrollment consumer (forked by its fork
    server: its children's children), once there is one, or [] after ``timeout``."""
    (consumer,) = worker.workers["enroll"]
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        parents: dict[int, int] = {}
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                parents[int(stat.parent.name)] = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError):  # gone meanwhile
                continue
        found = [p for p, parent in parents.items() if parents.get(parent) == consumer.pid]
        if found:
            return found
        time.sleep(0.01)
    return []


# --------------------------------------------------------------------------- servers


def _postgres_bin(name: str) -> str:
    versions = sorted(Path("/usr/lib/postgresql").glob(f"*/bin/{name}"))
    found = str(versions[-1]) if versions else shutil.which(name)
    if found is None:
        raise RuntimeError(f"PostgreSQL's {name} not found: apt-get install postgresql")
    return found


class Postgres:
    """A throwaway PostgreSQL cluster with one database ``shapes`` (trust auth).

    PostgreSQL refuses to run as root, so under root the cluster belongs to the
    package's ``postgres`` user.
    """

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="shapes-pg-"))
        self.port = free_port()
        self._as_user: list[str] = []
        if os.geteuid() == 0:
            shutil.chown(self.root, "postgres")
            self._as_user = ["runuser", "-u", "postgres", "--"]
        self.url = f"postgresql+psycopg://shapes@127.0.0.1:{self.port}/shapes"

    def _run(self, *args: str) -> None:
        subprocess.run([*self._as_user, *args], check=True, capture_output=True, cwd=self.root)

    def start(self) -> Postgres:
        """Create the cluster and its database on the first call; start it again after
        :meth:`kill`."""
        data = self.root / "data"
        created = data.exists()
        if not created:
            self._run(_postgres_bin("initdb"), "-D", str(data), "-U", "shapes", "--auth=trust",
                      "-E", "UTF8")  # fmt: skip
        options = f"-p {self.port} -k {self.root} -c listen_addresses=127.0.0.1 -c fsync=off"
        self._run(
            _postgres_bin("pg_ctl"), "-D", str(data), "-o", options, "-l", str(self.root / "log"),
            "-w", "start",
        )  # fmt: skip
        if not created:
            self._run(_postgres_bin("createdb"), "-h", "127.0.0.1", "-p", str(self.port), "-U",
                      "shapes", "shapes")  # fmt: skip
        return self

    def kill(self) -> None:
        """Stop the server at once (immediate mode: no checkpoint, clients cut off, as
        a crash); :meth:`start` brings it back with its data."""
        self._run(_postgres_bin("pg_ctl"), "-D", str(self.root / "data"), "-m", "immediate",
                  "stop")  # fmt: skip

    def _processes(self) -> list[int]:
        """The cluster's processes: the postmaster (its pid file's first line) and its
        children."""
        postmaster = int((self.root / "data" / "postmaster.pid").read_text().split()[0])
        children = []
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                if int(stat.read_text().rsplit(")", 1)[1].split()[1]) == postmaster:
                    children.append(int(stat.parent.name))
            except (OSError, ValueError):  # gone meanwhile
                continue
        return [postmaster, *children]

    def freeze(self) -> None:
        """Stop every process of the server (SIGSTOP): connections stay open and
        nothing answers, as on a hung host; :meth:`thaw` resumes them."""
        for pid in self._processes():
            os.kill(pid, signal.SIGSTOP)

    def thaw(self) -> None:
        for pid in self._processes():
            os.kill(pid, signal.SIGCONT)

    def stop(self) -> None:
        try:
            self.kill()
        finally:
            shutil.rmtree(self.root, ignore_errors=True)


class Redis:
    """A ``redis-server`` that logs every write (AOF, fsync always), so a kill -9 and a
    restart keep the queue as it was."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="shapes-redis-"))
        self.port = free_port()
        self.url = f"redis://127.0.0.1:{self.port}/0"
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> Redis:
        # The redis extra: only the scale-out runs need the client.
        import redis

        binary = shutil.which("redis-server")
        if binary is None:
            raise RuntimeError("redis-server not found: apt-get install redis-server")
        self.process = subprocess.Popen(
            [binary, "--port", str(self.port), "--bind", "127.0.0.1", "--dir", str(self.root),
             "--save", "", "--appendonly", "yes", "--appendfsync", "always"],
            stdout=subprocess.DEVNULL,
        )  # fmt: skip
        client = redis.Redis.from_url(self.url)
        deadline = time.monotonic() + STARTUP_SECONDS
        while True:
            try:
                client.ping()
                return self
            except redis.ConnectionError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    def kill(self) -> None:
        """kill -9, as a crash would."""
        assert self.process is not None
        self.process.send_signal(signal.SIGKILL)
        self.process.wait()

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait(30)
        shutil.rmtree(self.root, ignore_errors=True)


Vectors = dict[str, np.ndarray]


def resident_mb() -> float:
    """The process's resident memory now (Linux)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def timed_description(mesh: Mesh, preset: Preset) -> dict[str, float]:
    """Describe ``mesh``: its described vertex count, the seconds, each stage's
    (``timings``) and the process's peak resident memory so far."""
    start = time.perf_counter()
    descriptor = describe_mesh(mesh, preset)
    return {
        "vertices": descriptor.vertices,
        "seconds": time.perf_counter() - start,
        **descriptor.timings,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def fresh_process_runs(module: str, arguments: list[str], repeat: int) -> list[dict[str, float]]:
    """``python -m module *arguments`` run ``repeat`` times, each in a fresh process (so
    each peak memory is its own), each printing one JSON object as its last line."""
    command = [sys.executable, "-m", module, *arguments]
    runs = []
    for _ in range(repeat):
        out = subprocess.run(command, check=True, capture_output=True, text=True)
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    return runs


def synthetic_model(preset_name: str) -> dict[str, Vectors]:
    """Log-space class structure of the real TOSCA descriptors, per modality."""
    descriptors = tosca_descriptors(preset_name)
    labels = tosca_labels()
    names = sorted(descriptors)
    classes = sorted(set(labels[n] for n in names))
    model = {}
    for m in MODALITIES:
        x = np.stack([descriptors[n].vector(m) for n in names])
        positive = x[x > 0]
        floor = positive.min() if positive.size else 1e-12
        logx = np.log(np.maximum(x, floor))
        mu = logx.mean(axis=0)
        class_means = np.stack(
            [logx[[labels[n] == c for n in names]].mean(axis=0) for c in classes]
        )
        residuals = np.concatenate(
            [logx[[labels[n] == c for n in names]] - class_means[i] for i, c in enumerate(classes)]
        )
        model[m] = {
            "mu": mu,
            "between": class_means - mu,
            "spread": (class_means - mu).std(axis=0),
            "within": residuals,
        }
    return model


def synthetic(
    model: dict[str, Vectors], n_classes: int, per_class: int, rng: np.random.Generator
) -> Vectors:
    """``n_classes * per_class`` descriptors (modality -> (N, M)), class by class."""
    n = n_classes * per_class
    nb = len(next(iter(model.values()))["between"])
    nw = len(next(iter(model.values()))["within"])
    # The same class and pose draws for every modality (a shape is one draw).
    centre_weights = rng.normal(size=(n_classes, nb)) / np.sqrt(nb)
    member_weights = rng.normal(size=(n, nw)) / np.sqrt(nw)
    out = {}
    for m, part in model.items():
        noise = 0.3 * part["spread"] * rng.normal(size=(n_classes, len(part["mu"])))
        centres = part["mu"] + centre_weights @ part["between"] + noise
        out[m] = np.exp(np.repeat(centres, per_class, axis=0) + member_weights @ part["within"])
    return out
