"""Buildings of a hand-built scene: the world box minus the paved area, as a SUMO polygon file.

The shipped scenes' ``build.sh`` scripts call this once each (``python3 -m soabench.scenario.blocks``): the paved area
is the union of sidewalks, crossings, walking areas and roads of the net (:func:`~soabench.scenario.network.
net_regions`), buffered by ``margin`` metres with mitre joins; every remaining piece of the world box larger than
``min_area`` is one building (``type="building"``, an occluder; docs/user-guide/scenes.md). Network coordinates must
equal world coordinates (netOffset 0,0).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import shapely
from shapely.geometry import Polygon, box

from soabench.scenario.network import net_regions, read_net


def building_blocks(
    net_file: str | Path, world_box: tuple[float, float, float, float], margin: float, min_area: float = 50.0
) -> list[Polygon]:
    """The pieces of ``world_box`` (x0, y0, x1, y1) off the paved area + ``margin`` m, ordered by centroid (x, y)."""
    r = net_regions(read_net(str(net_file)))
    paved = shapely.union_all([r["sidewalk"], r["crossings"], r["walking_areas"], r["roads"]])
    rest = box(*world_box).difference(paved.buffer(margin, join_style="mitre"))
    pieces = (g for g in getattr(rest, "geoms", [rest]) if g.area > min_area)
    return sorted(pieces, key=lambda g: (g.centroid.x, g.centroid.y))


def buildings_xml(blocks: Sequence[Polygon], comment: str) -> str:
    """A SUMO additional file with one ``building`` polygon per block (simplified to 5 cm, coordinates to 1 cm)."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', f"<!-- {comment} -->", "<additional>"]
    for i, b in enumerate(blocks):
        shape = " ".join(f"{x:.2f},{y:.2f}" for x, y in b.simplify(0.05).exterior.coords)
        attrs = f'id="building_{i}" type="building" color="255,200,0" fill="1" layer="-1" shape="{shape}"'
        lines.append(f"    <poly {attrs}/>")
    lines.append("</additional>")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m soabench.scenario.blocks", description=__doc__.splitlines()[0])
    p.add_argument("net", help="the scene's .net.xml")
    p.add_argument("--box", type=float, nargs=4, required=True, metavar=("X0", "Y0", "X1", "Y1"), help="world box (m)")
    p.add_argument("--margin", type=float, required=True, help="clearance from the paved area (m)")
    p.add_argument("--comment", required=True, help="the comment line of the written file")
    p.add_argument("--out", default="buildings.poly.xml", help="polygon file (default buildings.poly.xml)")
    args = p.parse_args(argv)
    blocks = building_blocks(args.net, tuple(args.box), args.margin)
    Path(args.out).write_text(buildings_xml(blocks, args.comment))
    print(f"wrote {args.out} with {len(blocks)} buildings")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
