"""``soabench query PATH "SQL"``: SQL (DuckDB, embedded) over an atlas or any run folder."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "query",
        help="SQL over an atlas or a run folder (tables trials, episodes, steps; points for an atlas) with DuckDB",
    )
    p.add_argument("path", type=Path, help="an atlas folder, a run folder, or a folder holding run folders")
    p.add_argument("sql", help='the query, e.g. "SELECT model, avg(ospa) FROM trials GROUP BY model"')
    p.add_argument(
        "--out", type=Path, metavar="FILE", help="write the result to FILE.csv or FILE.parquet (default: print a table)"
    )


def handle(args: argparse.Namespace) -> int:
    from soabench.experiment.campaigns.atlas.query import format_table, run_query, write_result
    from soabench.folders import check_out_file

    if args.out is not None:
        check_out_file(str(args.out))
    table = run_query(args.path, args.sql)
    if args.out is not None:
        write_result(table, args.out)
        print(f"{table.num_rows} row(s) in {args.out}")
    else:
        print(format_table(table))
    return 0
