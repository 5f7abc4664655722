"""The filter families of a campaign's runs, and the per-family sections of its reports (docs/user-guide/outputs.md
"Filter families")."""

from __future__ import annotations

from soabench.config import FILTER_FAMILIES, Config, family_label


def config_families(config: dict) -> list[str | None]:
    """The filter families of a run's configuration (as stored, read through :class:`~soabench.config.Config`) in
    its order; ``[None]`` for the GM-PHD alone (the default, whose tables have no ``filter`` column and whose reports
    have no per-family sections)."""
    named = tuple(Config.from_record(config).experiment.filters)
    return [None] if named == FILTER_FAMILIES[:1] else list(named)


def family_heading(family: str | None) -> list[str]:
    """The Markdown heading of one filter family's section (none for a run without families)."""
    return [] if family is None else ["", f"## {family_label(family)}"]


def first_family_note(families: list[str | None]) -> str:
    """What a campaign's figure draws when its runs hold several filter families: the first family."""
    return "" if len(families) < 2 or families[0] is None else f" ({family_label(families[0])} family)"


def paper_family_rows(rows: list[dict]) -> list[dict]:
    """The trials.csv rows of the paper's filter family, the GM-PHD (every row of a run without a ``filter``
    column): the comparisons with the paper and the sensitivity of its headline numbers are made in it."""
    return [r for r in rows if r.get("filter", FILTER_FAMILIES[0]) == FILTER_FAMILIES[0]]


def family_rows(rows: list[dict], family: str | None) -> list[dict]:
    """The trials.csv rows of filter family ``family`` (every row for None: a run without a ``filter`` column)."""
    return rows if family is None else [r for r in rows if r.get("filter") == family]
