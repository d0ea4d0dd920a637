"""The service's HTTP client behind ``shapes import``, ``query``, ``collections`` and
``keys`` (:mod:`app.cli` parses their arguments).

HTTP only (httpx); nothing of the server is imported, so it runs against any
deployment. ``--url`` defaults to ``SHAPES_URL``, else to where the service's own
settings (``SHAPES_HOST``, ``SHAPES_PORT``) make ``./scripts/serve.sh`` listen.

``shapes import DIR|FILES... [--labels labels.csv] [--url URL] [--api-key K]
[--concurrency N] [--wait]`` enrolls every mesh file with a progress bar and an
ETA. It is resumable: a file whose content the service already holds answers 200
with the existing mesh (the service deduplicates by sha256), so a rerun skips what
is enrolled; Ctrl-C lets the uploads under way finish, starts no other and says so.
With ``--wait`` it follows the descriptions until every mesh is ready or failed. It
ends with a table of the failures and their reasons, and exits non-zero when any
file failed.

``shapes query FILE [--url URL] [-k K] [--json]`` prints the ranked matches as a
table (rank, name, label, score, per-modality scores, confidence).
"""

from __future__ import annotations

import csv
import os
import sys
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx


def default_url(environ: Mapping[str, str]) -> str:
    """Where the commands find the service: ``SHAPES_URL``, else the address the
    service's own settings make it listen on (``SHAPES_HOST``, ``SHAPES_PORT``; an
    all-interfaces host is reached on loopback)."""
    if environ.get("SHAPES_URL"):
        return environ["SHAPES_URL"].rstrip("/")
    host = environ.get("SHAPES_HOST") or "127.0.0.1"
    if host in ("0.0.0.0", "::"):
        host = "127.0.0.1"
    host = f"[{host}]" if ":" in host else host
    return f"http://{host}:{environ.get('SHAPES_PORT') or 8000}"


DEFAULT_URL = default_url(os.environ)
#: The engine's formats (``worker.engine.formats.MESH_FORMATS``, which a test keeps equal):
#: the client loads nothing of the server.
MESH_SUFFIXES = (
    ".obj",
    ".ply",
    ".off",
    ".stl",
    ".glb",
    ".gltf",
    ".pcd",
    ".e57",
    ".xyz",
    ".pts",
    ".csv",
)
TIMEOUT = httpx.Timeout(300.0, connect=10.0)
#: Below this share of an enrolled file's surface described, the import lists it as
#: described in part (specks and debris are far smaller; the service's notes on a query
#: and the web page use the same figure).
PARTIAL_SURFACE = 0.99


class ClientError(RuntimeError):
    """The service could not be reached or refused the request; the message says why."""


class Interrupted(ClientError):
    """Ctrl-C during an import: the uploads under way finished, no new one started."""


def mesh_files(paths: Iterable[str], labels: Path | None = None) -> list[Path]:
    """The mesh files named or found (recursively) in the directories named, sorted; a
    directory's ``labels`` file (a CSV, as points can be) is not one of them."""
    found: list[Path] = []
    skipped = None if labels is None else labels.resolve()
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            found.extend(
                p
                for p in sorted(path.rglob("*"))
                if p.is_file() and is_mesh(p) and p.resolve() != skipped
            )
        elif path.is_file():
            found.append(path)
        else:
            raise ClientError(f"{raw}: no such file or directory")
    return found


def is_mesh(path: Path) -> bool:
    name = path.name.lower()
    name = name[: -len(".gz")] if name.endswith(".gz") else name
    return name.endswith(MESH_SUFFIXES)


def read_labels(path: Path) -> dict[str, str]:
    """``file,class`` (or ``file,label``) rows: file name -> label."""
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        fields = {f.strip().lower(): f for f in reader.fieldnames or []}
        column = fields.get("label") or fields.get("class")
        if "file" not in fields or column is None:
            raise ClientError(f"{path} needs a header row with 'file' and 'class' (or 'label')")
        return {
            Path(row[fields["file"]].strip()).name: row[column].strip()
            for row in reader
            if row[fields["file"]].strip()
        }


def collection_prefix(collection: str | None) -> str:
    """The path prefix of a collection's resources (none: the default collection, which
    the paths without ``/collections/{name}`` work on)."""
    return "" if collection in (None, "default") else f"/collections/{collection}"


def _client(url: str, api_key: str | None) -> httpx.Client:
    headers = {"X-API-Key": api_key} if api_key else {}
    return httpx.Client(base_url=url.rstrip("/"), timeout=TIMEOUT, headers=headers)


def _refusal(response: httpx.Response) -> str:
    try:
        body = response.json()
        return f"{body.get('error', response.status_code)}: {body.get('detail', '')}".strip()
    except ValueError:
        return f"HTTP {response.status_code}"


@dataclass
class ImportResult:
    """What happened to every file of an import."""

    enrolled: dict[Path, int] = field(default_factory=dict)  # new meshes
    existing: dict[Path, int] = field(default_factory=dict)  # already there (same bytes)
    failed: dict[Path, str] = field(default_factory=dict)  # refused, or failed to describe
    # described, but only their largest connected part: the share of the surface (--wait)
    partial: dict[Path, float] = field(default_factory=dict)

    @property
    def count(self) -> int:
        return len(self.enrolled) + len(self.existing) + len(self.failed)


class Progress:
    """A one-line progress bar with a rate and an ETA, on stderr."""

    def __init__(self, total: int, what: str, stream: Any = sys.stderr) -> None:
        self.total, self.what, self.stream = total, what, stream
        self.done = 0
        self.started = time.monotonic()
        self._lock = threading.Lock()

    def step(self, count: int = 1) -> None:
        with self._lock:
            self.done += count
            self.show()

    def show(self) -> None:
        elapsed = time.monotonic() - self.started
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        width = 30
        filled = int(width * self.done / max(self.total, 1))
        bar = "#" * filled + "." * (width - filled)
        eta_text = f"{eta:5.0f}s" if eta == eta else "    ?"
        self.stream.write(
            f"\r{self.what} [{bar}] {self.done}/{self.total} {rate * 60:6.1f}/min ETA {eta_text}"
        )
        self.stream.flush()

    def close(self) -> None:
        self.stream.write("\n")
        self.stream.flush()


def import_files(
    files: list[Path],
    *,
    url: str = DEFAULT_URL,
    api_key: str | None = None,
    labels: dict[str, str] | None = None,
    collection: str | None = None,
    concurrency: int = 4,
    wait: bool = False,
    poll_seconds: float = 1.0,
    stream: Any = sys.stderr,
) -> ImportResult:
    """Enroll ``files`` through ``POST /meshes`` (of ``collection``); with ``wait``, until
    each is described."""
    labels = labels or {}
    prefix = collection_prefix(collection)
    result = ImportResult()
    lock = threading.Lock()
    progress = Progress(len(files), "upload  ", stream)
    with _client(url, api_key) as client:
        _check_reachable(client, url)

        def upload(path: Path) -> None:
            data = {"label": labels[path.name]} if path.name in labels else {}
            try:
                with open(path, "rb") as handle:
                    response = client.post(
                        f"{prefix}/meshes", files={"file": (path.name, handle)}, data=data
                    )
            except httpx.HTTPError as exc:
                outcome: tuple[str, Any] = ("failed", f"connection: {exc}")
            else:
                body = response.json() if response.status_code in (200, 202) else {}
                if response.status_code == 202:
                    outcome = ("enrolled", body["id"])
                elif body.get("status") == "failed":  # enrolled before, and failed then
                    outcome = ("failed", f"{body['error']}: {body['detail']}")
                elif response.status_code == 200:
                    outcome = ("existing", body["id"])
                else:
                    outcome = ("failed", _refusal(response))
            with lock:
                getattr(result, outcome[0])[path] = outcome[1]
            progress.step()

        pool = ThreadPoolExecutor(max(1, concurrency))
        try:
            for future in as_completed([pool.submit(upload, p) for p in files]):
                future.result()
        except KeyboardInterrupt:
            # Let the uploads under way finish (each is stored whole or not at all)
            # and start no other: a rerun then skips exactly what was enrolled.
            pool.shutdown(wait=True, cancel_futures=True)
            progress.close()
            raise Interrupted(
                f"interrupted after {len(result.enrolled) + len(result.existing)} of "
                f"{len(files)} files; run the same command again to enroll the rest "
                "(files already enrolled are skipped)"
            ) from None
        pool.shutdown()
        progress.close()
        if wait:
            try:
                _wait_described(client, prefix, result, poll_seconds, stream)
            except KeyboardInterrupt:
                progress.close()
                raise Interrupted(
                    "interrupted while waiting: every file is enrolled and will be "
                    "described; GET /meshes?status=ready shows which are done"
                ) from None
    return result


def _check_reachable(client: httpx.Client, url: str) -> None:
    try:
        client.get("/health")
    except httpx.HTTPError as exc:
        raise ClientError(
            f"no service answers at {url} ({exc}); start it with ./scripts/serve.sh or pass --url"
        ) from None


def _wait_described(
    client: httpx.Client, prefix: str, result: ImportResult, poll_seconds: float, stream: Any
) -> None:
    """Follow every enrolled or existing mesh until it is ready or failed."""
    pending = {**result.enrolled, **result.existing}
    progress = Progress(len(pending), "describe", stream)
    while pending:
        for path, mesh_id in list(pending.items()):
            response = client.get(f"{prefix}/meshes/{mesh_id}")
            if response.status_code != 200:
                result.failed[path] = _refusal(response)
            else:
                body = response.json()
                if body["status"] == "failed":
                    result.failed[path] = f"{body['error']}: {body['detail']}"
                elif body["status"] != "ready":
                    continue
                elif _partial(body["descriptor"]["kept_area_fraction"]):
                    result.partial[path] = body["descriptor"]["kept_area_fraction"]
            del pending[path]
            progress.step()
        if pending:
            time.sleep(poll_seconds)
    progress.close()
    for path in result.failed:
        result.enrolled.pop(path, None)
        result.existing.pop(path, None)


def query_file(
    path: Path,
    *,
    url: str = DEFAULT_URL,
    api_key: str | None = None,
    k: int = 10,
    collection: str | None = None,
) -> dict[str, Any]:
    """``POST /query`` (of ``collection``) with ``path``; the response body."""
    with _client(url, api_key) as client:
        _check_reachable(client, url)
        with open(path, "rb") as handle:
            response = client.post(
                f"{collection_prefix(collection)}/query",
                files={"file": (path.name, handle)},
                data={"k": str(k)},
            )
    if response.status_code != 200:
        raise ClientError(f"{path.name}: {_refusal(response)}")
    body: dict[str, Any] = response.json()
    return body


def aligned(rows: Sequence[Sequence[str]]) -> list[str]:
    """Rows of cells as lines of left-aligned columns, two spaces apart."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return [
        "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows
    ]


def format_matches(body: dict[str, Any]) -> str:
    """The ranked matches as an aligned text table."""
    # The modalities that ranked (a weight above 0; a partial query's parts among them).
    matches = body["matches"]
    modalities = list(body["modalities"])
    # A single view's verified matches: the share of it each holds once fitted rigidly.
    fitted = any(m.get("fitness") is not None for m in matches)
    header = ["rank", "name", "label", "score", *modalities, *(["fitness"] * fitted), "confidence"]
    rows = [
        [
            str(m["rank"]),
            m["name"],
            m["label"] or "-",
            f"{m['score']:.4g}",
            *(f"{m['scores'][x]:.4g}" for x in modalities),
            *([_share(m.get("fitness"))] * fitted),
            "-" if m["confidence"] is None else f"{m['confidence']:.0%}",
        ]
        for m in matches
    ]
    lines = aligned([header, *rows])
    title = (
        f"{body['preset']} v{body['preset_version']}, {body['fusion']} of "
        f"{'+'.join(modalities)}, {body['gallery_size']} enrolled in {body['collection']} "
        "(lower score = more alike)"
    )
    own = {  # a fusion the collection learned compares these otherwise (the size has its own)
        m: c
        for m, c in body.get("comparisons", {}).items()
        if m not in ("size", "parts") and c != body["dissimilarity"]
    }
    if own:
        title += "\nCompared by the collection's learned fusion: " + ", ".join(
            f"{m} by {c}" for m, c in own.items()
        )
    # The service's own sentences on the query: the point cloud it was, the part of the file
    # left out, how partial it looks or that it was smoothed.
    for note in body.get("notes", []):
        title += f"\n{note}"
    return "\n".join([title, *lines])


def _share(value: float | None) -> str:
    return "-" if value is None else f"{value:.0%}"


def _partial(kept_area_fraction: float | None) -> bool:
    """Whether a described file left a noticeable part of its surface out."""
    return kept_area_fraction is not None and kept_area_fraction < PARTIAL_SURFACE


def partial_table(result: ImportResult) -> str:
    width = max(len(p.name) for p in result.partial)
    lines = [
        f"{len(result.partial)} described in part: only their largest connected part, "
        "their other, separate parts left out",
        f"{'file'.ljust(width)}  described",
    ]
    lines += [f"{p.name.ljust(width)}  {kept:.0%}" for p, kept in sorted(result.partial.items())]
    return "\n".join(lines)


def failure_table(result: ImportResult) -> str:
    width = max(len(p.name) for p in result.failed)
    lines = [f"{'file'.ljust(width)}  reason"]
    lines += [f"{p.name.ljust(width)}  {why}" for p, why in sorted(result.failed.items())]
    return "\n".join(lines)


def format_collections(items: list[dict[str, Any]]) -> str:
    """The collections as an aligned text table."""
    rows = [("name", "units", "preset", "meshes", "ready")] + [
        (
            c["name"],
            c["units"],
            f"{c['preset']} v{c['preset_version']}",
            str(c["meshes"]),
            str(c["ready"]),
        )
        for c in items
    ]
    return "\n".join(aligned(rows))


def call(url: str, api_key: str | None, method: str, path: str, **kwargs: Any) -> Any:
    """One request to the service: its JSON answer (None for 204); ClientError with the
    service's sentence when refused."""
    with _client(url, api_key) as client:
        _check_reachable(client, url)
        response = client.request(method, path, **kwargs)
    if response.status_code >= 400:
        raise ClientError(_refusal(response))
    return None if response.status_code == 204 else response.json()
