"""The sensitivity table: headline numbers under gate on/off, truth set and probability mode.

The table builder on small synthetic trials.csv files (a number that moves gets the right sentence, an unchanged
one says so, a sign flip is called out), and a short ``soabench study`` (fake trial function) whose sensitivity
part runs with the gate off and visible truth and writes its files.
"""

from __future__ import annotations

import csv
import json

import fake_trial as ft
import pytest

from soabench.cli.main import main
from soabench.experiment.campaigns import sensitivity as sens
from soabench.experiment.runs.files import write_csv

COLS = ["trial", "clutter", "model", "mode", "delay_mean", "delay_std", "card_err", "ospa", "mean_components"]


def _rows(card: dict[str, list[float]], delay: dict[str, list[float]] | None = None, comps: float = 40.0):
    """trials.csv rows: per model a list of per-trial card_err (OSPA = 20 x card_err), both modes alike."""
    delay = delay or {}
    out = []
    for model, values in card.items():
        for mode in ("static", "dynamic"):
            for t, c in enumerate(values):
                d = delay.get(model, [1.0] * len(values))[t]
                out.append(
                    {
                        "trial": t,
                        "clutter": 3.0,
                        "model": model,
                        "mode": mode,
                        "delay_mean": d,
                        "delay_std": 0.5,
                        "card_err": c,
                        "ospa": 20.0 * c,
                        "mean_components": comps,
                    }
                )
    return out


BASE_CARD = {"soa": [1.0, 1.0, 1.0, 1.0], "atbm": [0.8, 0.8, 0.8, 0.8], "gmbm": [2.0, 2.0, 2.0, 2.0]}
BASE_DELAY = {"soa": [1.0, 1.0, 1.0, 1.0], "atbm": [0.5, 0.5, 0.5, 0.5], "gmbm": [3.0, 3.0, 0.5, 0.5]}


def _write(tmp_path, name, rows):
    d = tmp_path / name
    d.mkdir()
    write_csv(d / "trials.csv", rows, COLS)
    return d


def _by_name(rows):
    return {r.name: r for r in rows}


def test_a_moving_number_names_the_setting_and_the_values():
    gate_off = dict(BASE_CARD, gmbm=[1.25] * 4)  # S-OA's reduction vs GMBM: 50 % -> 20 %
    rows = sens.build_rows({"default": _rows(BASE_CARD, BASE_DELAY), "gate_off": _rows(gate_off, BASE_DELAY)})
    row = _by_name(rows)["card. error vs GMBM, static"]
    assert row.values["default"].text("card_err") == "50.00%"
    assert row.values["gate_off"].text("card_err") == "20.00%"
    assert row.sentence.startswith("The gate off moves it most, from 50.00% to 20.00%")
    assert "sign" not in row.sentence
    assert "unchanged with dynamic p" in row.sentence  # both modes are alike in the synthetic rows


def test_an_unchanged_number_says_so():
    rows = sens.build_rows({"default": _rows(BASE_CARD, BASE_DELAY), "visible": _rows(BASE_CARD, BASE_DELAY)})
    row = _by_name(rows)["k̄ S-OA, dynamic"]
    assert row.sentence == "Unchanged at 1.000 s under every switch (visible truth, static p)."
    wins = _by_name(rows)["wins vs GMBM, static"]
    assert wins.values["default"].text("wins") == "2/4"
    assert wins.sentence.startswith("Unchanged at 2/4")


def test_no_counted_episode_is_not_a_win_count():
    delay = dict(BASE_DELAY, soa=[float("nan")] * 4)
    rows = _by_name(sens.build_rows({"default": _rows(BASE_CARD, delay)}))
    wins = rows["wins vs ATBM, static"]
    assert wins.values["default"].text("wins") == "n/a" and wins.values["default"].n == 0
    assert wins.sentence == "No value under the default setting."
    assert rows["k̄ S-OA, static"].values["default"].text("delay") == "n/a"


def test_sign_flips_are_called_out_and_the_largest_move_comes_first():
    visible = dict(BASE_CARD, atbm=[2.0] * 4)  # S-OA vs ATBM: -25 % (worse) -> +50 % (better)
    gate_off = dict(BASE_CARD, atbm=[0.9] * 4)  # -11.11 %: moves less, no flip
    runs = {
        "default": _rows(BASE_CARD, BASE_DELAY),
        "gate_off": _rows(gate_off, BASE_DELAY),
        "visible": _rows(visible, BASE_DELAY),
    }
    row = _by_name(sens.build_rows(runs))["card. error vs ATBM, dynamic"]
    assert row.sentence.startswith("Visible truth moves it most, from -25.00% to 50.00%: the sign flips")
    assert "(S-OA turns from worse to better than ATBM)" in row.sentence
    assert "the gate off -11.11%" in row.sentence


def test_a_win_majority_flip_is_called_out():
    delay = dict(BASE_DELAY, gmbm=[3.0, 3.0, 3.0, 0.5])  # S-OA wins 3 of 4 instead of 2 of 4
    delay_flip = dict(BASE_DELAY, gmbm=[0.5, 0.5, 0.5, 3.0])  # 1 of 4
    runs = {"default": _rows(BASE_CARD, delay), "gate_off": _rows(BASE_CARD, delay_flip)}
    row = _by_name(sens.build_rows(runs))["wins vs GMBM, static"]
    assert row.values["default"].text("wins") == "3/4" and row.values["gate_off"].text("wins") == "1/4"
    assert "S-OA's majority flips (it now loses most trials)" in row.sentence


def test_write_sensitivity_files_pair_the_common_trials_and_check_the_filter(tmp_path):
    main_dir = _write(tmp_path, "main", _rows(BASE_CARD, BASE_DELAY))
    short = {k: v[:3] for k, v in BASE_CARD.items()}  # a variant with fewer trials: the table uses trials 0-2
    vis_dir = _write(tmp_path, "visible", _rows(short, {k: v[:3] for k, v in BASE_DELAY.items()}))
    gate_dir = _write(tmp_path, "gate_off", _rows(short, {k: v[:3] for k, v in BASE_DELAY.items()}, comps=41.0))
    md = sens.write_sensitivity(tmp_path, main_dir, {"gate_off": gate_dir, "visible": vis_dir})
    assert "3 trials common to every setting" in md
    assert "the visible-truth run's filters are the default run's" in md
    assert "wins vs GMBM, static | 2/3 | 2/3 | 2/3 |" in md
    with open(tmp_path / "sensitivity.csv", newline="", encoding="utf-8") as fh:
        table = list(csv.DictReader(fh))
    row = next(r for r in table if r["number"] == "card. error vs GMBM, dynamic")
    assert float(row["default"]) == pytest.approx(50.0) and row["default_n"] == "3"
    assert row["sentence"].startswith("Unchanged at 50.00%")
    # a visible-truth run whose filter differs from the default's is flagged, not passed off as a scoring change
    vis2 = _write(tmp_path, "visible2", _rows(BASE_CARD, BASE_DELAY, comps=99.0))
    md = sens.write_sensitivity(tmp_path / "main", main_dir, {"visible": vis2})
    assert "differ from the default run's" in md
    # a variant with fewer modes is compared on what both hold
    static_only = _write(tmp_path, "static_only", [r for r in _rows(BASE_CARD, BASE_DELAY) if r["mode"] == "static"])
    md = sens.write_sensitivity(tmp_path / "main", main_dir, {"visible": static_only})
    assert "filters are the default run's" in md and "| k̄ S-OA, dynamic | 1.000 s | n/a |" in md


def test_unknown_setting_is_refused(tmp_path):
    main_dir = _write(tmp_path, "main", _rows(BASE_CARD, BASE_DELAY))
    with pytest.raises(ValueError, match="unknown sensitivity setting"):
        sens.write_sensitivity(tmp_path, main_dir, {"gate_of": main_dir})


# ------------------------------------------------------------------------------------------------ the study part
def switch_aware_trial(trial, config, scene, scenario, *, save_estimates=False):
    """:func:`fake_trial.fake_trial`, plus a visible effect of the two switches, so the table shows they arrived.

    Gate off halves GMBM's cardinality error; visible truth triples ATBM's (the numbers are made up; only the
    direction matters).
    """
    res = ft.fake_trial(trial, config, scene, scenario, save_estimates=save_estimates)
    for r in res.rows:
        if not config.filter.gate and r["model"] == "gmbm":
            r["card_err"] *= 0.5
        if config.metrics.gt_set == "visible" and r["model"] == "atbm":
            r["card_err"] *= 3.0
    return res


@pytest.fixture
def fake_study(monkeypatch):
    import soabench.experiment.campaigns.sweep as sweep
    import soabench.experiment.reports.report as report

    monkeypatch.setattr(report, "write_report", lambda run_dir, figures=True, store=None: "summary")
    monkeypatch.setattr(sweep, "write_sweep_report", lambda d: "sweep")
    with ft.as_builtins(trial=switch_aware_trial):
        yield


STUDY = ["study", "--trials", "3", "--births-trials", "1", "--duration", "10", "--workers", "1", "--no-progress"]


@pytest.mark.slow
def test_study_runs_the_sensitivity_part(tmp_path, capsys, fake_study):
    out = tmp_path / "study"
    assert main([*STUDY, "--out", str(out)]) == 0
    assert "sensitivity/sensitivity.md" in capsys.readouterr().out
    part = out / "sensitivity"
    meta = {k: json.loads((part / k / "run.json").read_text()) for k in ("gate_off", "visible")}
    main_meta = json.loads((out / "main" / "run.json").read_text())
    assert main_meta["config"]["filter"]["gate"] is True and main_meta["config"]["metrics"]["gt_set"] == "fov"
    assert meta["gate_off"]["config"]["filter"]["gate"] is False
    assert meta["gate_off"]["config"]["metrics"]["gt_set"] == "fov"
    assert meta["visible"]["config"]["metrics"]["gt_set"] == "visible"
    assert meta["visible"]["config"]["filter"]["gate"] is True
    for m in meta.values():  # the main protocol otherwise: same trials, duration, seed, models, modes, clutter
        for key in ("trials", "duration", "seed", "models", "probabilities", "clutter"):
            assert m["config"]["experiment"][key] == main_meta["config"]["experiment"][key], key
    with open(part / "sensitivity.csv", newline="", encoding="utf-8") as fh:
        table = {r["number"]: r for r in csv.DictReader(fh)}
    assert len(table) == 5 * 2 * 3 + 6 * 2 * 2  # (wins, card, ospa) x 5 baselines x 2 modes + (k̄, σ̄) x 6 x 2
    gmbm = table["card. error vs GMBM, static"]  # the gate reached the trial function: GMBM got better
    assert float(gmbm["gate_off"]) < float(gmbm["default"]) and float(gmbm["visible"]) == float(gmbm["default"])
    assert "the gate off" in gmbm["sentence"].lower() and "unchanged with visible truth" in gmbm["sentence"]
    atbm = table["card. error vs ATBM, static"]
    assert float(atbm["visible"]) > float(atbm["default"]) and float(atbm["gate_off"]) == float(atbm["default"])
    assert "visible truth" in atbm["sentence"].lower() and "unchanged with the gate off" in atbm["sentence"]
    assert table["k̄ S-OA, static"]["sentence"].startswith("Dynamic p moves it most")  # the fake's mode effect
    md = (part / "sensitivity.md").read_text()
    assert "3 trials common to every setting" in md and "filters are the default run's" in md

    # re-running resumes: more sensitivity trials extend the variants only
    assert main([*STUDY, "--sensitivity-trials", "4", "--out", str(out)]) == 0
    assert json.loads((part / "gate_off" / "run.json").read_text())["trials"] == 4
    assert json.loads((out / "main" / "run.json").read_text())["trials"] == 3
    assert "3 trials common to every setting" in (part / "sensitivity.md").read_text()
    assert main([*STUDY, "--out", str(out)]) == 0  # the same command again: nothing asks the variants for fewer
    assert json.loads((part / "visible" / "run.json").read_text())["trials"] == 4
    assert main([*STUDY[:2], "5", *STUDY[3:], "--out", str(out)]) == 0  # --trials 5: main grows, variants follow
    assert json.loads((part / "visible" / "run.json").read_text())["trials"] == 5
    assert "5 trials common to every setting" in (part / "sensitivity.md").read_text()


def test_ctrl_c_in_the_sensitivity_part_names_the_study_rerun(tmp_path, capsys, monkeypatch, fake_study):
    out = tmp_path / "study"

    def ctrl_c(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(sens, "write_sensitivity", ctrl_c)
    assert main([*STUDY, "--out", str(out)]) == 130
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("progress:")]
    assert len(err) == 1 and f"finish with: soabench study --out {out}" in err[0], err
    assert not (out / "sensitivity" / "sensitivity.md").exists()


def test_bad_sensitivity_trials_is_one_line(tmp_path, capsys):
    assert main(["study", "--sensitivity-trials", "0", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["soabench: error: --sensitivity-trials 0 must be >= 1"] or (
        len(err) == 1 and "--sensitivity-trials 0 must be >= 1" in err[0]
    )
    assert not (tmp_path / "s").exists()


# ------------------------------------------------------------------------------------------------ soabench sensitivity
RUN = ["run", "--trials", "2", "--duration", "10", "--workers", "1", "--no-progress", "--models", "soa,gmbm,atbm"]


def test_sensitivity_command_on_a_finished_run(tmp_path, capsys, fake_study):
    run = tmp_path / "run"
    assert main([*RUN, "--out", str(run)]) == 0
    assert main(["sensitivity", "--main", str(run), "--workers", "1", "--no-progress"]) == 0
    out = tmp_path / "run_sensitivity"
    assert (out / "sensitivity.md").is_file() and (out / "sensitivity.csv").is_file()
    gate = json.loads((out / "gate_off" / "run.json").read_text())
    assert gate["config"]["filter"]["gate"] is False and gate["config"]["experiment"]["models"] == [
        "soa",
        "gmbm",
        "atbm",
    ]
    with open(out / "sensitivity.csv", newline="", encoding="utf-8") as fh:
        table = {r["number"]: r for r in csv.DictReader(fh)}
    assert set(table) >= {"wins vs GMBM, static", "k̄ ATBM, dynamic"} and "wins vs PUBM, static" not in table
    # more trials extend the variants; fewer are refused in one line; the main run is left as it was
    assert main(["sensitivity", "--main", str(run), "--trials", "3", "--workers", "1", "--no-progress"]) == 0
    assert json.loads((out / "visible" / "run.json").read_text())["trials"] == 3
    capsys.readouterr()
    assert main(["sensitivity", "--main", str(run), "--trials", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "would drop finished ones" in err[0], err
    assert json.loads((run / "run.json").read_text())["trials"] == 2


def test_a_variant_of_another_main_protocol_is_refused(tmp_path, capsys, fake_study):
    run, other = tmp_path / "run", tmp_path / "other"
    assert main([*RUN, "--out", str(run)]) == 0
    assert main([*RUN, "--seed", "3", "--out", str(other)]) == 0
    out = tmp_path / "sens"
    assert main(["sensitivity", "--main", str(other), "--out", str(out), "--workers", "1", "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["sensitivity", "--main", str(run), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "made from another main protocol" in err[0] and "experiment.seed" in err[0], err


def test_sensitivity_command_needs_a_finished_run(tmp_path, capsys):
    assert main(["sensitivity", "--main", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a run folder" in err[0], err
