"""The shipped scene suite: ``soabench scenes`` (a table) and ``--net all`` (any command on every shipped scene)."""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path

from soabench.errors import SoabenchError, require
from soabench.scenario import load, shipped_nets
from soabench.scenario.network import read_net

SNAPSHOT_COMMANDS = ("scene", "record", "birth")


def scene_rows() -> list[dict]:
    """One row per shipped scene: name, world-box size, vehicle lanes, pedestrians, occluders, what it tests."""

    rows = []
    for name in shipped_nets():
        scene, cfg = load(name, quiet=True)
        x0, y0, x1, y1 = scene.bounds

        net = read_net(cfg.net_file)
        from shapely.geometry import LineString

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


def run_on_all(args, command: Callable, command_name: str) -> int:
    """Run ``command(args)`` once per shipped scene (``--net all``); outputs go per scene; report per scene."""

    require(getattr(args, "resume", None) is None, "--net all cannot --resume; resume each scene's folder")
    names = shipped_nets()
    status: list[tuple[str, str]] = []
    rc_all = 0
    for name in names:
        a = copy.copy(args)
        a.net = name
        out = getattr(args, "out", None)
        if out is not None:
            p = Path(out)
            a.out = p.with_name(f"{p.stem}_{name}{p.suffix}") if command_name in SNAPSHOT_COMMANDS else p / name
            a.out = str(a.out) if command_name in SNAPSHOT_COMMANDS else a.out
        print(f"== {name} ==", flush=True)
        try:
            rc = command(a)
            status.append((name, "ok" if rc == 0 else f"exit {rc}"))
        except SoabenchError as exc:
            rc = 2
            status.append((name, f"error: {exc}"))
        rc_all = max(rc_all, rc)
    print("\n".join(["", "| scene | result |", "|---|---|"] + [f"| {n} | {s} |" for n, s in status]))
    return rc_all
