"""Breakdowns of identity kept, coasted share and re-emergence delay by gap length and occluder kind, with bootstrap
intervals over trials (docs/method.md §9.4), the Tracks table's intervals, and the check suite's gap metrics, on
hand-built episode rows."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from soabench.config import Config
from soabench.errors import SoabenchError
from soabench.experiment.reports.occlusion import bin_labels, breakdown, identity_curves, render
from soabench.experiment.reports.tables import RunTables
from soabench.experiment.reports.track_intervals import mean_interval, paired

#: per trial and model: (gap scans, occluder, coasted, id kept, delay) of each re-emergence episode
EPISODES = {
    "soa": [(1, "vehicle", 1, 1, 0.0), (3, "parked", 1, 1, 0.0), (9, "building", 0, 1, 1.0)],
    "pubm": [(1, "vehicle", 1, 1, 0.0), (3, "parked", 0, 1, 1.0), (9, "building", 0, 0, 3.0)],
}
N_TRIALS = 6


def tables() -> RunTables:
    """Six trials; in trial n the 9-scan gap of PUBM keeps its identity when n is even (so 3 of 6), S-OA always; an
    entry episode (empty gap cells) in every run."""
    rows: list[dict] = []
    for n in range(N_TRIALS):
        for model, eps in EPISODES.items():
            rows.append({"trial": n, "model": model, "gap_scans": "", "gap_occluder": "", "gap_coasted": "",
                         "gap_id_kept": "", "delay": 0.0, "censored": 0})  # fmt: skip
            for scans, kind, coasted, kept, delay in eps:
                if model == "pubm" and scans == 9:
                    kept = int(n % 2 == 0)
                gap = {"gap_scans": float(scans), "gap_occluder": kind, "gap_coasted": float(coasted),
                       "gap_id_kept": float(kept)}  # fmt: skip
                rows.append({"trial": n, "model": model, **gap, "delay": delay, "censored": 0})
    e = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    e["gap_scans"] = np.array([math.nan if v == "" else float(v) for v in e["gap_scans"]])
    for k in ("gap_coasted", "gap_id_kept"):
        e[k] = np.array([math.nan if v == "" else float(v) for v in e[k]])
    e["clutter"], e["mode"] = np.full(len(rows), 3.0), np.full(len(rows), "static")
    t = {
        "trial": np.repeat(np.arange(N_TRIALS), 2).astype(float),
        "model": np.tile(["soa", "pubm"], N_TRIALS),
        "mode": np.full(2 * N_TRIALS, "static"),
        "clutter": np.full(2 * N_TRIALS, 3.0),
    }
    meta = {"config": {"experiment": {"models": ["soa", "pubm"], "probabilities": ["static"]}}}
    return RunTables(t, e, {}, {}, meta)


def test_bin_labels():
    assert bin_labels((1, 2, 4, 8)) == ["1", "2-3", "4-7", "8+"]
    assert bin_labels((1, 3, 6)) == ["1-2", "3-5", "6+"]
    assert bin_labels((1,)) == ["1+"]


@pytest.mark.parametrize("bins", [[2, 4], [1, 1], [1, 3, 2], [], [1, 2.5], [0, 1]])
def test_gap_bins_are_validated(bins):
    with pytest.raises(SoabenchError, match="metrics.gap_bins"):
        Config.from_dict({"metrics": {"gap_bins": bins}}).validate()


def test_breakdown_by_bin_and_kind_with_bootstrap_intervals():
    occ = breakdown(tables(), 3.0, (1, 2, 4, 8), ["pubm"])
    row = {(r["model"], r["by"], r["group"]): r for r in occ["rows"]}
    assert occ["bin_labels"] == ["1", "2-3", "4-7", "8+"]
    # S-OA keeps every identity; PUBM keeps 3 of its 6 long gaps
    assert row[("soa", "gap", "8+")]["id_kept"] == 1.0 and row[("soa", "gap", "8+")]["n_id_kept"] == N_TRIALS
    long = row[("pubm", "gap", "8+")]
    assert long["id_kept"] == 0.5 and long["n_id_kept"] == N_TRIALS
    assert 0.0 <= long["id_kept_lo"] < 0.5 < long["id_kept_hi"] <= 1.0  # the trials disagree: a real interval
    assert row[("pubm", "gap", "2-3")]["coasted"] == 0.0 and row[("soa", "gap", "2-3")]["coasted"] == 1.0
    assert row[("pubm", "gap", "8+")]["delay"] == 3.0 and row[("pubm", "gap", "2-3")]["delay"] == 1.0
    # the same gaps by kind: the 3-scan gap is the parked car's, the 9-scan gap the building's
    assert (
        row[("pubm", "occluder", "parked")]["delay"] == 1.0 and row[("pubm", "occluder", "building")]["id_kept"] == 0.5
    )
    assert row[("soa", "gap", "4-7")]["n_id_kept"] == 0 and math.isnan(row[("soa", "gap", "4-7")]["id_kept"])
    assert row[("soa", "occluder", "other")]["n_coasted"] == 0
    # paired S-OA − PUBM per bin, on the same resampled trials
    vs = {(c["by"], c["group"]): c for c in occ["vs_soa"]}
    assert vs[("gap", "8+")]["id_kept_diff"] == 0.5
    assert vs[("gap", "8+")]["id_kept_diff_lo"] <= 0.5 <= vs[("gap", "8+")]["id_kept_diff_hi"]
    assert vs[("gap", "1")]["id_kept_diff"] == 0.0 and vs[("gap", "1")]["id_kept_diff_lo"] == 0.0
    assert vs[("gap", "8+")]["delay_diff"] == -2.0
    # seeded: the same rows give the same intervals
    assert json.dumps(breakdown(tables(), 3.0, (1, 2, 4, 8), ["pubm"])) == json.dumps(occ)  # NaN cells too
    text = "\n".join(render(occ, {"soa": True, "pubm": True}))
    assert "| PUBM | static | 8+ scans | 0.500 [" in text and "| PUBM | static | building |" in text


def test_other_bins_regroup_the_same_gaps():
    occ = breakdown(tables(), 3.0, (1, 4), [])
    row = {(r["model"], r["group"]): r for r in occ["rows"] if r["by"] == "gap"}
    assert set(occ["bin_labels"]) == {"1-3", "4+"} and occ["vs_soa"] == []
    assert row[("pubm", "1-3")]["n_coasted"] == 2 * N_TRIALS and row[("pubm", "1-3")]["coasted"] == 0.5


def test_identity_curves_per_kind():
    curves = identity_curves(tables(), 3.0, (1, 2, 4, 8))
    assert list(curves) == ["all", "parked", "vehicle", "building"]
    pubm = curves["all"][("pubm", "static")]
    assert pubm[:, 0].tolist()[:2] == [1.0, 1.0] and math.isnan(pubm[2, 0]) and pubm[3, 0] == 0.5
    assert pubm[:, 3].tolist() == [N_TRIALS, N_TRIALS, 0, N_TRIALS]
    assert np.isnan(curves["building"][("pubm", "static")][0, 0])  # the building hid no 1-scan gap


def test_identity_gaps_figure_labels_columns_and_rows_once_at_any_number_of_rows():
    """14 families x 3 kinds (42 panels, past the 26 letters): the kind once over each column, the family and mode
    once left of each row, no panel letter; the figure grows with the rows."""
    from soabench.figures.gaps import ROW_HEIGHT, identity_gaps_figure

    t = tables()
    fams = [(f"F{i}", t) for i in range(14)]
    fig, one = identity_gaps_figure(t, 3.0, fams), identity_gaps_figure(t, 3.0, fams[:1])
    axes = [ax for ax in fig.axes if ax.get_subplotspec() is not None]
    grid = np.array(axes).reshape(14, 4)
    assert [ax.get_title() for ax in grid[0]] == ["every occluder", "parked car", "moving vehicle", "building"]
    assert all(ax.get_title(loc=w) == "" for ax in grid[1:].ravel() for w in ("left", "center", "right"))
    assert all(ax.get_title(loc="left") == "" for ax in grid[0])
    assert [ax.get_ylabel() for ax in grid[:, 0]] == [f"F{i}, static\nidentity kept" for i in range(14)]
    assert all(ax.get_ylabel() == "" for ax in grid[:, 1:].ravel())
    assert fig.get_figheight() - one.get_figheight() == pytest.approx(13 * ROW_HEIGHT)


def test_track_intervals():
    mean, lo, hi, n = mean_interval(np.array([1.0, 2.0, 3.0, np.nan]))
    assert (mean, n) == (2.0, 3) and lo == pytest.approx(2.0 - 4.302653 / math.sqrt(3)) and hi > 3.0
    soa = {n: {"hota": 0.6 + 0.01 * n, "idf1": 0.5, "id_kept": 1.0} for n in range(8)}
    other = {n: {"hota": 0.5, "idf1": 0.5, "id_kept": math.nan if n == 0 else 0.5} for n in range(8)}
    c = paired(soa, other)
    assert c["hota_diff"] == pytest.approx(0.135) and c["hota_lo"] > 0.1 and c["hota_p"] < 0.01
    assert c["idf1_diff"] == 0.0 and math.isnan(c["idf1_p"])  # every difference 0: no test
    assert c["id_kept_n"] == 7 and c["id_kept_diff"] == 0.5


def test_check_suites_threshold_each_gap_bin(tmp_path):
    from soabench.experiment.campaigns.check import _gap_values, gap_metrics, load_suite
    from soabench.experiment.runs.files import write_csv

    names = gap_metrics((1, 2, 4, 8))
    assert names["identity_kept_long"] == ("gap_id_kept", 3) and names["coasted_gap_2-3"] == ("gap_coasted", 1)
    head = '[[scenario]]\nname = "a"\nnet = "intersection"\n[[threshold]]\nmetric = "{}"\nmin = 0.5\n'
    (tmp_path / "ok.toml").write_text(head.format("identity_kept_long"))
    assert load_suite(tmp_path / "ok.toml").thresholds[0].metric == "identity_kept_long"
    (tmp_path / "above.toml").write_text(head.format("identity_kept_long").replace("min = 0.5", "min = 1.5"))
    with pytest.raises(SoabenchError, match="outside the metric's range"):  # a share: in [0, 1]
        load_suite(tmp_path / "above.toml")
    (tmp_path / "bad.toml").write_text(head.format("identity_kept_gap_9-10"))
    with pytest.raises(SoabenchError, match="identity_kept_gap_9-10"):
        load_suite(tmp_path / "bad.toml")
    # a suite whose configuration bins the gaps otherwise has those bins' names
    (tmp_path / "bins.toml").write_text("[metrics]\ngap_bins = [1, 3]\n")
    (tmp_path / "own.toml").write_text('[suite]\nconfig = "bins.toml"\n' + head.format("coasted_gap_1-2"))
    assert load_suite(tmp_path / "own.toml").thresholds[0].metric == "coasted_gap_1-2"
    # pooled over the episodes of a run folder: kept / counted per bin, entry episodes and uncounted ones left out
    rows = [
        {"model": "soa", "mode": "static", "clutter": 3.0, "gap_scans": n, "gap_id_kept": kept, "gap_coasted": 0}
        for n, kept in ((1, 1), (1, 0), (9, 1), (12, None), (None, None))
    ]
    write_csv(tmp_path / "episodes.csv", rows, list(rows[0]))
    sums: dict = {}
    _gap_values(tmp_path, "a", (1, 2, 4, 8), sums)
    assert sums[("a", "soa", "static", 3.0, "identity_kept_gap_1")] == [1.0, 2.0]
    assert sums[("a", "soa", "static", 3.0, "identity_kept_long")] == [1.0, 1.0]
    assert sums[("a", "soa", "static", 3.0, "coasted_long")] == [0.0, 2.0]
