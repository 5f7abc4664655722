"""``soabench replay`` and ``soabench report``: the replay reproduces the run's trial, shows what
``soabench scene --sensor`` shows, and both pages run in a real (headless) browser."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import plugin_fixtures
import pytest

from soabench.cli.main import main

pytestmark = pytest.mark.slow  # real trials and a headless browser

DURATION = 30  # pedestrians of seed 0 enter the sensor's range after about 27 s


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("replay") / "run"
    argv = ["run", "--trials", "2", "--duration", str(DURATION), "--models", "soa,ubm", "--probabilities",
            "static", "--workers", "1", "--no-progress", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def replay_page(run_dir: Path) -> Path:
    out = run_dir.parent / "trial1.html"
    assert main(["replay", str(run_dir), "--trial", "1", "--out", str(out)]) == 0
    return out


def page_data(page: Path) -> dict:
    """The JSON the replay page draws from."""
    text = page.read_text(encoding="utf-8")
    m = re.search(r'<script type="application/json" id="replay-data">(.*?)</script>', text, re.S)
    assert m is not None
    return json.loads(m.group(1))


def scene_sensor_scans(monkeypatch, tmp_path: Path, time: float):
    """The scans ``soabench scene --sensor --trial 1 --time T`` draws (captured at its drawing call)."""
    import soabench.figures.sensor as sp

    seen = {}
    original = sp.draw_sensor_overlay

    def capture(ax, scans, k, cfg):
        seen["scans"], seen["k"] = scans, k
        return original(ax, scans, k, cfg)

    monkeypatch.setattr(sp, "draw_sensor_overlay", capture)
    argv = ["scene", "--sensor", "--trial", "1", "--time", f"{time:g}", "--out", str(tmp_path / "scene.png")]
    assert main(argv) == 0
    return seen["scans"], seen["k"]


def test_a_run_writes_its_report(run_dir: Path) -> None:
    """A plain `soabench run` leaves report.html in its folder: the page to open."""
    from soabench.experiment.reports.html import REPORT_FILE

    text = (run_dir / REPORT_FILE).read_text(encoding="utf-8")
    assert '<meta name="generator" content="soabench report">' in text and "Best and worst trials" in text


def test_replay_reproduces_the_run(replay_page: Path, capsys) -> None:
    data = page_data(replay_page)
    assert data["reproduced"] is True, data["notes"]
    assert [m["name"] for m in data["models"]] == ["soa", "ubm"]
    assert len(data["frames"]) == DURATION  # one scan per second, t = 0 .. DURATION - 1
    assert any(f["peds"] for f in data["frames"]) and any(f["z"] for f in data["frames"])
    assert all(len(f["models"]) == 2 for f in data["frames"])
    # S-OA's births carry its own origins (occlusion 0, semantic 1, FOV 2); UBM's are grid components (3)
    soa_src = {b[5] for f in data["frames"] for b in f["models"][0]["births"]}
    ubm_src = {b[5] for f in data["frames"] for b in f["models"][1]["births"]}
    assert soa_src <= {0, 1, 2} and 0 in soa_src and ubm_src == {3}
    # each pedestrian awaiting initiation names the model's nearest birth term of the scan
    why = [(f, i, w) for f in data["frames"] for i, m in enumerate(f["models"]) for w in m["why"]]
    assert why
    for f, i, (pid, sigmas, metres, source, _, _) in why:
        assert next(p for p in f["peds"] if p[0] == pid)[5][i] == 1 and sigmas >= 0 and metres >= 0
        assert source in {b[5] for b in f["models"][i]["births"]}
    # the labelled GM-PHD's estimates carry track labels: each estimate names one of its model's tracks
    for i, m in enumerate(data["models"]):
        indices = {e[2] for f in data["frames"] for e in f["models"][i]["est"]}
        assert m["tracks"] and indices <= set(range(len(m["tracks"])))


def _truth_rows(scans, k: int) -> dict[str, tuple[float, float]]:
    return {
        str(scans.ped_ids[j]): (round(float(scans.truth_xy[k, j, 0]), 2), round(-float(scans.truth_xy[k, j, 1]), 2))
        for j in np.flatnonzero(scans.present[k])
    }


@pytest.mark.parametrize("k", [DURATION - 1, 10])
def test_frame_shows_what_scene_sensor_shows(replay_page: Path, monkeypatch, tmp_path: Path, k: int) -> None:
    from soabench.geometry import polar_to_world
    from soabench.types import CLUTTER

    frame = page_data(replay_page)["frames"][k]
    scans, ks = scene_sensor_scans(monkeypatch, tmp_path, float(k))
    assert ks == k and frame["k"] == k and frame["t"] == pytest.approx(scans.scans[k].t)
    shown = {p[0]: (p[1], p[2]) for p in frame["peds"] if p[3] in (0, 1, 2)}  # present pedestrians
    assert shown == _truth_rows(scans, k)
    states = {p[0]: p[3] for p in frame["peds"]}
    for j, pid in enumerate(scans.ped_ids):
        if scans.present[k, j]:
            want = 0 if scans.visible[k, j] else (1 if scans.in_fov[k, j] else 2)
            assert states[str(pid)] == want
    ego = scans.scans[k].ego
    assert frame["ego"][:2] == [round(float(ego[0]), 2), round(-float(ego[1]), 2)]
    z = polar_to_world(scans.scans[k].Z, np.asarray(ego, dtype=float))
    want_z = [[round(float(x), 2), round(-float(y), 2), int(s == CLUTTER)] for (x, y), s in
              zip(z.tolist(), scans.source[k].tolist(), strict=True)]  # fmt: skip
    if k == DURATION - 1:
        # the last scan: `scene --sensor` simulated exactly the trial's scans, so every random draw is the trial's
        assert frame["z"] == want_z and len(want_z) > 0
    else:
        # `scene --time T` simulates only up to T: which targets are detected and how many clutter points fall are
        # the trial's, but the noise and the clutter positions are drawn for fewer scans (soabench.sensor.observe
        # draws them for the whole recording), so the measurement values differ
        assert sorted(z[2] for z in frame["z"]) == sorted(z[2] for z in want_z)


def test_nearest_birth_known_answer() -> None:
    from soabench.replay.frames import nearest_birth

    m = np.array([[0.0, 0.0, 0, 0], [10.0, 0.0, 0, 0]])
    P = np.array([np.diag([4.0, 1.0, 1, 1]), np.diag([100.0, 100.0, 1, 1])])
    # (3, 0): 1.5 sigma from the first term (sd 2 m along x), 0.7 from the wide second one 7 m away
    assert nearest_birth((m, P, np.array([1, 0])), np.array([3.0, 0.0])) == [0.7, 7.0, 0, 10.0, -0.0]
    assert nearest_birth((m[:1], P[:1], np.array([1])), np.array([0.0, 2.0])) == [2.0, 2.0, 1, 0.0, -0.0]
    assert nearest_birth((m[:0], P[:0], np.array([], dtype=int)), np.array([0.0, 0.0])) is None


def test_replay_scans_equal_scene_sensor_arrays(run_dir: Path, monkeypatch, tmp_path: Path) -> None:
    """The replay's own arrays (not only the rounded page data) equal `scene --sensor`'s on the last scan."""
    from soabench.replay import replay_trial

    rep = replay_trial(run_dir, 1, ("soa",))
    k = DURATION - 1
    scans, _ = scene_sensor_scans(monkeypatch, tmp_path, float(k))
    np.testing.assert_array_equal(rep.scans.truth_xy[k], scans.truth_xy[k])
    np.testing.assert_array_equal(rep.scans.scans[k].Z, scans.scans[k].Z)
    np.testing.assert_array_equal(rep.scans.source[k], scans.source[k])
    for flag in ("present", "in_fov", "visible", "detected"):
        np.testing.assert_array_equal(getattr(rep.scans, flag)[k], getattr(scans, flag)[k])


def test_replay_videos(run_dir: Path, tmp_path: Path) -> None:
    """--out picks the format by its ending: an MP4 (read back with ffmpeg) and a GIF of one frame per scan."""
    import imageio_ffmpeg
    from PIL import Image

    mp4, gif = tmp_path / "t0.mp4", tmp_path / "t0.gif"
    argv = ["replay", str(run_dir), "--trial", "0", "--models", "soa,ubm", "--out", str(mp4), "--out", str(gif)]
    assert main(argv) == 0
    reader = imageio_ffmpeg.read_frames(str(mp4))
    meta = reader.__next__()
    frames = [np.frombuffer(f, dtype=np.uint8) for f in reader]
    w, h = meta["size"]
    assert len(frames) == DURATION and meta["fps"] == 5.0  # 1 s scans at 5x real time
    # two panels side by side filling 720p at least, a title line above and the legend below, to multiples of 16 px
    assert w == 1280 and h % 16 == 0 and 720 <= h < 800, (w, h)
    assert all(f.size == w * h * 3 for f in frames)
    last = frames[-1].reshape(h, w, 3)
    assert len(np.unique(last.reshape(-1, 3) // 16, axis=0)) > 10  # a drawn frame, not a blank one
    with Image.open(gif) as img:
        assert img.n_frames == DURATION and img.info["duration"] == 200 and img.size == (w, h)
    assert not list(tmp_path.glob(".*part*"))  # no temporary file left
    assert main(["replay", str(run_dir), "--trial", "0", "--out", str(tmp_path / "t0.png")]) == 2


def test_mp4_without_its_extra_says_how_to_install(run_dir: Path, tmp_path: Path, monkeypatch, capsys) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # as if not installed: the import fails
    assert main(["replay", str(run_dir), "--trial", "0", "--out", str(tmp_path / "t.mp4")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'soabench[video]'" in err, err
    assert list(tmp_path.iterdir()) == []


class _Labelled:
    """A scan result with track labels beside its estimates (a tracker that keeps identities)."""

    def __init__(self, result, labels) -> None:
        self.result, self.labels = result, labels

    def __getattr__(self, name: str):
        return getattr(self.result, name)


@pytest.fixture(scope="module")
def labelled_page(run_dir: Path) -> tuple[Path, dict, list[list[str]]]:
    """Trial 1's replay with each estimate labelled by its nearest truth pedestrian (a stand-in tracker's ids)."""
    from soabench.replay import replay_data, replay_trial, write_replay

    rep = replay_trial(run_dir, 1, ("soa",))
    scans, model, given = rep.scans, rep.models[0], []
    for k, res in enumerate(model.results):
        X = np.asarray(res.X)[:, :2]
        truth = np.where(scans.present[k][:, None], scans.truth_xy[k], np.inf)
        near = [int(np.argmin(np.linalg.norm(truth - x, axis=1))) for x in X]
        given.append([f"trk-{scans.ped_ids[j]}" for j in near])
        model.results[k] = _Labelled(res, np.array(given[-1], dtype=object))
    page = run_dir.parent / "labelled.html"
    data = replay_data(rep)
    write_replay(data, page)
    return page, data, given


def test_track_labels_keep_one_colour_per_label(labelled_page) -> None:
    _, data, given = labelled_page
    tracks = data["models"][0]["tracks"]
    assert tracks and len(tracks) == len(set(tracks))
    shown = [[tracks[e[2]] for e in f["models"][0]["est"]] for f in data["frames"]]
    assert shown == given and sum(map(len, given)) >= 3  # every estimate keeps its own label, index = colour


def test_a_whole_tracker_is_replayed_with_its_track_labels(tmp_path: Path) -> None:
    """A run's tracker (not a birth model) gets its panel, without birth terms; the labels of its Estimates (set
    whether or not Estimates declares the field) are shown, one colour per label."""
    run = tmp_path / "run"
    argv = ["run", "--trials", "1", "--duration", "30", "--models", "soa", "--trackers",
            "plugin_fixtures:LabelledEchoTracker", "--probabilities", "static", "--workers", "1", "--no-progress",
            "--out", str(run)]  # fmt: skip
    assert main(argv) == 0
    page = tmp_path / "t0.html"
    assert main(["replay", str(run), "--trial", "0", "--models", "soa,plugin_fixtures:LabelledEchoTracker",
                 "--out", str(page)]) == 0  # fmt: skip
    data = page_data(page)
    assert data["reproduced"] is True, data["notes"]
    soa, echo = data["models"]
    assert soa["tracks"] and echo["tracks"]  # the labelled GM-PHD and the plugin both label their estimates
    for f in data["frames"]:
        assert f["models"][1]["births"] == [] and f["models"][1]["sum_w"] is None  # a tracker: no births, no mass
        for x, y, i in f["models"][1]["est"]:  # the plugin's label names its 10 m cell; the page's y is the world's -y
            assert int(echo["tracks"][i]) // 100 == plugin_fixtures.cell_code(x, -y)
    k = max(range(len(data["frames"])), key=lambda i: len(data["frames"][i]["models"][1]["est"]))
    attrs = body_attrs(browse(page, f"#frame={k}", tmp_path))
    labelled = sum(len(m["est"]) for m in data["frames"][k]["models"])  # every estimate of both panels is labelled
    assert attrs["status"] == "ok" and attrs["tracks"] == str(labelled), attrs


def test_labels_drawn_in_the_browser_and_the_video(labelled_page, tmp_path: Path) -> None:
    from soabench.replay.animation import TRACK_COLORS, render_frames

    page, data, given = labelled_page
    k = max(range(len(given)), key=lambda i: len(given[i]))
    attrs = body_attrs(browse(page, f"#frame={k}", tmp_path))
    assert attrs["status"] == "ok" and attrs["tracks"] == str(len(given[k])), attrs
    frame = next(render_frames({**data, "frames": [data["frames"][k]]}))
    colour = TRACK_COLORS[data["frames"][k]["models"][0]["est"][0][2] % len(TRACK_COLORS)]
    rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
    assert (np.abs(frame.reshape(-1, 3).astype(int) - rgb).sum(axis=1) < 30).sum() > 20  # the label's colour drawn


def test_a_family_run_is_replayed_in_each_family(tmp_path: Path, capsys) -> None:
    """``--filter`` picks the family a run's birth models are replayed in; each reproduces its own family's rows, the
    page names the family, and a mode the family does not define is refused with one line."""
    run = tmp_path / "run"
    argv = ["run", "--trials", "1", "--duration", "20", "--models", "soa,pubm", "--filters", "gmphd,lmb",
            "--probabilities", "static,dynamic", "--workers", "1", "--no-progress", "--out", str(run)]  # fmt: skip
    assert main(argv) == 0
    for family, label in (("gmphd", "GM-PHD"), ("lmb", "LMB")):
        assert main(["replay", str(run), "--trial", "0", "--filter", family]) == 0
        page = run / "replays" / ("trial_00000.html" if family == "gmphd" else "trial_00000_lmb.html")
        data = page_data(page)
        assert data["reproduced"] is True and data["filter"] == label, data["notes"]
    capsys.readouterr()
    assert main(["replay", str(run), "--trial", "0", "--filter", "lmb", "--mode", "dynamic"]) == 2
    err = capsys.readouterr().err
    assert "--mode 'dynamic' is not defined for the LMB filter; choose from static" in err and err.count("\n") == 1
    assert main(["replay", str(run), "--trial", "0", "--filter", "pf"]) == 2
    assert "--filter 'pf' is not in this run; choose from gmphd, lmb" in capsys.readouterr().err


def test_replay_bad_input(run_dir: Path, tmp_path: Path, capsys) -> None:
    cases = [
        (["replay", str(run_dir), "--trial", "7"], "--trial 7 is not a trial of this run; choose 0 to 1"),
        (
            ["replay", str(run_dir), "--trial", "0", "--models", "gmbm"],
            "'gmbm' is not a birth model or tracker of this run; choose from soa, ubm",
        ),
        (["replay", str(run_dir), "--trial", "0", "--mode", "dynamic"], "--mode 'dynamic' is not in this run"),
        (["replay", str(tmp_path), "--trial", "0"], "is not a run folder"),
        (["report", str(tmp_path)], "is not a run folder"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err


def test_report_page(run_dir: Path, capsys) -> None:
    from soabench.experiment.reports.html import REPLAYS_DIR, REPORT_FILE, extreme_trials

    assert main(["report", str(run_dir), "--replays"]) == 0
    text = (run_dir / REPORT_FILE).read_text(encoding="utf-8")
    n_figures = len(list((run_dir / "figures").glob("*.png")))
    assert n_figures > 0 and text.count('src="data:image/png;base64,') == n_figures
    assert "soabench replay" in text and "Provenance" in text and 'class="sortable"' in text
    # the best and worst trial of each model (by its trials.csv mean delay) link their replay pages
    rows = extreme_trials(run_dir)
    assert {r["model"] for r in rows} == {"soa", "ubm"}
    for r in rows:
        for which in ("best", "worst"):
            trial = r[which][1]
            assert (run_dir / REPLAYS_DIR / f"trial_{trial:05d}.html").is_file()
            assert f'href="{REPLAYS_DIR}/trial_{trial:05d}.html"' in text
    assert main(["report", str(run_dir)]) == 0  # its own page is rewritten


def test_report_leaves_a_foreign_file(run_dir: Path, tmp_path: Path, capsys) -> None:
    foreign = tmp_path / "mine.html"
    foreign.write_text("<p>my notes</p>", encoding="utf-8")
    assert main(["report", str(run_dir), "--out", str(foreign)]) == 2
    assert "was not written by soabench report" in capsys.readouterr().err
    assert foreign.read_text(encoding="utf-8") == "<p>my notes</p>"


# ------------------------------------------------------------------------------------------ in a real browser
def chromium() -> str:
    """The headless browser (Debian's ``chromium``); the browser tests fail, not skip, without it."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.fail("no chromium on PATH: install it (apt-get install chromium) to run the browser tests")
    return exe


def browse(page: Path, fragment: str, tmp_path: Path, screenshot: Path | None = None) -> str:
    """The page's DOM after its scripts ran (headless Chromium, 5 s of virtual time)."""
    what = [f"--screenshot={screenshot}", "--window-size=1300,1000"] if screenshot else ["--dump-dom"]
    argv = [chromium(), "--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars",
            f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=5000", *what,
            f"{page.resolve().as_uri()}{fragment}"]  # fmt: skip
    done = subprocess.run(argv, capture_output=True, text=True, timeout=180, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def body_attrs(dom: str) -> dict[str, str]:
    m = re.search(r"<body([^>]*)>", dom)
    assert m is not None, dom[:500]
    return dict(re.findall(r'data-([a-z-]+)="([^"]*)"', m.group(1)))


def test_replay_page_in_browser(replay_page: Path, tmp_path: Path) -> None:
    data = page_data(replay_page)
    for k in (0, 28):
        attrs = body_attrs(browse(replay_page, f"#frame={k}", tmp_path))
        assert attrs["status"] == "ok", attrs
        assert attrs["frame"] == str(k) and attrs["frames"] == str(len(data["frames"]))
        assert attrs["measurements"] == str(len(data["frames"][k]["z"]))
        assert attrs["pedestrians"] == str(len(data["frames"][k]["peds"]))
        assert int(attrs["drawn"]) > 0
    attrs = body_attrs(browse(replay_page, "#frame=28&view=ego", tmp_path))
    assert attrs["status"] == "ok" and attrs["view"] == "ego"
    shot = tmp_path / "replay.png"
    browse(replay_page, "#frame=28", tmp_path, screenshot=shot)
    from PIL import Image

    with Image.open(shot) as img:
        assert img.size == (1300, 1000)
        colours = img.convert("RGB").getcolors(maxcolors=1 << 20)
    assert colours is not None and len(colours) > 50  # a drawn page, not a blank one


def test_report_page_in_browser(run_dir: Path, tmp_path: Path) -> None:
    from soabench.experiment.reports.html import REPORT_FILE

    assert main(["report", str(run_dir)]) == 0
    page = run_dir / REPORT_FILE
    n_figures = len(list((run_dir / "figures").glob("*.png")))
    dom = browse(page, "#sort=0:3", tmp_path)  # the models table sorted by its 4th column (mean delay)
    attrs = body_attrs(dom)
    assert attrs["status"] == "ok", attrs
    assert attrs["images"] == f"{n_figures}/{n_figures}"
    table = re.search(r'<table class="sortable">(.*?)</table>', dom, re.S).group(1)
    cells = [re.findall(r'<span class="v">(.*?)</span>', row) for row in re.findall(r"<tr>(.*?)</tr>", table)]
    delays = [float(c[1]) for c in cells if c]  # the cells with a value and its interval: trials, delay, ...
    assert len(delays) == 2 and delays == sorted(delays) and 'class="asc"' in table


def test_index_of_a_folder_of_runs(run_dir: Path, tmp_path: Path) -> None:
    """A folder holding run folders (a study, results/) gets each run's report and an index page linking them."""
    from soabench.experiment.reports.html import INDEX_FILE, REPORT_FILE

    folder = run_dir.parent
    (folder / "notes.md").write_text("# Study <b>notes</b>\n\n| a | b |\n|---|---|\n| 2 | 1 |\n", encoding="utf-8")
    assert main(["report", str(folder)]) == 0
    index = folder / INDEX_FILE
    text = index.read_text(encoding="utf-8")
    assert f'href="{run_dir.name}/{REPORT_FILE}"' in text and (run_dir / REPORT_FILE).is_file()
    assert "Study &lt;b&gt;notes&lt;/b&gt;" in text
    attrs = body_attrs(browse(index, "", tmp_path))
    assert attrs["status"] == "ok" and attrs["tables"] == "2"


def test_a_run_ends_with_its_headline_and_the_page_to_open(run_dir: Path, capsys) -> None:
    """``soabench run`` closes with a short table of S-OA's paired differences and names report.html; the full
    Markdown stays in summary.md."""
    from types import SimpleNamespace

    from soabench.cli.common import report_outcome

    outcome = SimpleNamespace(summary_markdown="# the summary", complete=True, run_dir=run_dir, n_missing=0)
    assert report_outcome(outcome, short=True) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == f"open {run_dir / 'report.html'}" and out[-2] == f"every table: {run_dir / 'summary.md'}"
    assert len(out) < 15 and not any(line.startswith("|") or "# the summary" in line for line in out)
    (row,) = [line for line in out if line.startswith("  UBM (FOV)")]  # the table's row (a trade-off may name it)
    assert "/2" in row  # S-OA − UBM with its interval and the trials S-OA wins, of the run's 2
    assert out[0].startswith("λ = 3, static; best: ")
