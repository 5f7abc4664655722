"""``soabench import osm``: an OpenStreetMap extract as a scene folder for ``--net`` (docs/user-guide/scenes.md)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="turn an OpenStreetMap extract into a scene folder for --net")
    p.add_argument("kind", choices=["osm"])
    p.add_argument("file", metavar="FILE.osm")
    p.add_argument("--out", required=True, help="scene folder to write (new or empty)")
    p.add_argument(
        "--force", action="store_true", help="import a file above the size limit (soabench/scenario/osm.py MAX_OSM_MB)"
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.scenario.osm import import_osm

    toml = import_osm(args.file, args.out, force=args.force)
    print(f"wrote scene folder {toml.parent} (use: soabench run --net {toml.parent})")
    return 0
