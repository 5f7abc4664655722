"""The filter-family seam (docs/development.md "Adding a filter family"): every registry line resolves to a builder,
names a Config section that exists and modes that exist; every family runs every built-in birth model through the
neutral tracker and gives one label per estimate; the trial builds its filters from the registry."""

from __future__ import annotations

import argparse
import dataclasses
import re

import numpy as np
import pytest

import soabench.api as sb
from soabench.cli.common import config_from_args
from soabench.config import FAMILIES, FILTER_FAMILIES, PROBABILITY_MODES, Config
from soabench.errors import SoabenchError
from soabench.plugins import BUILTIN_BIRTH_MODELS
from soabench.protocols import Filter
from soabench.trackers import FilterTracker, build_filter, family_builder

NET = "intersection"


def test_every_registry_line_is_complete() -> None:
    assert FILTER_FAMILIES[0] == "gmphd"  # the default family of every run
    sections = {f.name for f in dataclasses.fields(Config)}
    for name, fam in FAMILIES.items():
        assert fam.name == name and fam.label and fam.modes
        assert set(fam.modes) <= set(PROBABILITY_MODES), name
        assert callable(family_builder(name)), name
        assert fam.section is None or fam.section in sections, name


@pytest.fixture(scope="module")
def scans():
    return sb.simulate_trial(NET, seed=1, trial=0, duration=15)[1]


@pytest.mark.parametrize("family", FILTER_FAMILIES)
def test_every_family_runs_every_builtin_birth_model(scans, family) -> None:
    cfg = Config.from_dict({"experiment": {"filters": [family], "probabilities": ["static"]}}).validate()
    labelled = 0
    for model in BUILTIN_BIRTH_MODELS:
        tracker = sb.make_tracker(model, NET, config=cfg)
        assert isinstance(tracker, FilterTracker) and tracker.name == family
        assert isinstance(tracker.filt, Filter)
        for scan in scans:
            res = tracker.step(scan)
            assert res.labels is not None and len(res.labels) == len(res.X), (family, model)
            assert np.isfinite(res.X).all()
            labelled += len(res.labels)
    assert labelled > 0  # some estimate was made and labelled in the family


def test_build_filter_refuses_what_the_registry_does_not_define() -> None:
    cfg = Config().validate()
    with pytest.raises(SoabenchError, match="filter family 'kf' is not allowed; choose one of gmphd, lmb"):
        build_filter("kf", cfg, cfg.sensor_at(), "static")
    undefined = [(name, m) for name, f in FAMILIES.items() for m in PROBABILITY_MODES if m not in f.modes]
    for name, mode in undefined:
        with pytest.raises(SoabenchError, match=re.escape(f"probability mode '{mode}' is not defined for the")):
            build_filter(name, cfg, cfg.sensor_at(), mode)
    filt, p_D_b = build_filter("gmphd", cfg, cfg.sensor_at(), "dynamic")
    assert filt.name == "gmphd" and filt.mode == "dynamic" and p_D_b == cfg.filter.mu_D0


def test_a_family_section_is_refused_unless_the_family_runs() -> None:
    for fam in FAMILIES.values():
        if fam.section is None:
            continue
        section = getattr(Config(), fam.section)
        key = dataclasses.fields(section)[0]
        value = getattr(section, key.name)
        changed = value / 2 if isinstance(value, float) else value + 1
        with pytest.raises(
            SoabenchError, match=rf"{fam.section}.{key.name} = .* runs no [^;]*\b{fam.label}\b[^;]* filter"
        ):
            Config.from_dict({fam.section: {key.name: changed}}).validate()
        cfg = Config.from_dict(
            {
                fam.section: {key.name: changed},
                "experiment": {"filters": ["gmphd", fam.name], "probabilities": ["static"]},
            }
        ).validate()
        assert cfg.to_dict()[fam.section][key.name] == changed
        assert fam.section not in Config().to_dict()  # a run without the family records no section


def test_a_family_section_in_the_config_file_is_read_when_a_flag_names_the_family(tmp_path) -> None:
    path = tmp_path / "ablation.toml"
    path.write_text('[lmb]\nbirth_mapping = "components"\n', encoding="utf-8")
    cfg = config_from_args(argparse.Namespace(config=str(path), filters=("lmb",), probabilities=("static",)))
    assert cfg.experiment.filters == ("lmb",) and cfg.lmb.birth_mapping == "components"
    with pytest.raises(SoabenchError, match=r"lmb.birth_mapping = 'components' is set .* runs no LMB filter"):
        config_from_args(argparse.Namespace(config=str(path), filters=("gmphd",)))
    with pytest.raises(SoabenchError, match="runs no LMB filter"):  # neither the file nor a flag names it
        config_from_args(argparse.Namespace(config=str(path)))


@pytest.mark.parametrize("family", FILTER_FAMILIES)
def test_static_occ_is_static_probabilities_with_the_line_of_sight(scans, family) -> None:
    """``static+occ`` (docs/method.md §4.6) is every family's static mode with the p_D of §4.4: the same steps as the
    static filter built with ``filter.occlusion_pd = true``, and not those of the plain static mode."""
    assert "static+occ" in FAMILIES[family].modes
    cfg = Config.from_dict({"experiment": {"filters": [family], "probabilities": ["static"]}}).validate()
    occ = Config.from_dict({"experiment": {"filters": [family]}, "filter": {"occlusion_pd": True}}).validate()
    runs = {}
    for name, c, mode in (("occ", cfg, "static+occ"), ("flag", occ, "static"), ("plain", cfg, "static")):
        tracker = sb.make_tracker("soa", NET, config=c, mode=mode, filter=family)
        assert tracker.p_D_b == cfg.filter.p_D
        runs[name] = [tracker.step(scan) for scan in scans]
    for a, b in zip(runs["occ"], runs["flag"], strict=True):
        assert np.array_equal(a.X, b.X) and np.array_equal(a.labels, b.labels) and a.sum_w == b.sum_w
    assert any(a.sum_w != b.sum_w for a, b in zip(runs["occ"], runs["plain"], strict=True))
