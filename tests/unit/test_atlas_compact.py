"""An atlas's compaction into parts (docs/user-guide/atlas.md, "The atlas folder"), with the fast fake trial: the
same rows before and after, a compaction killed at any moment leaves a valid dataset, a resumed or extended atlas
never runs or writes a chunk twice."""

from __future__ import annotations

import fake_trial as ft
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from soabench.cli.main import main
from soabench.experiment.campaigns.atlas import compact as compaction
from soabench.experiment.campaigns.atlas import store
from soabench.experiment.campaigns.atlas.design import make_design, parse_axis
from soabench.experiment.campaigns.atlas.query import run_query
from soabench.experiment.campaigns.atlas.run import AtlasRequest, run_atlas
from soabench.experiment.execution.options import RunOptions

AXES = ("pedestrians.count=3,5", "experiment.clutter=0.5,3")  # 2 scene variants x 2 clutter rates
CHUNKS_2 = {(0, 0), (0, 1), (1, 0), (1, 1)}
SORT = ["point", "trial", "model", "mode"]


def _request(out, trials: int = 2, explicit=()) -> AtlasRequest:
    cfg = ft.small_config(trials=trials, duration=10.0, models=("soa", "pubm"), probabilities=("static",))
    return AtlasRequest(
        out=out, net="intersection", design=make_design([parse_axis(a) for a in AXES]), config=cfg, report=False,
        trial_kind="fake", scene_loader="fake-load", explicit=set(explicit),
    )  # fmt: skip


def _run(req: AtlasRequest, written: list | None = None, monkeypatch=None):
    """``run_atlas`` serially; ``written`` collects the chunks it writes."""
    if written is not None:
        real = store.write_chunk
        monkeypatch.setattr(store, "write_chunk", lambda root, n, s, t: (written.append((n, s)), real(root, n, s, t)))
    return run_atlas(req, RunOptions(workers=1, progress=False), log=lambda m: None)


def _rows(root, table="trials"):
    """The table's rows as every reader sees them (the query layer), without wall-clock columns, in a fixed order."""
    t = run_query(root, f"SELECT * FROM {table}").to_pandas()
    t = t[[c for c in t.columns if not c.startswith("t_")]]
    return t.sort_values([c for c in (*SORT, "target") if c in t.columns]).reset_index(drop=True)


@pytest.fixture(scope="module")
def loose(tmp_path_factory):
    """A finished 2-trial atlas left as chunk files (compaction switched off), and its rows."""
    root = tmp_path_factory.mktemp("compact") / "loose"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(compaction, "compact", lambda root: {})
        assert _run(_request(root)).complete
    assert store.done_chunks(root) == CHUNKS_2 and len(list((root / "trials").iterdir())) == 4
    return root, _rows(root), _rows(root, "episodes")


def _copy(root, tmp_path):
    import shutil

    shutil.copytree(root, tmp_path / "atlas")
    return tmp_path / "atlas"


def test_compaction_keeps_every_row_once_in_one_part_per_table(loose, tmp_path):
    src, trials, episodes = loose
    root = _copy(src, tmp_path)
    assert compaction.compact(root) == {"episodes": 4, "trials": 4}
    for table in ("trials", "episodes"):
        assert [p.name for p in (root / table).iterdir()] == ["part-00000.parquet"]
        assert store.part_chunks(root / table / "part-00000.parquet") == CHUNKS_2
    assert _rows(root).equals(trials) and _rows(root, "episodes").equals(episodes)
    assert store.done_chunks(root) == CHUNKS_2
    assert compaction.compact(root) == {}  # nothing left to compact


def test_a_compaction_killed_while_writing_leaves_the_chunks(loose, tmp_path, monkeypatch):
    src, trials, _ = loose
    root = _copy(src, tmp_path)
    calls = []

    def dies(table, schema):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt  # killed in the middle of the first part
        return compaction_conform(table, schema)

    compaction_conform = compaction.conform
    monkeypatch.setattr(compaction, "conform", dies)
    with pytest.raises(KeyboardInterrupt):
        compaction.compact(root)
    monkeypatch.setattr(compaction, "conform", compaction_conform)
    for table in ("trials", "episodes"):
        names = sorted(p.name for p in (root / table).iterdir())
        assert len(names) == 4 and all(store.CHUNK.match(n) for n in names), names  # no part, no temporary file
    assert _rows(root).equals(trials)


def test_a_compaction_killed_before_removing_its_chunks_counts_no_row_twice(loose, tmp_path, monkeypatch):
    """The part is in place but its chunk files were not removed yet: readers ignore them, the next open removes
    them, and a resumed atlas runs nothing again."""
    src, trials, episodes = loose
    root = _copy(src, tmp_path)
    for table in ("episodes", "trials"):
        _, chunks = store.table_files(root, table)
        compaction.write_part(root / table / store.part_name(0), sorted(chunks.items()))
        assert len(list((root / table).iterdir())) == 5  # the part and the 4 chunk files it holds
    assert _rows(root).equals(trials) and _rows(root, "episodes").equals(episodes)
    assert store.done_chunks(root) == CHUNKS_2
    written: list = []
    o = _run(AtlasRequest(out=root, report=False), written, monkeypatch)
    assert o.complete and written == []
    for table in ("trials", "episodes"):
        assert [p.name for p in (root / table).iterdir()] == ["part-00000.parquet"]
    assert _rows(root).equals(trials)


def test_an_extended_atlas_runs_only_the_new_trials_with_the_same_seeds(loose, tmp_path, monkeypatch):
    """--trials 3 over a compacted 2-trial atlas: only trial 2's chunks run, into a second part; trials 0-1 keep
    their rows, and trial 2 is what a 3-trial atlas made at once has (common random numbers)."""
    src, trials, _ = loose
    root = _copy(src, tmp_path)
    compaction.compact(root)
    written: list = []
    o = _run(_request(root, trials=3, explicit={"experiment.trials"}), written, monkeypatch)
    assert o.complete and sorted(written) == [(2, 0), (2, 1)]
    assert store.read_meta(root)["trials"] == 3
    assert sorted(p.name for p in (root / "trials").iterdir()) == ["part-00000.parquet", "part-00001.parquet"]
    rows = _rows(root)
    assert not rows.duplicated(subset=SORT).any()
    assert rows[rows["trial"] < 2].reset_index(drop=True).equals(trials)
    once = _run(_request(tmp_path / "once", trials=3))
    assert once.complete and _rows(tmp_path / "once").equals(rows)
    written.clear()
    assert _run(_request(root, trials=3, explicit={"experiment.trials"}), written, monkeypatch).complete
    assert written == []  # resumed when complete: nothing runs twice
    assert main(["atlas", "--out", str(root), "--trials", "2", "--no-progress"]) == 2  # fewer trials: refused


def test_an_atlas_made_by_another_checkout_grows_here(loose, tmp_path, monkeypatch):
    """Its scene files name the scene's files where the other checkout had them: every session writes them anew
    from the scene and the variant's keys, so the new trials run on this checkout's files."""
    src, trials, _ = loose
    root = _copy(src, tmp_path)
    scenes = sorted((root / "scenes").glob("*.scenario.toml"))
    assert scenes
    here = {p.name: p.read_text() for p in scenes}
    for p in scenes:
        p.write_text(p.read_text().replace('net = "/', 'net = "/gone/elsewhere/'))
    written: list = []
    o = _run(_request(root, trials=3, explicit={"experiment.trials"}), written, monkeypatch)
    assert o.complete and sorted(written) == [(2, 0), (2, 1)]
    assert {p.name: p.read_text() for p in sorted((root / "scenes").glob("*.scenario.toml"))} == here


def test_unified_schema_promotes_numbers_and_fills_missing_columns(tmp_path):
    (tmp_path / "trials").mkdir()
    a = {"point": [0, 0], "x": [1, 2], "note": [None, None]}
    b = {"point": [1], "x": [0.5], "note": ["text"], "extra": [True]}
    for n, cols in enumerate((a, b)):
        (tmp_path / "trials" / store.chunk_name(n, 0)).write_bytes(store.parquet_bytes(cols))
    part = tmp_path / "trials" / store.part_name(0)
    compaction.write_part(part, sorted(store.table_files(tmp_path, "trials")[1].items()))
    t = pq.read_table(part)
    assert t.schema.field("x").type == pa.float64() and t.schema.field("note").type == pa.string()
    assert t.to_pydict() == {
        "point": [0, 0, 1], "x": [1.0, 2.0, 0.5], "note": [None, None, "text"], "extra": [None, None, True],
    }  # fmt: skip
    assert store.part_chunks(part) == {(0, 0), (1, 0)}
    assert store.decode_chunks(store.encode_chunks([(0, 1), (1, 1), (2, 1), (5, 1), (3, 0)])) == {
        (0, 1), (1, 1), (2, 1), (5, 1), (3, 0),
    }  # fmt: skip


def test_a_part_that_lists_no_chunks_is_refused(tmp_path):
    (tmp_path / "trials").mkdir()
    (tmp_path / "trials" / store.part_name(0)).write_bytes(store.parquet_bytes({"point": [0]}))
    with pytest.raises(Exception, match="is not an atlas part"):
        store.done_chunks(tmp_path)


def test_the_progress_line_counts_chunks(capsys):
    import io

    from soabench.experiment.execution.progress import Progress

    buf = io.StringIO()
    bar = Progress(4, 1, True, label="atlas", stream=buf, unit="chunks")
    bar.update(True)
    assert "atlas: 2/4 chunks (50%)" in buf.getvalue()


def test_no_parking_lanes_all_zero_densities_pass(tmp_path):
    from soabench.experiment.campaigns.occlusion import check_parking_lanes

    check_parking_lanes(str(tmp_path / "not-even-read.net.xml"), [0, 0.0])  # nothing above 0: nothing to check


def test_a_parking_axis_on_a_scene_without_parking_lanes_is_one_line(tmp_path, capsys):
    out = tmp_path / "atlas"
    argv = ["atlas", "--net", "grid_block", "--axis", "parking.density=0,4", "--trials", "1", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "axis parking.density on scene 'grid_block'" in err and "drop the parking.density axis" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_the_results_part_compacts_a_kept_atlas_left_as_chunks(tmp_path, monkeypatch):
    """An atlas made before compaction (chunk files only) is kept by `soabench results` and compacted: the same
    rows, one part per table, its report untouched."""
    from soabench.experiment.campaigns import results_suite as rs

    monkeypatch.setattr(rs, "ATLAS_AXES", {"pedestrians.count": (3, 6), "experiment.clutter": (0.5, 3.0)})
    part, log = tmp_path / "atlas" / "intersection", []
    exe = RunOptions(workers=1, progress=False)
    s = rs.Settings(duration=10.0, atlas_trials=2)
    with ft.as_builtins():
        with monkeypatch.context() as mp:
            mp.setattr(compaction, "compact", lambda root: {})
            assert rs._atlas_part(part, "intersection", s, exe, log.append) == ("done", 0)
        assert len(list((part / "trials").iterdir())) == 4  # chunk files, as before compaction existed
        rows = _rows(part)
        report = {p.name: p.read_bytes() for p in (part / "report").iterdir()}
        assert rs._atlas_part(part, "intersection", s, exe, log.append) == ("kept", 0)
    assert "4 chunks compacted" in log[-1]
    assert [p.name for p in (part / "trials").iterdir()] == ["part-00000.parquet"]
    assert _rows(part).equals(rows)
    assert {p.name: p.read_bytes() for p in (part / "report").iterdir()} == report
