"""Command line: ``shapes describe MESH...`` (and ``shapes evaluate``, see worker.evaluate)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .errors import MeshError
from .pipeline import describe_file
from .presets import DEFAULT_PRESET, PRESETS, get_preset


def _describe(args: argparse.Namespace) -> int:
    preset = get_preset(args.preset)
    failures = 0
    for path in args.meshes:
        try:
            descriptor = describe_file(path, preset)
        except (MeshError, OSError) as exc:
            failures += 1
            print(f"{path}: {getattr(exc, 'message', exc)}", file=sys.stderr)
            continue
        if args.out:
            out_dir = Path(args.out)
            out_dir.mkdir(parents=True, exist_ok=True)
            stem = Path(path).name.split(".")[0]
            if args.format == "npz":
                (out_dir / f"{stem}.npz").write_bytes(descriptor.to_npz_bytes())
            else:
                (out_dir / f"{stem}.json").write_text(json.dumps(descriptor.to_json()))
        timings = " ".join(f"{k}={v:.3f}s" for k, v in descriptor.timings.items())
        summary = {"file": str(path), "vertices": descriptor.vertices, "timings": timings}
        if not args.out:
            summary["descriptor"] = descriptor.to_json()
        print(json.dumps(summary))
    return 1 if failures else 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="shapes", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    describe = sub.add_parser("describe", help="compute GDM/DDT modal descriptors of meshes")
    describe.add_argument(
        "meshes", nargs="+", help="mesh files (.obj .ply .off .stl .glb .gltf, optionally .gz)"
    )
    describe.add_argument("--preset", default=DEFAULT_PRESET, choices=sorted(PRESETS))
    describe.add_argument("--out", help="directory to save descriptors in (default: print JSON)")
    describe.add_argument("--format", choices=("json", "npz"), default="json")
    describe.set_defaults(run=_describe)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    raise SystemExit(main())
