"""``soabench sweep occlusion``: occluder density as an experimental axis (paper §V on occlusion).

Each point is an ordinary run on the same scene with ``[parking] density = v`` parked cars per 100 m of parking lane
(:mod:`soabench.scenario.parking`); trial n of every point uses the same seeds (:mod:`soabench.seeding`), so the
points differ only in the parked cars. The report draws mean tracking delay, cardinality error and OSPA per birth
model against density, and tabulates the paired statistics of the main run (S-OA vs each baseline: trial wins /
ties / losses, card. and OSPA reductions, share of episodes with S-OA's delay <= the baseline's) per point.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from soabench.birth import LABEL
from soabench.errors import SoabenchError, require
from soabench.experiment.campaigns.families import config_families, family_heading, first_family_note
from soabench.experiment.reports.report import fmt, fmt_pct
from soabench.experiment.runs.files import read_json
from soabench.scenario import USER_NET_DEFAULTS, load_scenario, scene_folder
from soabench.scenario.config import MAX_PARKING_DENSITY
from soabench.scenario.network import read_net
from soabench.scenario.parking import parking_lanes

if TYPE_CHECKING:
    pass

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} to TOML")


def dump_toml(data: dict) -> str:
    """A scenario-shaped dict (sections of scalars and lists) as TOML text."""
    lines = []
    for section, table in data.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
        lines.append("")
    return "\n".join(lines)


def base_scenario(net: str, scenario: str | None) -> dict:
    """The scenario dict a sweep point starts from (the user's TOML, else the scene folder's own, else a user net's
    defaults), with ``[files]`` paths made absolute so the point's TOML may live anywhere."""

    path = Path(scenario) if scenario is not None else None
    if path is None:
        folder = scene_folder(net)
        path = folder / "scenario.toml" if folder is not None else None
    if path is None:
        return {k: dict(v) for k, v in USER_NET_DEFAULTS.items()}

    load_scenario(path)  # validates (one-line errors)
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    files = data.get("files", {})
    if "net" in files:
        files["net"] = str((path.parent / files["net"]).resolve())
    elif scene_folder(net) is not None:
        nets = sorted(scene_folder(net).glob("*.net.xml"))
        if len(nets) == 1:
            files["net"] = str(nets[0].resolve())
    if "polys" in files:
        files["polys"] = [str((path.parent / f).resolve()) for f in files["polys"]]
    if files:
        data["files"] = files
    return data


def write_point_scenarios(sweep_dir: Path, points: list[dict], net: str, scenario: str | None) -> None:
    """Write ``points/<name>.scenario.toml`` (base scenario + ``[parking] density``) and store its path per point."""
    base = base_scenario(net, scenario)
    (sweep_dir / "points").mkdir(parents=True, exist_ok=True)
    for p in points:
        data = {k: dict(v) for k, v in base.items()}
        data.setdefault("parking", {})["density"] = float(p["value"])
        path = sweep_dir / "points" / f"{p['name']}.scenario.toml"
        path.write_text(dump_toml(data), encoding="utf-8")
        p["scenario"] = str(path.resolve())


def occlusion_points(values, base_config: dict) -> list[dict]:
    """One point per density value (parked cars per 100 m of kerb), sorted, duplicates dropped."""

    vals = sorted({float(v) for v in values})
    for v in vals:
        require(
            0.0 <= v <= MAX_PARKING_DENSITY and math.isfinite(v),
            f"occlusion density {v!r} is out of range; allowed: parked cars per 100 m of kerb in [0, "
            f"{MAX_PARKING_DENSITY:g}]",
        )
    return [{"name": f"density_{v:05.2f}", "value": v, "config": base_config} for v in vals]


def check_parking_lanes(
    net_file: str,
    values,
    what: str = "sweep occlusion",
    fix: str = "give a network with parking lanes (every shipped scene has them) or only --values 0",
) -> None:
    """Refuse, before anything is written, densities above 0 on a network without parking lanes (parked cars stand
    only on parking lanes: :mod:`soabench.scenario.parking`); ``what`` names the command or axis in the message and
    ``fix`` says what to give instead."""

    above = [float(v) for v in values if float(v) > 0]
    if not above or parking_lanes(read_net(net_file)):
        return
    raise SoabenchError(
        f"{what}: network {Path(net_file).name!r} has no parking lanes, so density {above[0]:g} is "
        'impossible (parked cars stand on normal-edge lanes such as allow="custom1" that carry neither passenger '
        f"cars nor pedestrians); {fix}"
    )


def occlusion_report(sweep_dir: Path, meta: dict) -> tuple[dict, str]:
    """Delay, cardinality error and OSPA per model vs density, and S-OA's paired statistics per point, per filter
    family."""
    families = config_families(meta["points"][0]["config"])
    summaries = [read_json(sweep_dir / "points" / p["name"] / "summary.json") for p in meta["points"]]
    exp = meta["points"][0]["config"]["experiment"]
    lines = [
        f"# Occlusion sweep: {meta.get('net_name')}",
        "",
        f"Parked cars per 100 m of parking lane vs tracking quality; λ = {float(exp['clutter'][0]):g}, "
        f"{exp['trials']} trials per point (same seeds at every point). "
        "Per-point details in `points/<name>/summary.md`.",
    ]
    rows, comps, first_rows = [], [], None
    for family in families:
        named = {} if family is None else {"filter": family}
        fam_rows, fam_comps = [], []
        for p, s in zip(meta["points"], summaries, strict=True):
            res = [r for r in s["results"] if r.get("filter") == family][0]  # the first clutter rate
            fam_rows += [{"density": p["value"], "clutter": res["clutter"], **named, **m} for m in res["models"]]
            fam_comps += [{"density": p["value"], **named, **c} for c in res["vs_soa"]]
        lines += [*family_heading(family), *_occlusion_tables(fam_rows, fam_comps)]
        rows += fam_rows
        comps += fam_comps
        first_rows = fam_rows if first_rows is None else first_rows
    # imported when called: matplotlib would slow every start-up
    from soabench.figures.occlusion import occlusion_figure
    from soabench.figures.style import save_png

    figure = occlusion_figure(sweep_dir, meta["points"], first_rows or [], families[0])
    save_png(figure, sweep_dir / "sweep_occlusion.png")
    lines += [
        "",
        f"Figure: `sweep_occlusion.png`{first_family_note(families)} (mean over trials, error bars: 95% confidence "
        "interval over trials)",
    ]
    return {"kind": "occlusion", "table": rows, "vs_soa": comps}, "\n".join(lines) + "\n"


def _occlusion_tables(rows: list[dict], comps: list[dict]) -> list[str]:
    """The occlusion sweep's two tables (one filter family): the metrics per point and S-OA's paired statistics."""
    lines = [
        "",
        "| parked / 100 m | model | mode | k̄ delay (s) | card. error | OSPA (m) | precision | recall |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['density']:g} | {LABEL.get(r['model'], r['model'])} | {r['mode']} | {fmt(r['delay_mean'])} "
            f"| {fmt(r['card_err_mean'])} | {fmt(r['ospa_mean'])} | {fmt(r['precision_mean'])} "
            f"| {fmt(r['recall_mean'])} |"
        )
    if comps:
        lines += [
            "",
            "Paired S-OA vs baseline (per trial: wins / ties / losses / n/a on mean delay; reductions of the means; "
            "share of episodes with delay_S-OA <= delay_X):",
            "",
            "| parked / 100 m | mode | baseline | W / T / L / n/a | card. reduction | OSPA reduction | episodes <= |",
            "|---|---|---|---|---|---|---|",
        ]
        for c in comps:
            frac = c["episode_le_fraction"]
            lines.append(
                f"| {c['density']:g} | {c['mode']} | {LABEL.get(c['baseline'], c['baseline'])} "
                f"| {c['wins']} / {c['ties']} / {c['losses']} / {c['na']} | {fmt_pct(c['card_reduction'])} "
                f"| {fmt_pct(c['ospa_reduction'])} | {fmt_pct(100 * frac if math.isfinite(frac) else frac)} |"
            )
    return lines
