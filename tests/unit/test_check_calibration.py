"""``soabench check --calibrate N`` proposes thresholds from N runs' values: the 95 % prediction bounds of one
further run, never past the metric's range (a suite would refuse such a bound); a bad scenario is refused before the
check folder is made. No scenario runs here."""

from __future__ import annotations

import math

from scipy.stats import t as student_t

from soabench.experiment.campaigns.check import Suite, Threshold, propose

KEY = "a/soa/static/lambda=3/"


def _suite(*thresholds: Threshold) -> Suite:
    return Suite(name="s", path=None, scenarios=[], thresholds=list(thresholds))  # type: ignore[arg-type]


def test_the_bound_is_the_prediction_bound_of_one_further_run() -> None:
    ospa = [40.0, 50.0, 60.0, 55.0]
    (p,) = propose(_suite(Threshold("ospa", max=90.0)), [{KEY + "ospa": v} for v in ospa])
    s = math.sqrt(sum((v - 51.25) ** 2 for v in ospa) / 3)
    half = student_t.ppf(0.975, 3) * s * math.sqrt(1 + 1 / 4)
    assert (p.runs, p.mean) == (4, 51.25) and math.isclose(p.std, s)
    assert math.isclose(p.high, 51.25 + half) and math.isclose(p.low, 51.25 - half)
    assert p.threshold == f"max = {51.25 + half:.6g}"


def test_a_band_past_the_metric_range_stops_at_its_edge_and_says_so() -> None:
    precision = [0.5, 0.95, 0.99]  # one bad run: the band's low end is below 0
    (p,) = propose(_suite(Threshold("precision", min=0.5)), [{KEY + "precision": v} for v in precision])
    assert p.low == 0.0 and p.high == 1.0
    assert p.threshold == "min = 0 (the band passes the metric's range: too noisy to bound, add trials)"
    (q,) = propose(_suite(Threshold("precision", min=0.5)), [{KEY + "precision": v} for v in (0.9, 0.92, 0.91)])
    assert 0 < q.low < 0.9 and "too noisy" not in q.threshold


def test_a_misspelled_model_is_refused_before_the_check_folder_is_made(tmp_path, capsys) -> None:
    from soabench.cli.main import main

    suite = tmp_path / "s.toml"
    suite.write_text(
        '[[scenario]]\nname = "a"\nnet = "arterial"\nmodels = ["sao"]\n[[threshold]]\nmetric = "ospa"\nmax = 100\n'
    )
    for extra in ([], ["--calibrate", "3"]):
        assert main(["check", "--suite", str(suite), "--out", str(tmp_path / "out"), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "birth model 'sao' is unknown" in err[0] and "(did you mean 'soa'?)" in err[0]
        assert not (tmp_path / "out").exists()


def test_a_misspelled_scene_of_a_later_scenario_is_refused_before_the_first_runs(tmp_path, capsys) -> None:
    from soabench.cli.main import main

    suite = tmp_path / "s.toml"
    suite.write_text(
        '[[scenario]]\nname = "a"\nnet = "arterial"\n[[scenario]]\nname = "b"\nnet = "arterail"\n'
        '[[threshold]]\nmetric = "ospa"\nmax = 100\n'
    )
    assert main(["check", "--suite", str(suite), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[[scenario]] 'b': net='arterail' is neither a shipped network" in err[0], err
    assert "(did you mean 'arterial'?)" in err[0] and not (tmp_path / "out").exists()
