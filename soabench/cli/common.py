"""What the protocol commands (run, sweep, study) share: the configuration from ``--config`` and the flags, the
executor options, what a resume asked for, and the closing lines of an outcome (docs/user-guide/commands.md)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

from soabench import plugins
from soabench.cli import checks
from soabench.config import Config, load_config
from soabench.experiment.execution.options import RunOptions


def allow_typed_plugins(args: argparse.Namespace) -> None:
    """The ``module:Class`` names typed with --models/--trackers join this run's closed list (soabench.plugins)."""
    plugins.allow_import_paths([*(getattr(args, "models", None) or ()), *(getattr(args, "trackers", None) or ())])


def config_from_args(args: argparse.Namespace) -> Config:
    """The config file (if any) overlaid by the command-line flags, validated together (a family's section in the
    file is read when a flag names the family)."""
    allow_typed_plugins(args)
    cfg = load_config(getattr(args, "config", None), validate=False)
    overrides = {dest: getattr(args, dest, None) for dest in checks.FLAG_KEYS}
    flagged = dataclasses.replace(cfg.experiment, **{k: v for k, v in overrides.items() if v is not None})
    # the file's own values are checked as written, with the filter families the flags name
    dataclasses.replace(cfg, experiment=dataclasses.replace(cfg.experiment, filters=flagged.filters)).validate()
    cfg.experiment = flagged
    return cfg.validate()


def requested(args: argparse.Namespace, cfg: Config) -> dict:
    """What a resume asked for explicitly (flags, config file keys, net/poly/scenario), for the conflict check."""
    explicit = getattr(args, "explicit", set())
    return checks.requested_values(cfg, checks.requested_keys(args, explicit), args, explicit)


def run_options(args: argparse.Namespace, figures: bool | None = None) -> RunOptions:
    """The run options of ``run``, ``sweep`` and ``study`` (``figures``: None, each folder's default), checked."""
    return RunOptions(
        workers=args.workers,
        scheduler=args.scheduler,
        dask_local=args.dask == "local",
        fail_fast=args.fail_fast,
        save_estimates=args.save_estimates,
        progress=not args.no_progress,
        figures=figures,
    ).validate()


def run_answer(run_dir) -> list[str]:
    """The short answer a finished run ends with: its headline as a text table (per clutter rate and family), the
    full tables' file and the page to open."""
    from soabench.experiment.reports.headline import render_text
    from soabench.experiment.reports.html import REPORT_FILE, headlines
    from soabench.experiment.reports.tables import load_tables

    summary = json.loads((run_dir / "summary.json").read_text(encoding="utf-8"))
    warned = {(float(r["clutter"]), r.get("filter")) for r in summary.get("results", []) if r.get("warning")}
    lines = []
    for head in headlines(load_tables(run_dir)):
        if (head.clutter, head.family) in warned:  # nothing was observed: the warning above says why
            lines.append(f"λ = {head.clutter:g}: no comparison (no pedestrian was observed; see the warning)")
        else:
            lines += render_text(head)
    lines.append(f"every table: {run_dir / 'summary.md'}")
    if (run_dir / REPORT_FILE).is_file():
        lines.append(f"open {run_dir / REPORT_FILE}")
    return lines


def report_outcome(outcome, finish: str = "soabench run --resume {dir}", short: bool = False) -> int:
    """Print the summary (``short``: the run's headline and the page to open; else the summary's Markdown) and
    where the results are (0), or what is missing and how to finish (1)."""
    if getattr(outcome, "summary_markdown", None):
        answer = short and (outcome.run_dir / "summary.json").is_file()  # else the Markdown the run wrote
        print("\n".join(run_answer(outcome.run_dir)) if answer else outcome.summary_markdown)
    if outcome.complete:
        from soabench.experiment.runs.failures import failed_methods_line, outcome_model_failures

        if not short:
            print(f"results in {outcome.run_dir}")
        failed = failed_methods_line(outcome_model_failures(outcome))
        if failed:  # a requested method is missing from some tables: not a success (docs/user-guide/commands.md)
            print(f"soabench: {failed}", file=sys.stderr)
            return 1
        return 0
    print(
        f"run incomplete: {outcome.n_missing} trial(s) missing in {outcome.run_dir}; "
        f"finish with: {finish.format(dir=outcome.run_dir)}",
        file=sys.stderr,
    )
    return 1
