"""``python -m soabench`` is the same program as the ``soabench`` console script (docs/user-guide/install.md)."""

from __future__ import annotations

import subprocess
import sys

from soabench import __version__


def _python_m(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "soabench", *args], capture_output=True, text=True, timeout=120)


def test_python_m_soabench_runs_the_command_line() -> None:
    proc = _python_m("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"soabench {__version__}"
    proc = _python_m("scenes")
    assert proc.returncode == 0 and "| intersection |" in proc.stdout


def test_python_m_soabench_passes_the_exit_status_on() -> None:
    proc = _python_m("run", "--trials", "0")
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("soabench: error:") and len(proc.stderr.strip().splitlines()) == 1
