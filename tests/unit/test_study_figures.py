"""Which run folders of a study draw figures: the main run and the clutter sweep always; the N̂ sweep's points and
the sensitivity runs only with ``--all-figures`` (``sweep_births.png`` and ``sensitivity.md`` summarise them)."""

from __future__ import annotations

from pathlib import Path

import pytest

from soabench.cli.main import main


@pytest.fixture
def drawn(monkeypatch, fake_builtins) -> dict[str, bool]:
    """Fake trials and scenes; every report's folder (relative to the study) -> whether it drew figures."""
    import soabench.experiment.campaigns.study as study
    import soabench.experiment.reports.report as report

    monkeypatch.setattr(study, "paper_protocol_mismatch", lambda meta: "fake trials")
    calls: dict[str, bool] = {}
    real = report.write_report

    def write_report(run_dir, figures=True, store=None):  # the real summaries, without drawing
        calls[str(Path(run_dir))] = figures
        return real(run_dir, figures=False, store=store)

    monkeypatch.setattr(report, "write_report", write_report)
    return calls


@pytest.mark.slow
@pytest.mark.parametrize("all_figures", [False, True])
def test_study_draws_the_figures_of_the_folders_it_does_not_summarise(tmp_path, drawn, all_figures):
    out = tmp_path / "study"
    argv = ["study", "--trials", "1", "--births-trials", "1", "--duration", "10", "--workers", "1", "--no-progress"]
    assert main([*argv, "--out", str(out), *(["--all-figures"] if all_figures else [])]) == 0
    rel = {str(Path(d).relative_to(out)): f for d, f in drawn.items()}
    assert rel["main"] is True and rel["clutter/points/clutter"] is True
    summarised = [d for d in rel if d.startswith(("births/points/", "sensitivity/"))]
    assert len([d for d in summarised if d.startswith("births/")]) == 16  # N_tot = N_true + (-10..10), clipped at 1
    assert sorted(d for d in summarised if d.startswith("sensitivity/")) == [
        "sensitivity/gate_off",
        "sensitivity/visible",
    ]
    assert all(rel[d] is all_figures for d in summarised), rel
