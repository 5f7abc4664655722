"""The shipped scene suite: the table of ``soabench scenes`` (every shipped scene, what each holds and tests)."""

from __future__ import annotations

from shapely.geometry import LineString

from soabench import scenario as scenarios  # by attribute: a test may stand in for its load
from soabench.scenario import shipped_nets
from soabench.scenario.network import read_net


def scene_rows() -> list[dict]:
    """One row per shipped scene: name, world-box size, vehicle lanes, pedestrians, occluders, what it tests."""

    rows = []
    for name in shipped_nets():
        scene, cfg = scenarios.load(name, quiet=True)
        x0, y0, x1, y1 = scene.bounds

        net = read_net(cfg.net_file)

        lanes = sum(
            1
            for e in net.getEdges(withInternal=False)
            for ln in e.getLanes()
            if ln.allows("passenger")
            and e.getFunction() == ""
            and LineString(ln.getShape()).intersects(scene.world_box)
        )
        rows.append(
            {
                "name": name,
                "size": f"{x1 - x0:.0f} x {y1 - y0:.0f} m",
                "lanes": lanes,  # car lanes crossing the world box
                "pedestrians": cfg.n_pedestrians,
                "doors": len(scene.doors),
                "buildings": len(scene.buildings),
                "occluders": len(scene.static_occluders),
                "tests": cfg.description,
            }
        )
    return rows


def scenes_table() -> str:
    """The Markdown table of :func:`scene_rows`."""
    head = "| name | size | car lanes | pedestrians | doors | buildings | static occluders | what it tests |"
    lines = [head, "|---|---|---|---|---|---|---|---|"]
    for r in scene_rows():
        lines.append(
            f"| {r['name']} | {r['size']} | {r['lanes']} | {r['pedestrians']} | {r['doors']} | {r['buildings']} "
            f"| {r['occluders']} | {r['tests']} |"
        )
    return "\n".join(lines)
