"""The record of failed plugin runs in a run folder: ``model_failures.csv``, ``summary.json`` and the summary table.

A plugin run that failed (:mod:`soabench.experiment.guard`) has no row in trials.csv, episodes.csv or steps.csv;
the trial record keeps it under ``model_failures`` and this module lists every such run.
"""

from __future__ import annotations

from pathlib import Path

from soabench.experiment.files import write_csv
from soabench.experiment.guard import FAILURE_KEYS


def write_model_failures(run_dir: Path, failures: list[dict], summary: dict) -> str:
    """Record failed plugin runs: ``model_failures.csv``, ``summary["model_failures"]``; return the Markdown table.

    Always writes the CSV (header only when nothing failed) so a reader can rely on it; the Markdown is empty
    when nothing failed.
    """
    write_csv(Path(run_dir) / "model_failures.csv", failures, FAILURE_KEYS)
    summary["model_failures"] = [{k: f.get(k) for k in FAILURE_KEYS} for f in failures]
    if not failures:
        return ""
    lines = [
        "",
        f"## Failed model runs ({len(failures)})",
        "",
        "These runs have no row in any table; the model's statistics cover the trials where it ran.",
        "",
        "| trial | clutter | model | mode | scan | error |",
        "|---|---|---|---|---|---|",
    ]
    for f in failures:
        err = str(f.get("error", "")).replace("|", "\\|").replace("\n", " ")
        scan = "build" if int(f["k"]) < 0 else str(f["k"])
        lines.append(f"| {f['trial']} | {f['clutter']:g} | {f['model']} | {f['mode']} | {scan} | {err} |")
    return "\n".join(lines) + "\n"
