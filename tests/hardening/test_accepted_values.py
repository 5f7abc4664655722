"""Values that were accepted but wrong, or ended in a traceback: the bad command lines of tests/bad_inputs_more.py
(one line, exit 2, no trial), and trial records merged only when they are that trial of this run (a copy saved
under another trial's name, a stray file name, a JSON list, a record of another run: moved aside on --resume and
run again), and values given twice refused."""

from __future__ import annotations

import json
import shutil

import bad_inputs
import bad_inputs_more
import pytest
from fake_trial import renumbered
from test_command_line import test_bad_input_is_one_line_and_exit_2 as one_line_and_exit_2

from soabench.cli.main import main
from soabench.config import Config, ExperimentConfig
from soabench.errors import SoabenchError
from soabench.experiment.runs.files import read_csv
from soabench.experiment.runs.store import RunStore, run_identity, trial_of_name


# ------------------------------------------------------------------------------------------ bad command lines
@pytest.mark.parametrize(
    ("name", "make", "needle"), bad_inputs_more.CASES, ids=[c[0] for c in bad_inputs_more.CASES]
)  # fmt: skip
def test_bad_value_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch, no_work, name, make, needle):  # noqa: F811
    one_line_and_exit_2(
        tmp_path, capsys, monkeypatch, no_work, name, make, needle
    )  # the first table's test, on these cases
    for folder in ("out", "sw", "kout"):  # and no output folder was started
        assert not (tmp_path / folder).exists(), folder


@pytest.mark.parametrize(
    ("code", "err", "want"),
    [
        (2, "soabench: error: --trials 0 must be >= 1\n", "clean"),
        (2, "Traceback (most recent call last):\nValueError: --trials 0\n", "traceback"),
        (1, "soabench: error: --trials 0 must be >= 1\n", "silent"),
        (0, "", "silent"),
        (2, "soabench: error: --trials 0 must be >= 1\nsoabench: error: again\n", "unclear"),
        (2, "soabench: error: a value is wrong\n", "unclear"),  # the line does not name the value
        (2, "error: --trials 0 must be >= 1\n", "unclear"),
    ],
)
def test_the_verdict_of_every_case_tells_a_clean_refusal_from_the_others(code, err, want):
    """Each case above passes only on the verdict "clean": exit 2 and one line ``soabench: error: ...`` naming the
    value; a traceback, another exit status, a second line or a line without the value is not clean."""
    assert bad_inputs.verdict(code, "", err, "--trials 0") == want


# ---------------------------------------------------------------------------------------- values given twice
@pytest.mark.parametrize(
    ("field", "value"),
    [("clutter", (3.0, 3.0)), ("clutter", (0.5, 3.0, 0.5)), ("clutter", (3, 3.0)), ("probabilities", ("static",) * 2)],
)
def test_a_value_given_twice_is_refused(field, value):
    with pytest.raises(SoabenchError, match="twice; give each value once"):
        ExperimentConfig(**{field: value}).validate()


def test_distinct_values_are_accepted():
    ExperimentConfig(clutter=(0.5, 3.0, 5.0), probabilities=("static", "dynamic", "dynamic+occ")).validate()


# ------------------------------------------------------------------------------------------------ records
def _new_run(tmp_path, trials: int = 3, *extra: str):
    out = tmp_path / "run"
    argv = ["run", "--trials", str(trials), "--duration", "10", "--workers", "1", "--no-progress", "--out", str(out)]
    assert main([*argv, *extra]) == 0
    return out


def _rows(out) -> list[tuple[int, float, str, str]]:
    t = read_csv(out / "trials.csv")
    return sorted(zip(t["trial"].astype(int), t["clutter"], t["model"], t["mode"], strict=True))


def test_run_json_and_every_record_carry_the_run_identity(tmp_path, fake_cli_runs):
    out = _new_run(tmp_path)
    meta = json.loads((out / "run.json").read_text())
    assert meta["run_id"] == run_identity(meta) and len(meta["run_id"]) == 64
    for p in (out / "trials").glob("trial_*.json"):
        assert json.loads(p.read_text())["run_id"] == meta["run_id"]


def test_the_identity_ignores_the_trial_count_and_nothing_else(tmp_path, fake_cli_runs):
    meta = json.loads((_new_run(tmp_path) / "run.json").read_text())
    more = json.loads(json.dumps(meta))
    more["config"]["experiment"]["trials"] = 50  # a resume may raise the trial count
    assert run_identity(more) == run_identity(meta)
    for edit in (("experiment", "seed", 7), ("sensor", "lambda_c", 1.0), ("experiment", "clutter", [1.0])):
        other = json.loads(json.dumps(meta))
        other["config"][edit[0]][edit[1]] = edit[2]
        assert run_identity(other) != run_identity(meta), edit
    assert run_identity({**meta, "net": "arterial"}) != run_identity(meta)


def test_a_copy_of_trial_0_saved_as_trial_2_is_moved_aside_and_trial_2_runs(tmp_path, fake_cli_runs, capsys):
    out = _new_run(tmp_path)
    before = _rows(out)
    trials = out / "trials"
    shutil.copy(trials / "trial_00000.json", trials / "trial_00002.json")  # trial 0 twice, trial 2 never run
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "trials/trial_00002.json: it is not trial 2 of this run: it holds trial 0" in err
    assert "trial 2 runs again" in err
    assert json.loads((trials / "trial_00002.json").read_text())["trial"] == 2
    assert json.loads((out / "rejected" / "trials" / "trial_00002.json").read_text())["trial"] == 0
    assert _rows(out) == before  # the rows of trials 0, 1, 2, once each


def test_a_stray_record_beyond_the_trial_count_is_not_said_to_run_again(tmp_path, fake_cli_runs, capsys):
    out = _new_run(tmp_path)
    before = _rows(out)
    shutil.copy(out / "trials" / "trial_00000.json", out / "trials" / "trial_00007.json")
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "trials/trial_00007.json: it is not trial 7 of this run: it holds trial 0" in err
    assert "the run has trials 0-2, so no trial 7 runs" in err and "runs again" not in err
    assert not (out / "trials" / "trial_00007.json").exists() and _rows(out) == before


def test_a_record_whose_tables_hold_another_trial_is_moved_aside(tmp_path, fake_cli_runs, capsys):
    out = _new_run(tmp_path)
    before = _rows(out)
    rec = json.loads((out / "trials" / "trial_00001.json").read_text())
    (out / "trials" / "trial_00002.json").write_text(json.dumps({**rec, "trial": 2}))  # trial 1's rows, renamed
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "trial_00002.json: it is not trial 2 of this run: row 0 of its rows table has a key cell" in err
    assert "trial 2 runs again" in err and _rows(out) == before


def test_a_record_of_a_trial_beyond_the_trial_count_is_refused_in_one_line(tmp_path, fake_cli_runs, capsys):
    out = _new_run(tmp_path)
    before = _rows(out)
    rec = json.loads((out / "trials" / "trial_00001.json").read_text())
    (out / "trials" / "trial_00007.json").write_text(json.dumps(renumbered(rec, 7)))
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds trial [7] beyond its 3 trials" in err[0]
    assert _rows(out) == before


@pytest.mark.parametrize(
    ("name", "content", "says"),
    [
        ("trial_-0001.json", '{"trial": -1, "status": "ok"}', "is not a trial record name"),
        ("trial_2.json", '{"trial": 2, "status": "ok"}', "is not a trial record name"),
        ("trial_00001.json", "[1, 2, 3]", "it holds a JSON list, not a trial record"),
        ("trial_00001.json", "{not json", "cannot read"),
        ("trial_00001.json", '{"trial": "1", "status": "ok"}', "it holds trial '1'"),
    ],
)
def test_stray_or_malformed_records_are_moved_aside_and_the_run_finishes(
    tmp_path, fake_cli_runs, capsys, name, content, says
):
    out = _new_run(tmp_path)
    before = _rows(out)
    (out / "trials" / name).write_text(content)
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"trials/{name}: " in err and says in err and "Traceback" not in err
    assert (out / "rejected" / "trials" / name).read_text() == content
    assert _rows(out) == before
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0  # and again: nothing left to reject
    assert "rejected" not in capsys.readouterr().err


def test_a_record_of_another_run_is_moved_aside(tmp_path, fake_cli_runs, capsys):
    out = _new_run(tmp_path)
    before = _rows(out)
    other = _new_run(tmp_path / "o", 3, "--seed", "5")  # other settings: other numbers
    shutil.copy(other / "trials" / "trial_00001.json", out / "trials" / "trial_00001.json")
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    assert "it was made by another run" in capsys.readouterr().err
    assert _rows(out) == before


def test_a_failure_record_of_another_trial_is_moved_aside(tmp_path, fake_cli_runs, capsys):
    out = _new_run(tmp_path)
    (out / "failed").mkdir()
    (out / "failed" / "trial_00001.json").write_text('{"trial": 0, "status": "failed"}')
    assert main(["run", "--resume", str(out), "--no-progress"]) == 0
    assert "failed/trial_00001.json: it is not trial 1 of this run" in capsys.readouterr().err


def test_the_merge_refuses_a_record_that_is_not_its_trial(tmp_path, fake_cli_runs):
    out = _new_run(tmp_path)
    trials = out / "trials"
    shutil.copy(trials / "trial_00000.json", trials / "trial_00001.json")
    store = RunStore(out)
    with pytest.raises(SoabenchError, match="is not trial 1 of this run .*--resume"):
        store.merge(("soa",), ("static",))


def test_a_folder_made_before_records_carried_an_identity_still_checks_the_trial_index(tmp_path, fake_cli_runs):
    out = _new_run(tmp_path)
    meta = json.loads((out / "run.json").read_text())
    del meta["run_id"]
    (out / "run.json").write_text(json.dumps(meta))
    for p in (out / "trials").glob("trial_*.json"):
        rec = json.loads(p.read_text())
        del rec["run_id"]
        p.write_text(json.dumps(rec))
    store = RunStore(out)
    assert store.reject_foreign_records() == []
    assert store.load_trial(1)["trial"] == 1
    shutil.copy(out / "trials" / "trial_00000.json", out / "trials" / "trial_00001.json")
    assert len(RunStore(out).reject_foreign_records()) == 1


def test_a_run_id_that_is_not_an_identity_is_refused(tmp_path, fake_cli_runs):
    out = _new_run(tmp_path)
    meta = json.loads((out / "run.json").read_text())
    (out / "run.json").write_text(json.dumps({**meta, "run_id": ["x"]}))
    with pytest.raises(SoabenchError, match="is not a run identity"):
        RunStore(out).load_trial(0)


@pytest.mark.parametrize(
    ("name", "trial"),
    [("trial_00042.json", 42), ("trial_123456.json", 123456), ("trial_-0001.json", None), ("trial_42.json", None),
     ("trial_000042.json", None), ("trial_00042.json.tmp", None), ("trial_0004a.json", None)],
)  # fmt: skip
def test_trial_of_name(name, trial):
    assert trial_of_name(name) == trial


def test_resume_with_save_estimates_of_a_run_that_saves_them_is_accepted(tmp_path, fake_cli_runs):
    out = _new_run(tmp_path, 2, "--save-estimates")
    assert main(["run", "--resume", str(out), "--save-estimates", "--no-progress"]) == 0


def test_config_from_a_run_with_duplicates_is_refused_on_resume(tmp_path, fake_cli_runs, capsys):
    out = _new_run(tmp_path)
    meta = json.loads((out / "run.json").read_text())
    meta["config"]["experiment"]["clutter"] = [3.0, 3.0]
    (out / "run.json").write_text(json.dumps(meta))
    assert main(["run", "--resume", str(out)]) == 2
    assert "names 3.0 twice" in capsys.readouterr().err
    assert Config.from_dict({"experiment": {"clutter": [3.0]}}).validate()


# ------------------------------------------------------------------------------------------------ KITTI records
@pytest.mark.parametrize(
    ("content", "says"),
    [("[1, 2]", "is not the record of cv sequence 0001"), (None, "it says 'cv' sequence '0000'")],
)
def test_a_kitti_record_that_is_not_its_sequence_is_one_line(tmp_path, capsys, content, says):
    import kitti_files

    root = kitti_files.write_dataset(tmp_path / "kitti", n=3, n_frames=12)
    run = tmp_path / "run"
    assert main(["kitti", "--root", str(root), "--folds", "3", "--models", "soa", "--out", str(run)]) == 0
    records = run / "records" / "cv"
    if content is None:  # a copy of sequence 0000's record (folds of one sequence each: another N_hat, too)
        shutil.copy(records / "0000.json", records / "0001.json")
    else:
        (records / "0001.json").write_text(content)
    capsys.readouterr()
    assert main(["kitti", "--resume", str(run)]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("soabench: error")]
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in err, err
