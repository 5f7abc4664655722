"""Run folders merged on the workers of a process pool (:mod:`soabench.experiment.reports.premerge`).

* a grouped N̂ sweep on two workers (each point merged by a worker, its figure tables saved there) writes the files
  of the same sweep on one process, byte for byte: tables, model failures and every figure;
* the driver adopts a worker's merge only while the folder is as the worker left it;
* the figure list asks steps.csv for its columns without parsing the file.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from soabench.config import Config, ExperimentConfig
from soabench.experiment.campaigns.sweep import run_sweep
from soabench.experiment.execution.options import RunOptions
from soabench.experiment.reports import premerge
from soabench.experiment.reports.tables import load_tables
from soabench.experiment.runs.store import RunStore, merged_stamp

pytestmark = pytest.mark.slow  # merges on a process pool

POINTS = ("ntot_001", "ntot_002")
COMPARED = ("trials.csv", "episodes.csv", "steps.csv", "model_failures.csv")


def config(**exp) -> Config:
    base = dict(models=("soa", "pubm"), probabilities=("static",), clutter=(3.0,), seed=5, trials=2, duration=6.0)
    return Config(experiment=ExperimentConfig(**{**base, **exp})).validate()


def _files(pdir: Path) -> dict[str, bytes]:
    out = {name: (pdir / name).read_bytes() for name in COMPARED}
    out.update({f"figures/{p.name}": p.read_bytes() for p in sorted((pdir / "figures").glob("*.png"))})
    return out


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
    """The same grouped N̂ sweep with figures on two workers and on one process; the folders the driver adopted."""
    root = tmp_path_factory.mktemp("premerge")
    adopted: list[str] = []
    adopt = RunStore.adopt_merge

    def spy(self, done, failures):
        adopted.append(self.run_dir.name)
        adopt(self, done, failures)

    mp = pytest.MonkeyPatch()
    mp.setattr(RunStore, "adopt_merge", spy)
    try:

        def sweep(name: str, workers: int) -> None:
            options = RunOptions(workers=workers, progress=False, figures=True)
            run_sweep("births", (-1, 0), config(), "intersection", out=root / name, options=options, n_true=2)

        sweep("pool", 2)
        pool_adopted = list(adopted)
        sweep("serial", 1)
    finally:
        mp.undo()
    return root, pool_adopted, adopted[len(pool_adopted) :]


def test_points_merged_on_workers_write_the_serial_files(sweeps):
    root, pool_adopted, serial_adopted = sweeps
    assert sorted(pool_adopted) == list(POINTS)  # both points were merged by a worker, not again by the driver
    assert serial_adopted == []  # one process: nothing to adopt
    for p in POINTS:
        pool, serial = _files(root / "pool" / "points" / p), _files(root / "serial" / "points" / p)
        assert any(k.startswith("figures/") for k in serial), p
        assert pool.keys() == serial.keys(), p
        for name in serial:
            assert pool[name] == serial[name], (p, name)
    assert (root / "pool" / "sweep.md").read_text() == (root / "serial" / "sweep.md").read_text()


def test_a_worker_merge_is_adopted_only_while_the_folder_is_unchanged(sweeps, monkeypatch):
    root, _, _ = sweeps
    pdir = root / "serial" / "points" / POINTS[0]
    store = RunStore(pdir)
    done = tuple(store.done_trials())
    models, modes = ("soa", "pubm"), ("static",)
    merges: list[Path] = []
    real = RunStore.merge

    def counted(self, *a):
        merges.append(self.run_dir)
        return real(self, *a)

    monkeypatch.setattr(RunStore, "merge", counted)
    fake = {"failures": ({"trial": 0, "model": "x"},), "counts": {"trials": -1}}

    premerge._MERGED[premerge.folder_key(pdir)] = premerge.Merged(merged_stamp(pdir), done, **fake)
    assert premerge.merge(store, models, modes) == {"trials": -1}  # adopted: the recorded counts, no merge here
    assert merges == [] and store.model_failures() == [{"trial": 0, "model": "x"}]
    assert premerge.merge(store, models, modes)["trials"] == 4  # used once: then merged (2 trials x 2 models)
    assert merges == [pdir]

    before = merged_stamp(pdir)
    (pdir / "steps.csv").write_bytes((pdir / "steps.csv").read_bytes())  # the same bytes, a new modification time
    assert merged_stamp(pdir) != before
    premerge._MERGED[premerge.folder_key(pdir)] = premerge.Merged(before, done, **fake)
    assert premerge.merge(store, models, modes)["trials"] == 4  # changed since the worker's merge: merged again
    premerge._MERGED[premerge.folder_key(pdir)] = premerge.Merged(merged_stamp(pdir), done[:1], **fake)
    assert premerge.merge(store, models, modes)["trials"] == 4  # other finished trials: merged again
    assert len(merges) == 3 and not premerge._MERGED


def test_step_columns_are_known_from_the_header(sweeps):
    root, _, _ = sweeps
    tables = load_tables(root / "serial" / "points" / POINTS[0])
    assert "ospa" in tables.steps and "no such column" not in tables.steps
    assert tables.steps._columns is None  # the file was not parsed
    assert sorted(tables.steps) == sorted(tables.steps.columns)  # the header names what parsing gives
