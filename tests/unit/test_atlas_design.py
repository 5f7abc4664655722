"""The atlas's design, plan, statistics and bad input (docs/user-guide/atlas.md), without running a trial."""

from __future__ import annotations

import math

import numpy as np
import pytest

from soabench.cli.main import main
from soabench.config import Config
from soabench.errors import SoabenchError
from soabench.experiment.campaigns.atlas import stats
from soabench.experiment.campaigns.atlas.design import make_design, parse_axis
from soabench.experiment.campaigns.atlas.plan import estimate, plan_points, point_config


def _cfg(**exp) -> Config:
    cfg = Config()
    import dataclasses

    cfg.experiment = dataclasses.replace(cfg.experiment, **exp)
    return cfg.validate()


def test_factorial_points_first_axis_slowest():
    d = make_design([parse_axis("parking.density=0,4"), parse_axis("experiment.clutter=0.5,3,5")])
    assert len(d.points) == 6
    assert [p["parking.density"] for p in d.points] == [0.0, 0.0, 0.0, 4.0, 4.0, 4.0]
    assert [p["experiment.clutter"] for p in d.points[:3]] == [0.5, 3.0, 5.0]


@pytest.mark.parametrize("kind", ["sobol", "lhs"])
def test_sampled_designs_stay_in_range_and_repeat(kind):
    axes = [parse_axis("sensor.p_D=0.6:0.95"), parse_axis("pedestrians.count=3:24"), parse_axis("net=intersection")]
    d1 = make_design(axes, kind, 16, seed=3)
    d2 = make_design(axes, kind, 16, seed=3)
    assert d1.points == d2.points and len(d1.points) == 16
    pd = np.array([p["sensor.p_D"] for p in d1.points])
    assert pd.min() >= 0.6 and pd.max() <= 0.95 and len(set(pd)) == 16  # spread, not a grid
    assert all(isinstance(p["pedestrians.count"], int) and 3 <= p["pedestrians.count"] <= 24 for p in d1.points)
    assert make_design(axes, kind, 16, seed=4).points != d1.points


def test_points_share_a_scene_variant_across_non_simulation_axes():
    d = make_design(
        [parse_axis("pedestrians.count=3,6"), parse_axis("experiment.clutter=0.5,5"), parse_axis("sensor.p_D=0.7,0.9")]
    )
    variants, points = plan_points(d, _cfg(), "intersection")
    assert len(variants) == 2 and len(points) == 8
    assert sorted({p.scene for p in points}) == [0, 1]
    # sensor.p_D sets the filter's p_D too (a filter that knows its sensor) ...
    cfg = point_config(_cfg().to_dict(), points[1].overrides)
    assert cfg.sensor.p_D == cfg.filter.p_D == points[1].values["sensor.p_D"]
    assert cfg.experiment.clutter == (points[1].values["experiment.clutter"],)
    # ... unless filter.p_D is an axis of its own: the mismatch is studied
    d2 = make_design([parse_axis("sensor.p_D=0.7"), parse_axis("filter.p_D=0.98")])
    _, pts = plan_points(d2, _cfg(), "intersection")
    cfg2 = point_config(_cfg().to_dict(), pts[0].overrides)
    assert (cfg2.sensor.p_D, cfg2.filter.p_D) == (0.7, 0.98)


def test_nhat_offset_counts_from_the_points_pedestrians():
    d = make_design([parse_axis("pedestrians.count=6,12"), parse_axis("birth.N_hat_offset=-10,2")])
    _, points = plan_points(d, _cfg(duration=50.0), "intersection")
    got = {
        (p.values["pedestrians.count"], p.values["birth.N_hat_offset"]): p.overrides["birth"]["N_hat"] for p in points
    }
    assert got == {(6, -10): 1 / 50, (6, 2): 8 / 50, (12, -10): 2 / 50, (12, 2): 14 / 50}


def test_cost_counts_one_sumo_run_per_variant_and_trial():
    d = make_design([parse_axis("parking.density=0,4"), parse_axis("experiment.clutter=0.5,3,5")])
    base = _cfg(trials=10, models=("soa", "pubm"), probabilities=("static", "dynamic"))
    variants, points = plan_points(d, base, "intersection")
    c = estimate(base, variants, points, 10)
    assert (c.points, c.trials, c.sumo_runs, c.filter_runs) == (6, 60, 20, 6 * 10 * 2 * 2)
    assert c.core_hours > 0


def test_fdr_marks_bh_discoveries_and_their_intervals_exclude_the_null():
    cells = [
        stats.Cell("ospa_red", "pubm", "static", "gmphd", ("a",), (i,), 20, est, est - w, est + w, p)
        for i, (est, w, p) in enumerate([(5.0, 2.0, 0.001), (3.0, 2.5, 0.02), (1.0, 3.0, 0.04), (0.5, 4.0, 0.6)])
    ]
    stats._fdr(cells)
    # BH at q = 0.05, m = 4: thresholds 0.0125, 0.025, 0.0375, 0.05 -> p = 0.001, 0.02 rejected; 0.04 > 0.0375
    assert [c.significant for c in cells] == [True, True, False, False]
    for c in cells[:2]:
        assert c.adj_low > 0 and c.adj_high > c.high  # wider than the 95 % interval, still excluding 0
    assert math.isnan(cells[2].adj_low)


def test_t_interval_p_value_matches_scipy():
    from scipy import stats as st

    x = np.array([0.3, -0.1, 0.5, 0.2, 0.4, 0.0, 0.6])
    m, lo, hi, p = stats._t_interval(x, 0.0)
    assert p == pytest.approx(st.ttest_1samp(x, 0.0).pvalue)
    assert lo < m < hi
    assert stats._t_interval(np.ones(5), 0.5)[3] == 0.0  # every trial a win: certain


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--axis", "nope.key=1"], "nope.key"),
        (["--axis", "sensor.p_D=0.5,1.5"], "sensor.p_D = 1.5"),
        (["--axis", "sensor.p_D="], "axis sensor.p_D is empty"),
        (["--axis", "parking.density=40"], "parking.density = 40"),
        (["--axis", "experiment.seed=1,2"], "experiment.seed"),
        (["--axis", "sensor.p_D=0.5:0.9"], "needs --sample sobol or lhs"),
        (["--axis", "sensor.p_D=0.5,0.6", "--trials", "30", "--max-trials", "50"], "--max-trials 50"),
        (["--axis", "sensor.p_D=0.5:0.9", "--sample", "sobol", "--points", "12"], "power of 2"),
    ],
)
def test_bad_atlas_input_one_line_exit_2_nothing_written(tmp_path, capsys, argv, needle):
    out = tmp_path / "atlas"
    code = main(["atlas", *argv, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_bad_query_input(tmp_path, capsys):
    assert main(["query", str(tmp_path), "SELECT 1"]) == 2
    assert "is neither an atlas" in capsys.readouterr().err
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text("{}")
    (run / "trials.csv").write_text("trial,model,ospa\n0,soa,1.5\n1,soa,2.5\n")
    assert main(["query", str(run), "SELECT avg(ospa) AS m FROM trials"]) == 0
    assert "2" in capsys.readouterr().out
    assert main(["query", str(run), "SELECT nope FROM trials"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("soabench: error: the SQL failed") and len(err.strip().splitlines()) == 1
    # the query reads only inside the folder
    assert main(["query", str(run), f"SELECT * FROM read_csv('{tmp_path / 'x.csv'}')"]) == 2
    assert main(["query", str(run), f"COPY (SELECT 1) TO '{tmp_path / 'y.csv'}'"]) == 2
    assert not (tmp_path / "y.csv").exists()


def test_query_out_writes_csv_and_parquet(tmp_path, capsys):
    import pyarrow.parquet as pq

    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text("{}")
    (run / "trials.csv").write_text("trial,model,ospa\n0,soa,1.5\n0,pubm,2.5\n")
    assert (
        main(["query", str(run), "SELECT model, ospa FROM trials ORDER BY model", "--out", str(tmp_path / "r.csv")])
        == 0
    )
    assert (tmp_path / "r.csv").read_text().splitlines()[1:] == ['"pubm",2.5', '"soa",1.5']
    assert main(["query", str(run), "SELECT * FROM trials", "--out", str(tmp_path / "r.parquet")]) == 0
    assert pq.read_table(tmp_path / "r.parquet").num_rows == 2
    assert main(["query", str(run), "SELECT 1", "--out", str(tmp_path / "r.txt")]) == 2


def test_not_an_atlas_is_refused(tmp_path):
    (tmp_path / "atlas.json").write_text('{"format": "something else"}')
    with pytest.raises(SoabenchError, match="is not an atlas"):
        from soabench.experiment.campaigns.atlas.query import tables_of

        tables_of(tmp_path)


def test_a_folder_that_is_not_an_atlas_is_refused(tmp_path, capsys):
    folder = tmp_path / "stuff"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    assert main(["atlas", "--axis", "sensor.p_D=0.5,0.6", "--out", str(folder)]) == 2
    assert "holds no atlas" in capsys.readouterr().err
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
    assert main(["atlas", "--out", str(folder)]) == 2  # nothing to resume
    assert "not an atlas to resume" in capsys.readouterr().err
    (folder / "atlas.json").write_text("[1, 2]")
    assert main(["query", str(folder), "SELECT 1"]) == 2
    assert "is not an atlas folder" in capsys.readouterr().err
