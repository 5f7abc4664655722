"""``soabench scenes``: the shipped scenes, what each holds and tests (docs/user-guide/scenes.md)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    sub.add_parser("scenes", help="the shipped scenes: size, lanes, pedestrians, occluders, what each tests")


def handle(args: argparse.Namespace) -> int:
    from soabench.scenario.suite import scenes_table

    print(scenes_table())
    return 0
