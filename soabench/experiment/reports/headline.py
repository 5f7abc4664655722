"""A run's headline: who wins each metric, S-OA's paired differences with their intervals, and the trade-offs
(docs/method.md §5.8).

For every metric, probability mode and model X paired with S-OA, the per-trial differences d_n = M_n(S-OA) - M_n(X)
over the trials where both values are finite give the mean difference and its 95 % Student-t interval
d̄ ± t_{0.975, n-1} s_d / √n, and the win count: the trials in which S-OA is better (lower delay, error or distance;
higher precision, recall or HOTA), with ties and losses apart. The delay's win count is the summary's "S-OA lower k̄".

The winner of a metric is the model with the best mean over trials; a trade-off is one sentence per model that wins
some metric while being among the worse half on another. Everything is computed from ``trials.csv`` alone (the
:class:`~soabench.experiment.reports.tables.RunTables` of a run), so the report page, the run's closing table and
the key figure say the same thing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import t as student_t

from soabench.birth import BASELINES, LABEL
from soabench.experiment.reports.tables import RunTables, select

LEVEL = 0.95


@dataclass(frozen=True)
class Metric:
    """One per-trial column of ``trials.csv`` the headline compares."""

    key: str
    label: str
    unit: str
    lower_is_better: bool
    digits: int = 3

    def better(self, a: float, b: float) -> bool:
        """``a`` is strictly better than ``b``."""
        return a < b if self.lower_is_better else a > b

    def show(self, x: float, signed: bool = False) -> str:
        """``x`` at this metric's precision ('n/a' when not finite)."""
        if x is None or not math.isfinite(x):
            return "n/a"
        return f"{x:+.{self.digits}f}" if signed else f"{x:.{self.digits}f}"


#: the metrics of the headline, in the order the page and the forest plot show them (method §5.2-5.6, §9.3)
METRICS = (
    Metric("delay_mean", "tracking delay k̄", "s", True),
    Metric("card_err", "cardinality error", "targets", True),
    Metric("ospa", "OSPA", "m", True, 2),
    Metric("gospa", "GOSPA", "m", True, 2),
    Metric("precision", "precision", "", False),
    Metric("recall", "recall", "", False),
    Metric("hota", "HOTA", "", False),
)


#: the metrics of the short answers (a run's closing table, the README's key figure): the paper's delay,
#: cardinality error and OSPA, and precision, which a fast birth model may trade
KEY_METRICS = ("delay_mean", "card_err", "ospa", "precision")


@dataclass(frozen=True)
class Paired:
    """S-OA against model ``other`` on one metric in one mode: the mean paired difference S-OA - X and its interval,
    and the trials in which S-OA is better, equal or worse."""

    metric: str
    mode: str
    other: str
    n: int
    diff: float
    low: float
    high: float
    wins: int
    ties: int
    losses: int

    @property
    def settled(self) -> bool:
        """The interval excludes 0: the sign of the difference holds at the 95 % level."""
        return math.isfinite(self.low) and (self.low > 0 or self.high < 0)


@dataclass(frozen=True)
class Leader:
    """The model with the best mean on one metric in one mode, and every model's mean."""

    metric: str
    mode: str
    model: str
    means: dict[str, float]


@dataclass(frozen=True)
class Headline:
    """A run's headline at one clutter rate (and filter family, None for a run of one family)."""

    clutter: float
    family: str | None
    metrics: tuple[Metric, ...]
    modes: tuple[str, ...]
    models: tuple[str, ...]
    leaders: tuple[Leader, ...]
    paired: tuple[Paired, ...]
    tradeoffs: tuple[str, ...]

    def leader(self, metric: str, mode: str) -> Leader | None:
        return next((w for w in self.leaders if w.metric == metric and w.mode == mode), None)

    def pair(self, metric: str, mode: str, other: str) -> Paired | None:
        return next((p for p in self.paired if (p.metric, p.mode, p.other) == (metric, mode, other)), None)


def mean_interval(d: np.ndarray, level: float = LEVEL) -> tuple[float, float, float]:
    """Mean of ``d`` and its Student-t interval at ``level`` (NaN bounds for fewer than two values; a zero spread
    gives the mean as both bounds)."""
    d = np.asarray(d, dtype=float)
    if d.size == 0:
        return math.nan, math.nan, math.nan
    mean = float(d.mean())
    if d.size < 2:
        return mean, math.nan, math.nan
    half = float(student_t.ppf(0.5 + level / 2, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size))
    return mean, mean - half, mean + half


def _per_trial(trials: dict[str, np.ndarray], key: str, clutter: float, model: str, mode: str) -> dict[int, float]:
    m = select(trials, clutter=clutter, model=model, mode=mode)
    values = np.array([math.nan if v in ("", None) else float(v) for v in trials[key][m].tolist()], dtype=float)
    return dict(zip((int(n) for n in trials["trial"][m]), values.tolist(), strict=True))


def paired_difference(metric: Metric, soa: dict[int, float], other: dict[int, float], mode: str, name: str) -> Paired:
    """S-OA's per-trial values ``soa`` against ``other``'s (trial -> value) on ``metric``."""
    both = [n for n in sorted(set(soa) & set(other)) if math.isfinite(soa[n]) and math.isfinite(other[n])]
    a = np.array([soa[n] for n in both], dtype=float)
    b = np.array([other[n] for n in both], dtype=float)
    diff, low, high = mean_interval(a - b)
    wins = int(sum(metric.better(x, y) for x, y in zip(a, b, strict=True)))
    ties = int(np.sum(a == b))
    return Paired(metric.key, mode, name, len(both), diff, low, high, wins, ties, len(both) - wins - ties)


def _present(trials: dict[str, np.ndarray], metric: Metric, clutter: float) -> bool:
    """Whether ``metric`` has a finite value at ``clutter`` (an unlabelled run has an empty HOTA column)."""
    if metric.key not in trials:
        return False
    m = select(trials, clutter=clutter)
    return any(v not in ("", None) and math.isfinite(float(v)) for v in trials[metric.key][m].tolist())


def headline(tables: RunTables, clutter: float, family: str | None = None) -> Headline:
    """The headline of ``tables`` (one filter family's, see :func:`~soabench.experiment.reports.report.family_tables`)
    at ``clutter``."""
    trials = tables.trials
    metrics = tuple(m for m in METRICS if _present(trials, m, clutter))
    models, modes = tuple(tables.models), tuple(tables.modes)
    others = [b for b in BASELINES if b in models] + [m for m in models if m != "soa" and m not in BASELINES]
    leaders, paired = [], []
    for metric in metrics:
        for mode in modes:
            values = {mo: _per_trial(trials, metric.key, clutter, mo, mode) for mo in models}
            means = {mo: _finite_mean(v.values()) for mo, v in values.items()}
            ranked = [mo for mo in models if math.isfinite(means[mo])]
            if ranked:
                sign = 1.0 if metric.lower_is_better else -1.0
                best = min(ranked, key=lambda mo: (sign * means[mo], models.index(mo)))
                leaders.append(Leader(metric.key, mode, best, means))
            if "soa" in models:
                paired += [paired_difference(metric, values["soa"], values[o], mode, o) for o in others]
    head = Headline(clutter, family, metrics, modes, models, tuple(leaders), tuple(paired), ())
    return Headline(**{**head.__dict__, "tradeoffs": tuple(tradeoffs(head))})


def _finite_mean(values) -> float:
    v = np.array([x for x in values if math.isfinite(x)], dtype=float)
    return float(v.mean()) if v.size else math.nan


def tradeoffs(head: Headline) -> list[str]:
    """One sentence per model that leads on some metric while sitting in the worse half of the models on another
    (first mode only): what it buys and what it pays, with the best value of what it pays."""
    if not head.modes:
        return []
    mode = head.modes[0]
    by_key = {m.key: m for m in head.metrics}
    leads: dict[str, list[str]] = {}
    for w in head.leaders:
        if w.mode == mode:
            leads.setdefault(w.model, []).append(w.metric)
    out = []
    for model, won in leads.items():
        pays = []
        for w in head.leaders:
            if w.mode != mode or w.metric in won:
                continue
            metric = by_key[w.metric]
            ranked = sorted(
                (mo for mo in w.means if math.isfinite(w.means[mo])),
                key=lambda mo: w.means[mo] if metric.lower_is_better else -w.means[mo],
            )
            if model in ranked and ranked.index(model) >= (len(ranked) + 1) // 2:
                pays.append(
                    f"{metric.label} {metric.show(w.means[model])} against {metric.show(w.means[w.model])} "
                    f"({LABEL.get(w.model, w.model)}, the best)"
                )
        if pays:
            names = ", ".join(by_key[k].label for k in won)
            out.append(f"{LABEL.get(model, model)} leads on {names} ({mode}) but pays with {'; '.join(pays)}.")
    return out


#: short column names of the text table
_SHORT = {"delay_mean": "delay k̄", "card_err": "card. error"}


def _text_cell(p: Paired | None, metric: Metric) -> str:
    """``−0.149 ±0.026* 82/100``: the mean paired difference, the half-width of its interval (* where the interval
    excludes 0), the trials won."""
    if p is None or p.n == 0:
        return "n/a"
    half = f" ±{metric.show(p.diff - p.low)}" if math.isfinite(p.low) else ""
    mark = "*" if p.settled else " "
    return f"{metric.show(p.diff, signed=True)}{half}{mark} {p.wins}/{p.n}".replace("-", "−")


def _column(m: Metric) -> str:
    return _SHORT.get(m.key, m.label) + (f" ({m.unit})" if m.unit else "") + (" ↓" if m.lower_is_better else " ↑")


def render_text(head: Headline, metrics: Sequence[str] = KEY_METRICS) -> list[str]:
    """The headline as a short plain-text table (the end of ``soabench run``): per mode, the best model of each of
    ``metrics``, then one row per model X with S-OA − X, ± the half-width of its 95 % interval and the trials S-OA
    wins (* where the interval excludes 0), then the trade-offs."""
    chosen = [m for m in head.metrics if m.key in metrics]
    others = list(dict.fromkeys(p.other for p in head.paired))
    if not chosen:
        return []
    width = max([len("S-OA − X")] + [len(LABEL.get(o, o)) for o in others])
    cols = [_column(m) for m in chosen]
    lines = []
    for mode in head.modes:
        best = []
        for m in chosen:
            w = head.leader(m.key, mode)
            if w is not None:
                best.append(f"{_SHORT.get(m.key, m.label)} {LABEL.get(w.model, w.model)} {m.show(w.means[w.model])}")
        family = f", {head.family}" if head.family else ""
        lines += [f"λ = {head.clutter:g}, {mode}{family}; best: {', '.join(best)}"]
        if others:
            cells = [[_text_cell(head.pair(m.key, mode, o), m) for m in chosen] for o in others]
            widths = [max(len(c), *(len(r[i]) for r in cells)) for i, c in enumerate(cols)]
            for label, row in [("S-OA − X", cols), *((LABEL.get(o, o), r) for o, r in zip(others, cells, strict=True))]:
                padded = (f"{c:<{w}}" for c, w in zip(row, widths, strict=True))
                lines.append("  ".join([f"  {label:<{width}}", *padded]).rstrip())
    if any(p.n for p in head.paired):
        lines.append("(S-OA − X: mean over trials ± 95 % interval, * the interval excludes 0, then trials S-OA wins)")
    lines += head.tradeoffs
    return lines
