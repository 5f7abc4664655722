"""The Tracks table of the summary (soabench/tracks/report.py; docs/method.md §9.3, §9.4)."""

from __future__ import annotations

import math

import numpy as np

from soabench.tracks.evaluate import LABEL_KEYS, TRACK_KEYS
from soabench.tracks.report import ABSENT, render_tracks, track_stats, tracks_vs_soa

NAN = math.nan


def columns(rows: list[dict]) -> dict[str, np.ndarray]:
    """Per-trial columns as trials.csv reads back: a missing value (an unlabelled tracker's) is NaN."""
    return {key: np.array([r.get(key, NAN) for r in rows], dtype=float) for key in TRACK_KEYS}


def trial(hota, idf1, id_kept, n_id, coasted, n_gaps, labelled=True) -> dict:
    row = {
        "delay_entry_mean": 1.0, "delay_entry_std": 0.5, "n_entry": 4, "n_entry_censored": 1,
        "delay_reemergence_mean": 2.0, "delay_reemergence_std": 1.0, "n_reemergence": 2, "n_reemergence_censored": 0,
        "coasted": coasted, "n_gaps": n_gaps,
    }  # fmt: skip
    if labelled:
        row.update(dict.fromkeys(LABEL_KEYS, 0.5), hota=hota, idf1=idf1, idsw=3, id_kept=id_kept, n_id=n_id)
    return row


def test_stats_pool_fractions_over_items_and_absent_without_labels():
    t = columns([trial(0.6, 0.7, 1.0, 1, 0.5, 2), trial(0.8, 0.9, 0.25, 4, NAN, 0)])
    s = track_stats(lambda key: t[key])
    assert s["labelled"] and s["hota_mean"] == 0.7 and math.isclose(s["hota_std"], 0.1)
    assert (s["id_kept"], s["n_id"]) == (2 / 5, 5) and (s["coasted"], s["n_gaps"]) == (0.5, 2)
    assert s["delay_reemergence_mean"] == 2.0 and s["delay_reemergence_sigma_bar"] == 1.0
    assert (s["n_entry"], s["n_entry_censored"]) == (8, 2)
    u = columns([trial(0, 0, 0, 0, 1.0, 1, labelled=False)] * 2)
    plain = track_stats(lambda key: u[key])
    assert not plain["labelled"] and plain["n_id"] == 0 and (plain["coasted"], plain["n_gaps"]) == (1.0, 2)
    lines = render_tracks([("S-OA", "static", s), ("nnkf", "—", plain)], [])
    row = lines[-1].split(" | ")
    assert row[2:7] == [ABSENT] * 5 and row[-1] == f"{ABSENT} |" and "1.000 of 2" in lines[-1]
    assert "0.400 of 5" in lines[-2] and "0.700 ± 0.100" in lines[-2]


def test_paired_hota_against_soa():
    soa = {0: {"hota": 0.7, "idf1": 0.8}, 1: {"hota": 0.5, "idf1": 0.5}, 2: {"hota": 0.4, "idf1": 0.4}}
    other = {0: {"hota": 0.6, "idf1": 0.6}, 1: {"hota": 0.5, "idf1": 0.7}, 2: {"hota": 0.5, "idf1": 0.5}, 3: {}}
    c = tracks_vs_soa(soa, other)
    assert (c["hota_higher"], c["hota_ties"], c["hota_lower"], c["na"], c["n_trials"]) == (1, 1, 1, 1, 4)
    assert math.isclose(c["hota_diff"], 0.0, abs_tol=1e-15) and math.isclose(c["idf1_diff"], (0.2 - 0.2 - 0.1) / 3)
    lines = render_tracks([], [("static", "UBM", c)])
    assert lines[-1] == "| static | UBM | 1 / 4 | 1 | 1 | 1 | 0.000 | -0.033 |"


def test_tracks_figure_draws_labelled_curves_and_names_the_unlabelled():
    from soabench.figures.tracks import tracks_figure
    from soabench.tracks.evaluate import ALPHA_KEYS

    def col(key: str, model: str, mode: str) -> np.ndarray:
        if model == "nnkf" and key in ALPHA_KEYS:
            return np.full(3, NAN)
        return np.array([0.5, 0.6, 0.7])

    fig = tracks_figure(col, ["soa", "nnkf"], ["static", "dynamic"], 3.0)
    curves, bars = fig.axes[:2]
    assert len(curves.get_lines()) == 2 and "no labels: nnkf" in curves.get_title(loc="left")
    assert len(bars.patches) == 2 * 2 * 2  # two models x two modes x (entry, re-emergence)


def test_sweep_and_study_track_tables():
    from soabench.experiment.campaigns.study import _tracks_table
    from soabench.tracks.report import render_hota

    s = track_stats(columns([dict(hota=0.5, idf1=0.6, idsw=1.0), dict(hota=0.7, idf1=0.8, idsw=2.0)]).__getitem__)
    plain = track_stats(columns([{}, {}]).__getitem__)
    assert render_hota("λ", [("3", "nnkf", "—", plain)]) == []  # nothing labelled: no table
    lines = render_hota("λ", [("3", "S-OA", "static", s), ("3", "nnkf", "—", plain)])
    assert lines[0] == "| λ | model | mode | HOTA | IDF1 | IDSW / trial |"
    assert lines[2] == "| 3 | S-OA | static | 0.600 ± 0.100 | 0.700 ± 0.100 | 1.50 |"
    assert lines[3] == f"| 3 | nnkf | — | {ABSENT} | {ABSENT} | {ABSENT} |"
    # the study's table from trials.csv rows: per clutter rate, model and mode; none for a run without labels
    rows = [dict(clutter=3.0, model="soa", mode="static", hota=h, idf1=f, idsw=i)
            for h, f, i in ((0.5, 0.6, 1.0), (0.7, 0.8, 2.0))]  # fmt: skip
    assert _tracks_table(rows)[2] == "| 3 | S-OA | static | 0.600 ± 0.100 | 0.700 ± 0.100 | 1.50 |"
    assert _tracks_table([{k: v for k, v in r.items() if k not in ("hota", "idf1", "idsw")} for r in rows]) == []
