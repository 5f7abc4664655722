"""A run's report page (soabench/experiment/reports/html.py) shows what it reads as text: HTML is escaped."""

from __future__ import annotations

from soabench.experiment.reports.html import markdown_html


def test_report_escapes_what_it_reads() -> None:
    out = markdown_html("# a <script>x</script>\n\n| a | b |\n|---|---|\n| <img src=x onerror=y> | `c` |\n")
    assert "<script>" not in out and "<img" not in out and "&lt;img" in out and "<code>c</code>" in out
