"""The record of failed plugin runs in a run folder: ``model_failures.csv``, ``summary.json`` and the summary table.

A plugin run that failed (:mod:`soabench.experiment.trial.guard`, :mod:`soabench.experiment.trial.isolate`) has no row
in
trials.csv, episodes.csv or steps.csv; the trial record keeps it under ``model_failures`` (with the plugin's
traceback), this module lists every such run, and a command whose runs include one exits with status 1
(docs/user-guide/commands.md, "Exit status").
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from soabench.experiment.runs.files import write_csv
from soabench.experiment.trial.guard import FAILURE_KEYS


def write_model_failures(run_dir: Path, failures: list[dict], summary: dict) -> str:
    """Record failed plugin runs: ``model_failures.csv``, ``summary["model_failures"]``; return the Markdown table.

    Always writes the CSV (header only when nothing failed) so a reader can rely on it; the Markdown is empty
    when nothing failed.
    """
    failures = [{k: f.get(k) for k in FAILURE_KEYS} for f in failures]  # the tracebacks stay in the trial records
    write_csv(Path(run_dir) / "model_failures.csv", failures, FAILURE_KEYS)
    summary["model_failures"] = failures
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


def outcome_model_failures(outcome: Any) -> list[dict]:
    """Every failed method run of a run, sweep or study outcome (its points, its parts), in order."""
    out = list(getattr(outcome, "model_failures", None) or ())
    for part in ("main", "clutter", "births"):
        if getattr(outcome, part, None) is not None:
            out += outcome_model_failures(getattr(outcome, part))
    for part in ("points", "sensitivity"):
        for sub in getattr(outcome, part, None) or ():
            out += outcome_model_failures(sub)
    return out


def failed_methods_line(failures: list[dict]) -> str:
    """One line naming each method that failed and in how many runs and trials ("" when none failed)."""
    if not failures:
        return ""
    per: dict[str, tuple[int, set]] = {}
    for f in failures:
        runs, trials = per.get(f["model"], (0, set()))
        per[f["model"]] = (runs + 1, trials | {f["trial"]})
    parts = [f"{m!r} in {runs} run(s) of {len(trials)} trial(s)" for m, (runs, trials) in per.items()]
    return (
        f"{len(failures)} method run(s) failed and have no row: {', '.join(parts)}; the list is model_failures.csv, "
        "each traceback is in trials/trial_NNNNN.json (exit status 1)"
    )
