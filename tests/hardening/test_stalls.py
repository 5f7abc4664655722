"""No command hangs: a SUMO run that makes no progress stops with one line (soabench.scenario.watchdog), and the
points of an occlusion sweep on a user network keep that network's defaults."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import sumo

from soabench.cli.main import main
from soabench.errors import SoabenchError
from soabench.scenario import load, simulate
from soabench.scenario.simulation import _simulate_here
from soabench.scenario.watchdog import INSERTING, STALL_ENV, STEPPING, Progress, run_watched, stall_timeout
from soabench.seeding import trial_seeds

pytestmark = pytest.mark.slow  # SUMO runs that stall until a watchdog stops them

BIN = Path(sumo.SUMO_HOME) / "bin"
ENV = {**os.environ, "SUMO_HOME": sumo.SUMO_HOME}
RUN = "from soabench.cli.main import main; raise SystemExit(main())"  # the console script, in a child we can time out


def _tool(*args: str) -> None:
    subprocess.run([str(BIN / args[0]), *args[1:], "--no-warnings"], check=True, capture_output=True, env=ENV)


@pytest.fixture(scope="module")
def grid(tmp_path_factory) -> Path:
    """A netgenerate grid with sidewalks: its sidewalks enclose blocks, where SUMO's jupedsim never returns."""
    d = tmp_path_factory.mktemp("grid")
    _tool("netgenerate", "--grid", "--grid.number", "3", "--grid.length", "80", "--sidewalks.guess",
          "--crossings.guess", "-o", str(d / "grid.net.xml"))  # fmt: skip
    (d / "jupedsim.toml").write_text('[pedestrians]\nmodel = "jupedsim"\n')
    return d


@pytest.fixture(scope="module")
def block(tmp_path_factory) -> Path:
    """One block enclosed by sidewalks, with parking lanes (allow="custom1") beside them and an arm at each corner."""
    d = tmp_path_factory.mktemp("block")
    xy = {"a": (0, 0), "b": (100, 0), "c": (100, 100), "d": (0, 100),
          "ao": (-60, 0), "bo": (160, 0), "co": (160, 100), "do": (-60, 100)}  # fmt: skip
    nodes = "".join(f'<node id="{k}" x="{x}" y="{y}" type="priority"/>' for k, (x, y) in xy.items())
    (d / "k.nod.xml").write_text(f"<nodes>{nodes}</nodes>")
    lanes = (
        '<lane index="0" allow="pedestrian" width="3"/><lane index="1" allow="custom1" width="2.2"/>'
        '<lane index="2" disallow="pedestrian custom1"/>'
    )
    ends = [("a", "b"), ("b", "c"), ("c", "d"), ("d", "a"), ("ao", "a"), ("b", "bo"), ("c", "co"), ("do", "d")]
    edges = "".join(
        f'<edge id="{u}{v}" from="{u}" to="{v}" numLanes="3" speed="13.9">{lanes}</edge>'
        f'<edge id="{v}{u}" from="{v}" to="{u}" numLanes="3" speed="13.9">{lanes}</edge>'
        for u, v in ends
    )
    (d / "k.edg.xml").write_text(f"<edges>{edges}</edges>")
    _tool("netconvert", "-n", str(d / "k.nod.xml"), "-e", str(d / "k.edg.xml"), "--crossings.guess",
          "-o", str(d / "block.net.xml"))  # fmt: skip
    return d / "block.net.xml"


def test_watched_run_is_bit_identical_to_an_unwatched_one(tmp_path):
    scene, sc = load("intersection", quiet=True)
    seeds = trial_seeds(0, 3)
    watched = simulate(scene, sc, seeds, duration=3.0)
    here = _simulate_here(scene, sc, seeds, 30, tmp_path, Progress())
    for name, value in vars(here).items():
        other = getattr(watched, name)
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, other, err_msg=name)
        elif name == "static_occluders":
            assert all(np.array_equal(a, b) for a, b in zip(value, other, strict=True))
        else:
            assert value == other, name


def test_stalled_run_stops_with_one_line_and_the_trial_fails(grid, tmp_path):
    """The issue's hang, bounded: jupedsim on a netgenerate grid stalls; the run records failed trials and ends."""
    out = tmp_path / "run"
    args = ["run", "--net", str(grid / "grid.net.xml"), "--scenario", str(grid / "jupedsim.toml"), "--trials", "2",
            "--duration", "3", "--models", "soa", "--workers", "1", "--no-progress", "--out", str(out)]  # fmt: skip
    t0 = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-c", RUN, *args], capture_output=True, text=True, timeout=240, env={**ENV, STALL_ENV: "2"}
    )
    assert time.monotonic() - t0 < 240
    failed = [ln for ln in done.stderr.splitlines() if ln.startswith("trial ")]
    assert len(failed) == 2, done.stderr
    for line in failed:
        assert "made no progress for 2 s while inserting" in line and 'model = "striping"' in line
    assert "0 of 2 trials succeeded, 2 failed" in (out / "summary.md").read_text()


def test_scene_command_on_a_stalling_net_exits_2(grid, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(STALL_ENV, "1.5")
    args = ["scene", "--net", str(grid / "grid.net.xml"), "--scenario", str(grid / "jupedsim.toml"), "--time", "2"]
    rc = main([*args, "--out", str(tmp_path / "s.png")])
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "derived" not in ln]
    assert rc == 2 and len(err) == 1 and "made no progress for 1.5 s" in err[0] and STALL_ENV in err[0]


def test_user_net_defaults_to_striping_and_simulates(grid):
    scene, sc = load(str(grid / "grid.net.xml"), quiet=True)
    assert sc.pedestrian_model == "striping"
    assert simulate(scene, sc, trial_seeds(0, 0), duration=2.0).ped_present.any()


@pytest.mark.parametrize("text", ["0", "-3", "soon", "nan"])
def test_bad_stall_limit_is_one_line(monkeypatch, text):
    monkeypatch.setenv(STALL_ENV, text)
    with pytest.raises(SoabenchError, match=STALL_ENV):
        stall_timeout()


def test_occlusion_sweep_on_net_without_parking_lanes_refused_up_front(grid, tmp_path, capsys):
    out = tmp_path / "sw"
    args = ["sweep", "occlusion", "--net", str(grid / "grid.net.xml"), "--values", "0,4", "--trials", "2",
            "--duration", "20", "--models", "soa", "--workers", "1", "--no-progress", "--out", str(out)]  # fmt: skip
    rc = main(args)
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "derived" not in ln]
    assert rc == 2 and len(err) == 1 and "no parking lanes" in err[0] and "density 4 " in err[0]
    assert not out.exists()


def test_occlusion_sweep_on_user_net_keeps_its_defaults_and_says_each_derivation_once(block, tmp_path, capfd):
    """Each point's generated scenario keeps the user net's striping (jupedsim fails on this block), and the pool's
    workers do not repeat the driver's "derived ... parked cars" line."""
    out = tmp_path / "sw"
    args = ["sweep", "occlusion", "--net", str(block), "--values", "0,4", "--trials", "2", "--duration", "3",
            "--models", "soa", "--workers", "2", "--no-progress", "--out", str(out)]  # fmt: skip
    assert main(args) == 0
    for toml in sorted((out / "points").glob("*.scenario.toml")):
        assert 'model = "striping"' in toml.read_text()
    err = capfd.readouterr().err
    for density in ("0 per 100 m", "4 per 100 m"):
        assert sum(density in ln for ln in err.splitlines()) == 1, err
    _sweep_figure_has_error_bars(out)


def _sweep_figure_has_error_bars(sweep_dir: Path) -> None:
    """sweep_occlusion.png: every panel draws each series with error bars (95 % CI over trials, said in the legend)."""
    import json

    from matplotlib.container import ErrorbarContainer

    from soabench.experiment.campaigns.occlusion import occlusion_report
    from soabench.figures.occlusion import occlusion_figure

    meta = json.loads((sweep_dir / "sweep.json").read_text())
    report, _ = occlusion_report(sweep_dir, meta)
    fig = occlusion_figure(sweep_dir, meta["points"], report["table"])
    assert "95% CI over trials" in fig.legends[0].get_title().get_text()
    for ax in fig.axes:
        bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
        assert len(bars) == 2  # S-OA static and dynamic
        segments = [seg for c in bars for seg in c.lines[2][0].get_segments()]
        assert len(segments) == 4 and any(abs(seg[1, 1] - seg[0, 1]) > 0 for seg in segments)


def _beating(seconds: float, progress: Progress) -> str:
    for i in range(int(seconds / 0.05)):
        time.sleep(0.05)
        progress.beat(STEPPING, 0.1 * i)
    return "done"


def _silent(progress: Progress) -> None:
    progress.beat(INSERTING)
    time.sleep(60)


def _crashing(progress: Progress) -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def test_watchdog_tells_slow_progress_from_a_stall(monkeypatch):
    """Progress resets the clock (1.5 s of work under a 0.5 s limit returns); silence stops the child in bounded
    time with the phase it stood in; a crash becomes one line too; an error keeps its message."""
    monkeypatch.setenv(STALL_ENV, "0.5")
    assert run_watched(_beating, (1.5,), "work") == "done"
    t0 = time.monotonic()
    with pytest.raises(SoabenchError, match=r"^work made no progress for 0.5 s while inserting .*; try less"):
        run_watched(_silent, (), "work", hint="try less")
    assert time.monotonic() - t0 < 5
    with pytest.raises(SoabenchError, match="work stopped without a result .*signal SIGKILL"):
        run_watched(_crashing, (), "work")
    with pytest.raises(SoabenchError, match="^bad input$"):
        run_watched(lambda progress: (_ for _ in ()).throw(SoabenchError("bad input")), (), "work")
