"""``soabench study``: the paper's whole simulation study (main protocol, clutter sweep, N_hat sweep, sensitivity,
comparison with the paper) in one folder."""

from __future__ import annotations

import argparse

from soabench.cli import checks, common
from soabench.cli.parsing import add_filters_arg, add_run_args
from soabench.errors import require


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "study",
        help="the paper's whole simulation study: main protocol, clutter sweep, N_hat sweep, sensitivity, comparison",
    )
    add_run_args(p)
    add_filters_arg(p)
    p.add_argument("--sweep-trials", type=int, help="trials of the clutter sweep (default: --trials)")
    p.add_argument("--births-trials", type=int, default=30, help="trials per point of the N_hat sweep (default 30)")
    p.add_argument(
        "--sensitivity-trials", type=int, help="trials of each sensitivity run (default: the main run's trials)"
    )
    p.add_argument(
        "--all-figures",
        action="store_true",
        help="also draw the figures of the N_hat sweep's points and of the sensitivity runs (default: "
        "births/sweep_births.png and sensitivity/sensitivity.md summarise them)",
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.campaigns import study

    options = common.run_options(args, True if args.all_figures else None)
    study.check_part_trials(args.sweep_trials, args.births_trials, args.sensitivity_trials)
    require(args.probabilities is None, "`study` runs the paper's probability modes")
    for flag, value in (("--poly", args.poly[0] if args.poly else None), ("--scenario", args.scenario)):
        require(value is None, f"{flag} {value!r} is not offered by `study`: give a scene folder with --net")
    extra = tuple(args.models or ())  # plugins ride along with the built-in six (--trackers too)
    args.models = None
    cfg = study.with_plugin_models(common.config_from_args(args), extra)
    explicit = getattr(args, "explicit", set())
    parts = ("sweep_trials", "births_trials", "sensitivity_trials")
    keys = checks.requested_keys(args, explicit) | {k for k in parts if k in explicit}
    trials = study.PartTrials(args.sweep_trials, args.births_trials, args.sensitivity_trials)
    request = study.StudyRequest(cfg, args.net, args.out, trials, options, frozenset(keys))
    outcome = study.study(request)
    return common.report_outcome(outcome, "soabench study --out {dir}")
