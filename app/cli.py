"""The ``shapes`` command: the service's verbs (``import``, ``query``, ``collections`` and
``keys`` over HTTP, :mod:`app.client`; ``backup`` and ``restore`` of the embedded
deployment, :mod:`app.backup`) beside the engine's (``describe``, ``evaluate``,
``robustness``, ``partiality``, ``tune``, ``samples``: :mod:`worker.cli`).

Each verb loads what it needs when it runs: the help, and the client's verbs, start
without the engine, the server or the migrations."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from worker import cli as engine_cli

from .client import (
    DEFAULT_URL,
    MESH_SUFFIXES,
    ClientError,
    Interrupted,
    aligned,
    call,
    failure_table,
    format_collections,
    format_matches,
    import_files,
    mesh_files,
    partial_table,
    query_file,
    read_labels,
)

if TYPE_CHECKING:
    from .config import Settings


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="shapes",
        description="Pose-invariant 3D shape retrieval. describe, evaluate, robustness, "
        "partiality, tune and samples run the descriptor engine here; import, query, "
        "collections and keys talk to a running service over HTTP; backup and restore copy "
        "an embedded deployment's data directory.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    engine_cli.add_subcommands(sub)
    _add_client_subcommands(sub)
    _add_backup_subcommands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    code: int = args.run(args)
    return code


# ------------------------------------------------------------- the service's client
def _add_client_subcommands(sub: Any) -> None:
    """Register ``import``, ``query``, ``collections`` and ``keys`` on the ``shapes``
    parser's subparsers."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--url", default=DEFAULT_URL, help=f"the service (default {DEFAULT_URL})")
    common.add_argument(
        "--api-key",
        default=os.environ.get("SHAPES_API_KEY"),
        help="the service's API key, if it has one (default $SHAPES_API_KEY)",
    )
    scoped = argparse.ArgumentParser(add_help=False, parents=[common])
    scoped.add_argument(
        "--collection",
        default="default",
        help="the collection to work on (default: the default collection)",
    )
    enroll = sub.add_parser(
        "import",
        parents=[scoped],
        help="enroll a folder or files through the service's API",
        description="Enroll mesh files (directories are searched recursively) with a "
        "progress bar; files already enrolled (same bytes) are skipped. Exits non-zero "
        "when any file failed.",
    )
    enroll.add_argument("paths", nargs="+", help="mesh files or directories")
    enroll.add_argument("--labels", help="CSV with columns file,class (file names)")
    enroll.add_argument("--concurrency", type=int, default=4, help="uploads at once (4)")
    enroll.add_argument("--wait", action="store_true", help="wait until every mesh is described")
    enroll.set_defaults(run=_import_command)
    query = sub.add_parser(
        "query",
        parents=[scoped],
        help="rank the enrolled meshes against a mesh file",
    )
    query.add_argument("file", help="the mesh to search with")
    query.add_argument("-k", type=int, default=10, help="matches (10)")
    query.add_argument("--json", action="store_true", help="print the service's JSON answer")
    query.set_defaults(run=_query_command)
    collections = sub.add_parser(
        "collections",
        help="list, create or delete the service's collections",
        description="A collection is a gallery of its own: meshes, index, calibration, "
        "preset and units (any: scale-free; metric: every file in one physical unit, so "
        "size counts).",
    )
    action = collections.add_subparsers(dest="action", required=True)
    listing = action.add_parser("list", parents=[common], help="each collection and its meshes")
    listing.set_defaults(run=_collections_command)
    create = action.add_parser("create", parents=[common], help="a new, empty collection")
    create.add_argument("name")
    create.add_argument("--units", choices=("any", "metric"), default="any")
    create.add_argument("--preset", help="default: the service's")
    create.set_defaults(run=_collections_command)
    delete = action.add_parser(
        "delete", parents=[common], help="a collection with every mesh enrolled in it"
    )
    delete.add_argument("name")
    delete.set_defaults(run=_collections_command)
    keys = sub.add_parser(
        "keys",
        help="make, list or revoke API keys (with the admin key, $SHAPES_API_KEY)",
        description="A key opens one collection (or * for all) with a scope: read (list, "
        "download, search, verify), write (also enroll and delete meshes) or admin (also "
        "delete the collection; for *, create collections and manage keys).",
    )
    key_action = keys.add_subparsers(dest="action", required=True)
    key_list = key_action.add_parser("list", parents=[common], help="every key's id and scope")
    key_list.set_defaults(run=_keys_command)
    key_create = key_action.add_parser(
        "create", parents=[common], help="a new key, printed once (only its hash is stored)"
    )
    key_create.add_argument("collection", help="a collection's name, or '*' for all")
    key_create.add_argument("scope", choices=("read", "write", "admin"))
    key_create.set_defaults(run=_keys_command)
    key_revoke = key_action.add_parser("revoke", parents=[common], help="revoke a key by id")
    key_revoke.add_argument("id", type=int)
    key_revoke.set_defaults(run=_keys_command)


def _import_command(args: argparse.Namespace) -> int:
    try:
        files = mesh_files(args.paths, Path(args.labels) if args.labels else None)
        labels = read_labels(Path(args.labels)) if args.labels else {}
        if not files:
            suffixes = " ".join(MESH_SUFFIXES)
            raise ClientError(f"no mesh files found ({suffixes}, or .gz)")
        result = import_files(
            files,
            url=args.url,
            api_key=args.api_key,
            labels=labels,
            collection=args.collection,
            concurrency=args.concurrency,
            wait=args.wait,
        )
    except Interrupted as exc:
        print(f"shapes import: {exc}", file=sys.stderr)
        return 130  # the shell's code for SIGINT
    except ClientError as exc:
        print(f"shapes import: {exc}", file=sys.stderr)
        return 2
    print(
        f"{result.count} files: {len(result.enrolled)} enrolled, "
        f"{len(result.existing)} already enrolled, {len(result.failed)} failed"
    )
    if result.partial:
        print(partial_table(result))
    if result.failed:
        print(failure_table(result))
        return 1
    return 0


def _query_command(args: argparse.Namespace) -> int:
    try:
        body = query_file(
            Path(args.file),
            url=args.url,
            api_key=args.api_key,
            k=args.k,
            collection=args.collection,
        )
    except (ClientError, OSError) as exc:
        print(f"shapes query: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(body, indent=1) if args.json else format_matches(body))
    return 0


def _call(args: argparse.Namespace, command: str, method: str, path: str, **kwargs: Any) -> Any:
    """One request of ``shapes collections`` or ``shapes keys`` (:func:`app.client.call`),
    its refusal prefixed with the command."""
    try:
        return call(args.url, args.api_key, method, path, **kwargs)
    except ClientError as exc:
        raise ClientError(f"shapes {command} {args.action}: {exc}") from None


def _collections_command(args: argparse.Namespace) -> int:
    try:
        if args.action == "list":
            print(format_collections(_call(args, "collections", "GET", "/collections")["items"]))
        elif args.action == "create":
            body = {"name": args.name, "units": args.units}
            if args.preset:
                body["preset"] = args.preset
            made = _call(args, "collections", "POST", "/collections", json=body)
            units, preset = made["units"], made["preset"]
            print(f"created collection {made['name']} (units {units}, preset {preset})")
        else:
            _call(args, "collections", "DELETE", f"/collections/{args.name}")
            print(f"deleted collection {args.name} and its meshes")
    except ClientError as exc:
        print(exc, file=sys.stderr)
        return 1
    return 0


def _keys_command(args: argparse.Namespace) -> int:
    try:
        if args.action == "list":
            items = _call(args, "keys", "GET", "/keys")["items"]
            rows = [("id", "collection", "scope", "created")] + [
                (str(k["id"]), k["collection"], k["scope"], k["created_at"][:19]) for k in items
            ]
            print("\n".join(aligned(rows)))
        elif args.action == "create":
            body = {"collection": args.collection, "scope": args.scope}
            made = _call(args, "keys", "POST", "/keys", json=body)
            print(made["key"])
            print(
                f"key {made['id']}: {made['scope']} on {made['collection']}; shown this once, "
                "keep it now",
                file=sys.stderr,
            )
        else:
            _call(args, "keys", "DELETE", f"/keys/{args.id}")
            print(f"revoked key {args.id}")
    except ClientError as exc:
        print(exc, file=sys.stderr)
        return 1
    return 0


# --------------------------------------------------------- the embedded deployment
# The backup loads the settings and the migrations (alembic): only when it runs.
def _settings(args: argparse.Namespace) -> Settings:
    from .config import Settings

    return Settings(data_dir=Path(args.data_dir)) if args.data_dir else Settings()


def _backup(args: argparse.Namespace) -> int:
    from .backup import MANIFEST, BackupError, backup

    try:
        manifest = backup(_settings(args), Path(args.dest))
    except BackupError as exc:
        print(f"shapes backup: {exc}", file=sys.stderr)
        return 1
    size = sum(f["bytes"] for f in manifest["files"].values())
    print(
        f"Backed up {manifest['meshes']} meshes ({manifest['descriptors']} descriptors) to "
        f"{args.dest}: {len(manifest['files'])} files, {size / 1e6:.1f} MB, checksums in "
        f"{MANIFEST}."
        + (
            f" Left out (deleted meanwhile): {manifest['left_out']}."
            if manifest["left_out"]
            else ""
        )
    )
    return 0


def _restore(args: argparse.Namespace) -> int:
    from .backup import BackupError, restore

    settings = _settings(args)
    try:
        manifest = restore(Path(args.source), settings)
    except BackupError as exc:
        print(f"shapes restore: {exc}", file=sys.stderr)
        return 1
    print(
        f"Restored {manifest['meshes']} meshes (backed up {manifest['created_at']}) into "
        f"{settings.data_dir}; start the service on it."
    )
    return 0


def _add_backup_subcommands(sub: Any) -> None:
    """``shapes backup`` and ``shapes restore`` on the CLI's subparsers."""
    data_dir = "the service's data directory (default: SHAPES_DATA_DIR, else ./data)"
    command = sub.add_parser(
        "backup",
        help="copy a live gallery (database, uploads, index) to a new directory",
        description="Back up the embedded deployment while it runs: the SQLite database "
        "(online, SQLite's backup API), the uploaded files, the saved index and a manifest "
        "with checksums. PostgreSQL: use pg_dump.",
    )
    command.add_argument("dest", help="the backup directory to create")
    command.add_argument("--data-dir", help=data_dir)
    command.set_defaults(run=_backup)
    command = sub.add_parser(
        "restore",
        help="bring a backup back into an empty data directory",
        description="Check a backup's checksums and copy it into an empty data directory; "
        "then start the service on it.",
    )
    command.add_argument("source", help="a directory written by shapes backup")
    command.add_argument("--data-dir", help=data_dir)
    command.set_defaults(run=_restore)


if __name__ == "__main__":
    raise SystemExit(main())
