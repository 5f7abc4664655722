"""The paper-comparison statistics: win counts, reductions, Wilcoxon and bootstrap on constructed rows."""

from __future__ import annotations

import math

import numpy as np

from soabench.experiment.reports import paper


def _rows(n=40, seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for t in range(n):
        for m, mu in {"soa": 1.0, "pubm": 1.5, "ubm": 1.0, "ubm-ws": 2.0, "atbm": 0.4, "gmbm": 4.0}.items():
            rows.append(
                dict(
                    trial=t,
                    clutter=3.0,
                    model=m,
                    mode="static",
                    delay_mean=mu + rng.normal(0, 0.2),
                    delay_std=mu,
                    card_err=mu,
                    ospa=10 * mu,
                    precision=0.9,
                    mean_components=50 * mu,
                )
            )
    return rows


def test_wins_reductions_and_intervals():
    rows = _rows()
    comps = {(c.baseline, c.metric): c for c in paper.compare(rows)}
    assert comps[("gmbm", "wins")].ours == 40 and comps[("atbm", "wins")].ours == 0
    assert comps[("gmbm", "wins")].p_value < 1e-4
    assert 0 < comps[("ubm", "wins")].ours < 40  # equal means: a coin flip per trial
    assert comps[("ubm", "wins")].p_value > 0.01
    red = comps[("pubm", "card_err")]
    assert math.isclose(red.ours, 100 * (1.5 - 1.0) / 1.5)
    assert red.ci_low <= red.ours <= red.ci_high
    assert comps[("atbm", "ospa")].ours < 0  # S-OA worse than ATBM: reported as a negative reduction


def test_missing_delays_are_not_counted_as_wins():
    rows = _rows(10)
    for r in rows:
        if r["model"] == "pubm" and r["trial"] < 3:
            r["delay_mean"] = math.nan
    c = next(c for c in paper.compare(rows) if c.baseline == "pubm" and c.metric == "wins")
    assert c.n == 7 and c.ours <= 7


def test_markdown_has_every_baseline_and_sigma_bar():
    md = paper.markdown(_rows())
    for label in ("PUBM", "UBM (FOV)", "UBM (workspace)", "ATBM", "GMBM"):
        assert f"| {label} |" in md
    # the paper's UBM is the workspace grid: its numbers stand beside ubm-ws, the FOV variant has none
    assert "| without dyn. p | UBM (workspace) | 100 | 40 of 40 " in md
    assert "| without dyn. p | UBM (FOV) | - | " in md and "n/a / " not in md  # no paper number: "-" everywhere
    assert "1.65 / 1.00" in md  # paper sigma-bar of S-OA vs ours (delay_std = 1.0 in every trial)
    assert paper.component_ratios(_rows())[("static", "gmbm")] == 4.0


def test_resampled_sums_are_the_gathered_sums_bit_for_bit():
    """Whole numbers go through the resamples' draw counts (one product) and must equal the gather-and-sum of the
    draws bit for bit; other values (fractions, NaN, -0.0) are gathered, so they equal it trivially."""
    rng = np.random.default_rng(5)
    for n in (1, 2, 7, 20, 100, 137):
        idx = paper.resample_indices(n)
        assert idx.shape == (paper.N_BOOT, n) and not idx.flags.writeable
        assert paper.resample_counts(n).sum(axis=1).tolist() == [float(n)] * paper.N_BOOT
        cases = [
            rng.integers(0, 4, n).astype(float),  # counts of episodes
            rng.integers(0, 3000, n).astype(float) * (rng.random(n) < 0.2),  # mostly empty trials
            np.zeros(n),
            rng.random(n) * 7.3,  # delays (s): not whole, gathered
            np.where(rng.random(n) < 0.5, np.nan, 1.0),
            np.full(n, -0.0),
            np.where(np.arange(n) == 0, 2.0**52, 1.0),  # whole, but a resample's sum may pass 2^53: gathered
        ]
        for values in cases:
            want = values[idx].sum(axis=-1)
            got = paper.resampled_sums(values)
            assert got.tobytes() == want.tobytes(), (n, values[:5])
    # the product is what makes it fast: whole numbers must not be gathered
    whole = rng.integers(0, 5, 100).astype(float)
    assert paper.resample_counts(100) is paper.resample_counts(100)  # kept for the process
    assert paper.resampled_sums(whole).tobytes() == (paper.resample_counts(100) @ whole).tobytes()
    # beyond KEPT_TRIALS the resamples are drawn again, the same ones
    big = paper.KEPT_TRIALS + 1
    assert paper.resample_indices(big) is not paper.resample_indices(big)
    assert np.array_equal(paper.resample_indices(big), paper.resample_indices(big))
    values = rng.integers(0, 3, big).astype(float)
    assert paper.resampled_sums(values).tobytes() == values[paper.resample_indices(big)].sum(axis=-1).tobytes()
