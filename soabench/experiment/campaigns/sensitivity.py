"""Sensitivity of the headline numbers to the modelling choices: ``sensitivity.md`` and ``sensitivity.csv``.

The headline numbers are those of the paper comparison (docs/method.md §5.9, :mod:`soabench.experiment.reports.paper`):
S-OA's delay win counts against each baseline, every model's mean delay k̄ and σ̄, and S-OA's percent reduction of
the mean cardinality error and of the mean OSPA against each baseline, each in the static and the dynamic
probability mode. This module puts each of them side by side under the settings a reviewer asks about first, one
column per setting:

* ``default``: the main run, χ² gate on (``[filter] gate = true``, docs/method.md §2.8), truth = present ∩ FOV
  (``[metrics] gt_set = "fov"``, §5.1);
* ``gate_off``: the same protocol with ``[filter] gate = false``;
* ``visible``: the same protocol scored against line-of-sight visible pedestrians (``[metrics] gt_set =
  "visible"``);
* ``gate_off_visible`` (optional): both.

The probability mode is a row of its own (both modes are in every run). Each row gets ONE sentence generated from
its numbers: which switch (gate, truth set, or the probability mode, whose value is the other mode's row under the
default setting) moves it most, from what to what, whether a sign flips (S-OA turning from better to worse than a
baseline, or its win count crossing half of the trials compared), and which switches leave it unchanged. A number
is "unchanged" when it prints the same at the table's precision.

Why the switches move what they move (checked with short runs on the shipped intersection: 3 trials x 40 s, six
models, both modes, one run per setting; larger gate numbers in docs/method.md §2.8):

* **Truth set.** ``gt_set`` is a scoring option only: the visible-truth run's filters are the default run's (same
  seeds, same posteriors). :func:`write_sensitivity` checks this on every table it writes (per-trial posterior
  component counts of the two runs) and says so in ``sensitivity.md``. Visible truth drops the occluded
  pedestrians from GT_k: in the check runs S-OA's misses fell from 67 to 18 per trial and its cardinality error
  from 1.66 to 0.48, while ATBM's fell only from 1.78 to 1.73. ATBM extracts many false tracks (68 per trial
  against S-OA's 2): under the default truth they partly cancel the under-count that every model has with
  occluded pedestrians in the truth, under visible truth they are plain errors. So S-OA's reductions against
  ATBM (and GMBM) grow most. An estimate that the default truth matched to an occluded pedestrian now counts as
  false (a few per trial for PUBM, UBM, ATBM). The delays move little: delay episodes follow the visible runs of
  each target whatever the truth set (docs/method.md §5.4); only the matching changes, since an estimate no longer
  matched to an occluded pedestrian may now initiate a visible one (none moved in the 3-trial check runs; on 30
  trials, static, S-OA's k̄ went from 1.171 s to 1.165 s with identical posteriors).
* **Gate.** Without the χ² gate every component takes part in every update. In the check runs this changed the
  component counts and OSPA of every model slightly, but the extracted estimates (delays, cardinality error,
  TP/FP/FN) only of GMBM: its birth components sit at fixed doors and boundary exits, far from most measurements;
  a measurement outside every gate is ignored by the gated filter, while the ungated one lets a faraway
  component take a small but decisive weight (docs/method.md §2.8).
* **Probability mode.** The dynamic mode (docs/method.md §4.2) moved the mean delays by at most 0.07 s in the
  check runs (S-OA 1.169 s -> 1.099 s); it is a row of the table, not a column, because every run has both modes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from soabench.atomic import write_text_atomic
from soabench.birth import BASELINES, LABEL
from soabench.experiment.campaigns.families import paper_family_rows
from soabench.experiment.reports import paper
from soabench.experiment.runs.files import write_csv

#: settings in column order: key -> column header
SETTINGS: dict[str, str] = {
    "default": "default (gate on, truth present ∩ FOV)",
    "gate_off": "gate off",
    "visible": "visible truth",
    "gate_off_visible": "gate off + visible truth",
}
#: how a setting is named inside a sentence
SETTING_PHRASE = {
    "gate_off": "the gate off",
    "visible": "visible truth",
    "gate_off_visible": "the gate off with visible truth",
}
#: the config change that makes each variant (what the study part runs)
SETTING_CHANGE = {
    "gate_off": ("filter", "gate", False),
    "visible": ("metrics", "gt_set", "visible"),
}
MODES = ("static", "dynamic")
OTHER_MODE = {"static": "dynamic", "dynamic": "static"}

#: the kinds of headline number: key -> (title, unit shown after a value, decimals)
KINDS: dict[str, tuple[str, str, int]] = {
    "wins": ("Trials in which S-OA has the lower mean delay (wins / trials compared)", "", 0),
    "delay": ("Mean delay k̄ (s): mean over trials of the per-trial mean delay", " s", 3),
    "sigma": ("σ̄ (s): mean over trials of the per-trial delay standard deviation", " s", 3),
    "card_err": ("S-OA's percent reduction of the mean absolute cardinality error", "%", 2),
    "ospa": ("S-OA's percent reduction of the mean OSPA (c = 100, p = 1)", "%", 2),
}


@dataclass
class Value:
    """One headline number under one setting; ``n`` is the number of trials it compares or averages."""

    value: float
    n: int

    def text(self, kind: str) -> str:
        if not math.isfinite(self.value):
            return "n/a"
        if kind == "wins":
            return f"{self.value:.0f}/{self.n}"
        _, unit, nd = KINDS[kind]
        return f"{round(self.value, nd) + 0.0:.{nd}f}{unit}"  # + 0.0: no "-0.00"

    def sign(self, kind: str) -> int:
        """+1 where S-OA is ahead (positive reduction, wins in more than half the trials), -1 behind, 0 level."""
        if not math.isfinite(self.value) or kind in ("delay", "sigma"):
            return 0
        x = self.value - self.n / 2 if kind == "wins" else float(self.text(kind).rstrip("%"))
        return int(np.sign(x))

    def scaled(self, kind: str) -> float:
        """The value on a scale where changes of different settings compare (win counts as fractions)."""
        return self.value / self.n if kind == "wins" and self.n else self.value


@dataclass
class Row:
    """One headline number (kind, model, mode) under every setting, with its generated sentence."""

    kind: str
    model: str
    mode: str
    values: dict[str, Value]
    sentence: str = ""
    extra: dict[str, Value] = field(default_factory=dict)  # the other probability mode, default setting

    @property
    def name(self) -> str:
        what = {"wins": "wins vs", "delay": "k̄", "sigma": "σ̄", "card_err": "card. error vs", "ospa": "OSPA vs"}
        return f"{what[self.kind]} {LABEL.get(self.model, self.model)}, {self.mode}"


def _mean(rows: Sequence[dict], metric: str, model: str, mode: str, clutter: float) -> Value:
    v = np.array(
        [
            float(r[metric])
            for r in rows
            if r["mode"] == mode and r["model"] == model and float(r["clutter"]) == float(clutter)
        ]
    )
    v = v[np.isfinite(v)]
    return Value(float(v.mean()) if len(v) else math.nan, len(v))


def headline_numbers(rows: Sequence[dict], clutter: float = paper.PAPER_CLUTTER) -> dict[tuple[str, str, str], Value]:
    """Every headline number the rows allow: (kind, model, mode) -> Value (see :data:`KINDS`)."""
    out: dict[tuple[str, str, str], Value] = {}
    models = {r["model"] for r in rows}
    modes = [m for m in MODES if any(r["mode"] == m for r in rows)]
    for mode in modes:
        for model in [m for m in ("soa", *BASELINES) if m in models]:
            out[("delay", model, mode)] = _mean(rows, "delay_mean", model, mode, clutter)
            out[("sigma", model, mode)] = _mean(rows, "delay_std", model, mode, clutter)
        if "soa" not in models:
            continue
        for base in [b for b in BASELINES if b in models]:
            s, b = paper.paired(rows, "delay_mean", "soa", base, mode, clutter)
            ok = np.isfinite(s) & np.isfinite(b)
            n = int(ok.sum())  # no trial with a counted episode for both: no win count (n/a, not 0/0)
            out[("wins", base, mode)] = Value(float(np.sum(s[ok] < b[ok])) if n else math.nan, n)
            for metric in ("card_err", "ospa"):
                s, b = paper.paired(rows, metric, "soa", base, mode, clutter)
                ok = np.isfinite(s) & np.isfinite(b)
                red = paper.percent_reduction(np.mean(b[ok]), np.mean(s[ok])) if ok.any() else math.nan
                out[(metric, base, mode)] = Value(float(red), int(ok.sum()))
    return out


def describe(row: Row) -> str:
    """The row's one sentence: which switch moves the number most, from what to what, flips, unchanged ones."""
    kind = row.kind
    base = row.values.get("default")
    if base is None or not math.isfinite(base.value):
        return "No value under the default setting."
    cands = {SETTING_PHRASE[k]: v for k, v in row.values.items() if k != "default"}
    cands.update(row.extra)
    cands = {k: v for k, v in cands.items() if math.isfinite(v.value)}
    t0 = base.text(kind)
    moved = {k: v for k, v in cands.items() if v.text(kind) != t0}
    same = [k for k in cands if k not in moved]
    if not moved:
        tail = f" ({', '.join(same)})" if same else ""
        return f"Unchanged at {t0} under every switch{tail}."
    ranked = sorted(moved.items(), key=lambda kv: -abs(kv[1].scaled(kind) - base.scaled(kind)))
    top, tv = ranked[0]
    s = f"{top[0].upper()}{top[1:]} moves it most, from {t0} to {tv.text(kind)}"
    flips = [k for k, v in moved.items() if v.sign(kind) * base.sign(kind) < 0]
    if top in flips:
        s += ": " + _flip(kind, row.model, base, tv)
    others = [f"{k} {v.text(kind)}" for k, v in ranked[1:]]
    if others:
        s += "; " + ", ".join(others)
    if same:
        s += "; unchanged with " + " and ".join(same)
    more = [k for k in flips if k != top]
    if more:
        s += "; the sign also flips with " + " and ".join(more)
    return s + "."


def _flip(kind: str, model: str, base: Value, to: Value) -> str:
    if kind == "wins":
        return "S-OA's majority flips (it " + ("now loses" if to.sign(kind) < 0 else "now wins") + " most trials)"
    return (
        f"the sign flips (S-OA turns from {'better' if base.sign(kind) > 0 else 'worse'} to "
        f"{'better' if to.sign(kind) > 0 else 'worse'} than {LABEL.get(model, model)})"
    )


def build_rows(runs: Mapping[str, Sequence[dict]], clutter: float = paper.PAPER_CLUTTER) -> list[Row]:
    """The sensitivity rows from each setting's trials.csv rows (``runs["default"]`` is required)."""
    numbers = {k: headline_numbers(rows, clutter) for k, rows in runs.items()}
    settings = [k for k in SETTINGS if k in runs]
    out = []
    for kind in KINDS:
        keys = [k for k in numbers["default"] if k[0] == kind]
        keys.sort(key=lambda k: (MODES.index(k[2]), ("soa", *BASELINES).index(k[1])))
        for key in keys:
            _, model, mode = key
            values = {s: numbers[s].get(key, Value(math.nan, 0)) for s in settings}
            row = Row(kind, model, mode, values)
            other = numbers["default"].get((kind, model, OTHER_MODE[mode]))
            if other is not None:
                row.extra = {f"{OTHER_MODE[mode]} p": other}
            row.sentence = describe(row)
            out.append(row)
    return out


def common_trials(runs: Mapping[str, Sequence[dict]]) -> tuple[list[int], dict[str, list[dict]]]:
    """Trial indices every setting has, and each setting's rows restricted to them (so the columns pair)."""
    common = set.intersection(*({int(r["trial"]) for r in rows} for rows in runs.values()))
    return sorted(common), {k: [r for r in rows if int(r["trial"]) in common] for k, rows in runs.items()}


#: trials.csv columns that describe the filter's posteriors, not their scoring
FILTER_COLUMNS = ("mean_components", "max_components", "mean_predicted", "mean_updated")


def same_filter_output(a: Sequence[dict], b: Sequence[dict]) -> bool | None:
    """Whether two runs' filters produced the same posteriors (equal :data:`FILTER_COLUMNS` per trial x model x
    mode x clutter that both hold); None when they share no such row or column."""
    cols = [c for c in FILTER_COLUMNS if a and b and c in a[0] and c in b[0]]
    if not cols:
        return None

    def key(rows):
        return {(int(r["trial"]), r["model"], r["mode"], float(r["clutter"])): tuple(r[c] for c in cols) for r in rows}

    ka, kb = key(a), key(b)
    common = ka.keys() & kb.keys()  # a variant may hold fewer models or modes
    return all(ka[k] == kb[k] for k in common) if common else None


def to_markdown(rows: Sequence[Row], settings: Sequence[str], header: str) -> str:
    lines = [header]
    for kind, (title, _, _) in KINDS.items():
        krows = [r for r in rows if r.kind == kind]
        if not krows:
            continue
        lines += ["", f"## {title}", ""]
        lines.append("| number | " + " | ".join(SETTINGS[s] for s in settings) + " | what moves it |")
        lines.append("|---|" + "---:|" * len(settings) + "---|")
        for r in krows:
            cells = [r.values[s].text(kind) for s in settings]
            lines.append(f"| {r.name} | " + " | ".join(cells) + f" | {r.sentence} |")
    return "\n".join(lines) + "\n"


def csv_rows(rows: Sequence[Row], settings: Sequence[str]) -> tuple[list[dict], list[str]]:
    cols = ["number", "kind", "model", "mode", *settings, *(f"{s}_n" for s in settings), "sentence"]
    out = []
    for r in rows:
        d = {"number": r.name, "kind": r.kind, "model": r.model, "mode": r.mode, "sentence": r.sentence}
        for s in settings:
            d[s] = r.values[s].value
            d[f"{s}_n"] = r.values[s].n
        out.append(d)
    return out, cols


def write_sensitivity(
    out_dir: Path, main_dir: Path, variants: Mapping[str, Path], clutter: float = paper.PAPER_CLUTTER
) -> str:
    """Write ``sensitivity.md`` and ``sensitivity.csv`` in ``out_dir`` from the main run and the variant runs.

    ``variants``: setting key (``gate_off``, ``visible``, ``gate_off_visible``) -> finished run folder. Every
    setting is restricted to the trials all of them have, so the columns compare the same trials.
    """
    unknown = sorted(set(variants) - set(SETTINGS) - {"default"})
    if unknown:
        raise ValueError(f"unknown sensitivity setting(s) {unknown}; choose from {sorted(SETTING_PHRASE)}")
    out_dir = Path(out_dir)
    # a run of several filter families: the paper's headline numbers, in its family
    runs = {"default": paper_family_rows(paper.read_rows(Path(main_dir) / "trials.csv"))}
    runs.update({k: paper_family_rows(paper.read_rows(Path(d) / "trials.csv")) for k, d in variants.items()})
    trials, runs = common_trials(runs)
    settings = [s for s in SETTINGS if s in runs]
    rows = build_rows(runs, clutter)
    header = [
        "# Sensitivity of the headline numbers to the gate, the truth set and the probability mode",
        "",
        f"Generated from `trials.csv` of the main run and of one run per setting; {len(trials)} "
        f"trial{'' if len(trials) == 1 else 's'} common to every setting (same seeds), clutter λ = {clutter:g}. "
        "Columns: "
        + "; ".join(f"**{SETTINGS[s]}**" for s in settings)
        + ". The probability mode is in each row's name; the sentence also weighs the other mode's value under the "
        "default setting. A number is unchanged when it prints the same. Why the switches move what they move: "
        "`docs/user-guide/outputs.md` (the sensitivity table).",
    ]
    if "visible" in runs:
        same = same_filter_output(runs["default"], runs["visible"])
        if same is None:
            check = "the rows hold no component counts, so that the filters are the default run's is not checked."
        elif same:
            check = (
                "the visible-truth run's filters are the default run's (posterior component counts agree on every "
                "trial, model and mode both runs hold), so every change in that column comes from the truth set."
            )
        else:
            check = (
                "**the visible-truth run's posterior component counts differ from the default run's**, so its "
                "column mixes a filter change with the truth-set change (were the runs made with the same code?)."
            )
        header += ["", "Visible truth is a scoring change only: " + check]
    md = to_markdown(rows, settings, "\n".join(header))
    table, cols = csv_rows(rows, settings)
    write_csv(out_dir / "sensitivity.csv", table, cols)
    write_text_atomic(out_dir / "sensitivity.md", md)
    return md
