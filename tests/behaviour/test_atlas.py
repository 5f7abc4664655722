"""An atlas end to end with real trials (docs/user-guide/atlas.md): one SUMO run per trial and scene variant, the same
rows as a plain run of a point's configuration, the same dataset on the process pool and on a Dask cluster reached
through its TCP address, resumable chunk by chunk, queried with SQL, reported with phase diagrams."""

from __future__ import annotations

import dataclasses
import os

import pyarrow.parquet as pq
import pytest

from soabench.cli.main import main
from soabench.config import Config
from soabench.experiment.campaigns.atlas import store
from soabench.experiment.campaigns.atlas.design import make_design, parse_axis
from soabench.experiment.campaigns.atlas.run import AtlasRequest, run_atlas
from soabench.experiment.execution.options import RunOptions

pytestmark = pytest.mark.slow

AXES = ("pedestrians.count=3,5", "experiment.clutter=0.5,3")


def _request(out, trials=2, explicit=()) -> AtlasRequest:
    cfg = Config()
    cfg.experiment = dataclasses.replace(
        cfg.experiment, trials=trials, duration=8.0, models=("soa", "pubm"), probabilities=("static",)
    )
    design = make_design([parse_axis(a) for a in AXES])
    return AtlasRequest(out=out, net="intersection", design=design, config=cfg, explicit=set(explicit))


def _dataset(root, table="trials"):
    """The table's rows without the wall-clock columns, in a fixed order."""
    t = pq.read_table(root / table).to_pandas()
    t = t[[c for c in t.columns if not c.startswith("t_")]]
    return t.sort_values(["point", "trial", "model", "mode"]).reset_index(drop=True)


@pytest.fixture(scope="module")
def pool_atlas(tmp_path_factory):
    root = tmp_path_factory.mktemp("atlas") / "pool"
    o = run_atlas(_request(root), RunOptions(workers=2, progress=False))
    return root, o


def test_atlas_shares_one_sumo_run_per_trial_and_variant(pool_atlas):
    root, o = pool_atlas
    assert o.complete and o.n_done == 8 and o.n_missing == 0
    # 2 scene variants (pedestrians) x 2 trials: 4 SUMO runs; the second clutter rate of a variant reuses it
    assert o.shared["recording"] == 4 and o.shared["recording_reused"] == 4
    # the session's 4 chunks (trial x scene variant), compacted into one part per table
    assert sorted(p.name for p in (root / "trials").iterdir()) == ["part-00000.parquet"]
    assert store.part_chunks(root / "trials" / "part-00000.parquet") == {(0, 0), (0, 1), (1, 0), (1, 1)}
    rows = _dataset(root)
    assert len(rows) == 8 * 2  # points x trials x models
    assert set(rows["pedestrians_count"]) == {3, 5} and set(rows["experiment_clutter"]) == {0.5, 3.0}
    assert (rows["clutter"] == rows["experiment_clutter"]).all() and set(rows["family"]) == {"gmphd"}
    assert {"hota", "ospa", "delay_mean", "sumo_seed"} <= set(rows.columns)
    assert len(_dataset(root, "episodes")) > 0


def test_a_point_equals_a_plain_run_of_its_configuration(pool_atlas, tmp_path):
    """Common random numbers: the atlas's point (5 pedestrians, λ = 3) gives the rows of `soabench run` with that
    scenario and clutter rate."""
    root, _ = pool_atlas
    out = tmp_path / "run"
    scen = root / "scenes" / "s0001.scenario.toml"
    argv = ["run", "--scenario", str(scen), "--trials", "2", "--duration", "8", "--models", "soa,pubm"]
    argv += ["--probabilities", "static", "--clutter", "3", "--workers", "1", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    import pandas as pd

    plain = pd.read_csv(out / "trials.csv").sort_values(["trial", "model"]).reset_index(drop=True)
    rows = _dataset(root)
    mine = rows[(rows["pedestrians_count"] == 5) & (rows["experiment_clutter"] == 3.0)]
    mine = mine.sort_values(["trial", "model"]).reset_index(drop=True)
    for col in ("trial", "sumo_seed", "model", "delay_mean", "card_err", "ospa", "n_episodes", "hota"):
        assert mine[col].tolist() == plain[col].tolist() or (
            mine[col].astype(float).fillna(-1).tolist() == plain[col].astype(float).fillna(-1).tolist()
        ), col


def test_dask_cluster_by_tcp_address_gives_the_same_dataset(pool_atlas, tmp_path):
    from local_dask import local_cluster

    root, _ = pool_atlas
    with local_cluster(2) as address:
        assert address.startswith("tcp://")
        o = run_atlas(_request(tmp_path / "dask"), RunOptions(scheduler=address, progress=False))
    assert o.complete
    for table in ("trials", "episodes"):
        a, b = _dataset(root, table), _dataset(tmp_path / "dask", table)
        assert a.equals(b), table


def test_extending_runs_only_the_new_trials_and_query_report(pool_atlas, tmp_path, capsys):
    root, _ = pool_atlas
    grown = tmp_path / "grown"
    first = _request(grown, trials=1)
    first.report = False
    assert run_atlas(first, RunOptions(workers=1, progress=False)).complete
    kept = {p.name: p.stat().st_mtime_ns for p in (grown / "trials").iterdir()}
    more = _request(grown, trials=2, explicit={"experiment.trials"})
    more.report = False
    o = run_atlas(more, RunOptions(workers=1, progress=False))
    assert o.complete and o.shared["recording"] == 2  # trial 1 of each scene variant, nothing else
    assert all((grown / "trials" / n).stat().st_mtime_ns == t for n, t in kept.items())
    assert _dataset(grown).equals(_dataset(root))  # the same seeds: the atlas made at once
    # the report and the query read the dataset
    assert (root / "report" / "index.html").is_file() and (root / "report" / "cells.csv").is_file()
    assert any(p.suffix == ".png" for p in (root / "report").iterdir())
    sql = "SELECT count(*) AS n FROM trials t JOIN points p USING (point) WHERE p.pedestrians_count = 3"
    assert main(["query", str(root), sql]) == 0
    assert "8" in capsys.readouterr().out
    assert not os.path.exists(grown / "failures") or not list((grown / "failures").iterdir())


def test_the_results_part_is_kept_when_complete_and_extended_with_more_trials(tmp_path, monkeypatch):
    import fake_trial as ft

    from soabench.experiment.campaigns import results_suite as rs

    monkeypatch.setattr(rs, "ATLAS_AXES", {"pedestrians.count": (3, 6), "experiment.clutter": (0.5, 3.0)})
    part, log = tmp_path / "atlas" / "intersection", []
    exe = RunOptions(workers=1, progress=False)
    with ft.as_builtins():
        s = rs.Settings(duration=10.0, atlas_trials=2)
        assert rs._atlas_part(part, "intersection", s, exe, log.append) == ("done", 0)
        files = {p: p.stat().st_mtime_ns for p in part.rglob("*.parquet")}
        assert rs._atlas_part(part, "intersection", s, exe, log.append) == ("kept", 0)
        assert {p: p.stat().st_mtime_ns for p in part.rglob("*.parquet")} == files
        more = dataclasses.replace(s, atlas_trials=3)
        assert rs._atlas_part(part, "intersection", more, exe, log.append) == ("done", 0)
    assert len(store.done_chunks(part)) == 3 * 2  # trials x scene variants
    assert len(list((part / "trials").iterdir())) == 2  # a part per session that ran trials
    assert all(p.stat().st_mtime_ns == t for p, t in files.items())  # the first chunks were not written again
    assert (part / "report" / "summary.md").is_file()
