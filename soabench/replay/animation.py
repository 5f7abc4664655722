"""A replay as a video: an animated GIF (Pillow) or an MP4 (ffmpeg from the ``imageio-ffmpeg`` package, the
``video`` extra), drawn with matplotlib from the same frame data as the page (docs/user-guide/replay.md): one panel
per model, one video frame per scan (at least 1280 x 720), in the page's colours, with the pedestrians' ids and
the estimates' track numbers (1, 2, ... in the order the run's tracks first appear; the page's track table gives
each number's label); the legend sits in a strip under the panels."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.collections import EllipseCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, PathPatch
from matplotlib.path import Path as MplPath
from PIL import Image

from soabench.errors import SoabenchError

#: pedestrian fill per state (visible, occluded, outside FOV, in building), as on the page
_PED_FILL = ("#111111", "#999999", "#ffffff", "#8b4513")
_AWAIT, _EST, _HIDE = "#e6007e", "#5b2a86", "#4b2e83"
#: one colour per track label (the page's palette; label i of a model in colour i modulo its length)
TRACK_COLORS = ("#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324", "#469990",
                "#800000", "#808000", "#000075")  # fmt: skip
#: the file endings :func:`write_video` writes
VIDEO_SUFFIXES = (".gif", ".mp4")
VIDEO_EXTRA = "pip install 'soabench[video]' (or: pip install imageio-ffmpeg)"


def _rings(path: str) -> list[np.ndarray]:
    """The closed rings of one of our SVG paths ("M x y x y ... Z" subpaths)."""
    out = []
    for part in path.split("Z"):
        nums = part.replace("M", " ").replace("L", " ").split()
        if len(nums) >= 6:
            out.append(np.asarray(nums, dtype=float).reshape(-1, 2))
    return out


def _patch(path: str, **style: Any):
    """A compound patch of an SVG path of ours (holes: the rings' opposite orientations, nonzero fill)."""

    rings = _rings(path)
    if not rings:
        return None
    verts = np.concatenate([np.vstack([r, r[:1]]) for r in rings])
    codes = np.concatenate([[MplPath.MOVETO] + [MplPath.LINETO] * (len(r) - 1) + [MplPath.CLOSEPOLY] for r in rings])
    return PathPatch(MplPath(verts, codes), **style)


def _add(ax: Any, path: str, **style: Any) -> list:
    """Draw an SVG path of ours on ``ax`` (as an artist: the panels' limits are set, not fitted to what is drawn)."""
    patch = _patch(path, **style)
    return [] if patch is None else [ax.add_artist(patch)]


def _legend(sources: list[dict[str, str]], ncol: int, width: int, height: int, dpi: int) -> np.ndarray:
    """The page's legend, drawn once as the (height, width, 3) strip under the panels of every frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(fig)

    def mark(marker: str, **kw: Any) -> Line2D:
        return Line2D([], [], ls="none", marker=marker, **kw)

    items = [
        (Patch(fc="#7fd37f", alpha=0.6), "visible sidewalk Ω_k"),
        (Patch(fc=_HIDE + "2e", ec=_HIDE, hatch="////", lw=0), "occluded sidewalk in the FOV"),
        *((mark("s" if i == 3 else "o", ms=8, mfc=c, mec="k"), f"pedestrian: {s}") for i, (c, s) in
          enumerate(zip(_PED_FILL, ("visible", "occluded", "outside FOV", "in building"), strict=True))),
        (mark("o", ms=12, mfc="none", mec=_AWAIT, mew=1.8), "detected, not yet initiated"),
        (Line2D([], [], color=_AWAIT, ls="--"), "to its nearest birth term"),
        (mark(".", color="#1f77b4", ms=10), "measurement (target)"),
        (mark("x", color="#ff7f0e", ms=7), "measurement (clutter)"),
        (mark("+", color=_EST, ms=11, mew=2.0), "estimate (n: its track number)"),
        *((mark("o", ms=10, mfc="none", mec=s["color"]), f"birth: {s['label']}") for s in sources),
    ]  # fmt: skip
    fig.legend(*zip(*items, strict=True), loc="center", ncol=ncol, fontsize=_LEGEND_PT, frameon=False,
               handlelength=1.6, columnspacing=1.2, borderaxespad=0.2)  # fmt: skip
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[:height, :width, :3].copy()


#: the smallest video frame (pixels): 720p, where the ids and track numbers read at 100 %
MIN_WIDTH, MIN_HEIGHT = 1280, 720
_DPI = 100
_TEXT_PT, _TITLE_PT, _LEGEND_PT = 11, 12, 11  #: ids and track numbers, panel titles, legend (points at _DPI)
_TITLE_PX = 26  #: the title line above each row of panels
_LEGEND_ROW_PX = 22
_LEGEND_COL_PX = 260
_LEGEND_FIXED = 11  #: legend entries besides the birth origins
_PANELS_PER_ROW = 3


@dataclass(frozen=True)
class FrameLayout:
    """Where a video frame's parts go (pixels): ``rows`` x ``cols`` panels of ``panel_w`` x ``panel_h``, each row
    under its title line, over a legend strip of ``legend_h`` in ``legend_cols`` columns (outside every panel)."""

    width: int
    height: int
    cols: int
    rows: int
    panel_w: int
    panel_h: int
    legend_h: int
    legend_cols: int


def frame_size(n_models: int, n_legend: int, panel_px: int = 420) -> FrameLayout:
    """The layout of a video frame: at most :data:`_PANELS_PER_ROW` panels of at least ``panel_px`` x 3/4
    ``panel_px`` a row, grown to fill at least :data:`MIN_WIDTH` x :data:`MIN_HEIGHT`; the legend of ``n_legend``
    entries in a strip below; width and height rounded up to multiples of 16 (what video codecs want)."""
    cols = max(1, min(n_models, _PANELS_PER_ROW))
    rows = -(-n_models // cols)
    panel_w = max(panel_px, -(-MIN_WIDTH // cols))
    width = cols * panel_w
    legend_cols = max(2, width // _LEGEND_COL_PX)
    legend_h = _LEGEND_ROW_PX * -(-n_legend // legend_cols) + 10
    panel_h = max(panel_w * 3 // 4, -(-(MIN_HEIGHT - legend_h) // rows) - _TITLE_PX)
    up16 = lambda v: -(-v // 16) * 16  # noqa: E731
    return FrameLayout(up16(width), up16(rows * (panel_h + _TITLE_PX) + legend_h), cols, rows, panel_w, panel_h,
                       legend_h, legend_cols)  # fmt: skip


def render_frames(data: dict[str, Any], panel_px: int = 420) -> Iterator[np.ndarray]:
    """One (H, W, 3) uint8 RGB image per scan of the replay ``data`` (:func:`soabench.replay.frames.replay_data`),
    laid out by :func:`frame_size`: each panel follows the ego, the sensor's range and a margin around it (the page's
    "the FOV" view). An estimate's track is drawn as its number in the run (1, 2, ... by first appearance, the
    page's track table names the label)."""
    from matplotlib import patheffects
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    S, models = data["scene"], data["models"]
    lay = frame_size(len(models), _LEGEND_FIXED + len(data["sources"]), panel_px)
    width, height, panel_h, legend_h = lay.width, lay.height, lay.panel_h, lay.legend_h
    fig = Figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI)
    canvas = FigureCanvasAgg(fig)
    axes = []
    for i in range(len(models)):
        row, col = divmod(i, lay.cols)
        bottom = legend_h + (lay.rows - 1 - row) * (panel_h + _TITLE_PX)
        axes.append(fig.add_axes(((col * lay.panel_w + 3) / width, bottom / height, (lay.panel_w - 6) / width,
                                  panel_h / height)))  # fmt: skip
    half_h = 1.1 * data["r_max"]
    half_w = half_h * (lay.panel_w - 6) / panel_h
    colours = [s["color"] for s in data["sources"]]
    for ax in axes:
        ax.set_facecolor("#dde3ea")
        for key, style in (
            ("roads", {"fc": "#8c8c8c", "ec": "none"}),
            ("sidewalk", {"fc": "white", "ec": "#b0b0b0"}),
            ("crossings", {"fc": "#f4f4f4", "ec": "#b0b0b0"}),
            ("buildings", {"fc": "#f5c518", "ec": "#b8860b"}),
            ("parked", {"fc": "black", "ec": "none"}),
        ):
            _add(ax, S[key], lw=0.5, **style)  # fmt: skip
        ax.set_xticks([])
        ax.set_yticks([])
    legend = _legend(data["sources"], lay.legend_cols, width, legend_h, _DPI)
    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    text = {"fontsize": _TEXT_PT, "clip_on": True, "path_effects": halo}
    drawn: list = []
    for f in data["frames"]:
        for artist in drawn:
            artist.remove()
        drawn = []
        for i, ax in enumerate(axes):
            mf = f["models"][i]
            drawn += _add(ax, f["omega"], fc="#7fd37f", alpha=0.45, ec="none")
            drawn += _add(ax, f["hidden"], fc=_HIDE + "2e", ec=_HIDE, hatch="////", lw=0)
            drawn += _add(ax, f["fov"], fc="none", ec="black", lw=0.6, ls="--")
            for v in f["vehicles"]:
                drawn += _add(ax, "M" + " ".join(f"{x} {y}" for x, y in v) + "Z", fc="#377eb8", ec="k", lw=0.4)
            if f["ego_box"]:
                drawn += _add(ax, "M" + " ".join(f"{x} {y}" for x, y in f["ego_box"]) + "Z", fc="#e41a1c", ec="k")
            b = np.asarray(mf["births"], dtype=float).reshape(-1, 6)
            if len(b):
                drawn.append(ax.add_collection(EllipseCollection(
                    b[:, 2], b[:, 3], b[:, 4], units="xy", offsets=b[:, :2], offset_transform=ax.transData,
                    facecolors="none", edgecolors=[colours[int(s)] for s in b[:, 5]], linewidths=0.7)))  # fmt: skip
            for p in f["peds"]:
                drawn += ax.plot(p[1], p[2], "s" if p[3] == 3 else "o", ms=7, mfc=_PED_FILL[p[3]], mec="k", mew=0.6)
                if p[5][i] == 1:
                    drawn += ax.plot(p[1], p[2], "o", ms=14, mfc="none", mec=_AWAIT, mew=1.8)
                # the id above left of the pedestrian, the track number below right of the estimate: apart when
                # a track sits on its pedestrian
                drawn.append(ax.text(p[1] - 1.0, p[2] - 1.2, p[0], ha="right", va="bottom", **text))
            z = np.asarray(f["z"], dtype=float).reshape(-1, 3)
            drawn += ax.plot(z[z[:, 2] == 0, 0], z[z[:, 2] == 0, 1], ".", color="#1f77b4", ms=8)
            drawn += ax.plot(z[z[:, 2] == 1, 0], z[z[:, 2] == 1, 1], "x", color="#ff7f0e", ms=6)
            at = {p[0]: p for p in f["peds"]}
            for w in mf.get("why", ()):  # awaiting pedestrian -> its nearest birth term
                p = at[w[0]]
                drawn += ax.plot([p[1], w[4]], [p[2], w[5]], color=_AWAIT, lw=1.2, ls="--")
            for x, y, lab in mf["est"]:
                colour = _EST if lab < 0 else TRACK_COLORS[lab % len(TRACK_COLORS)]
                drawn += ax.plot(x, y, "+", color=colour, ms=12, mew=2.2)
                if lab >= 0:
                    drawn.append(ax.text(x + 1.0, y + 1.2, str(lab + 1), color=colour, fontweight="bold", ha="left",
                                         va="top", **text))  # fmt: skip
            cx, cy = f["ego"][:2]
            ax.set_xlim(cx - half_w, cx + half_w)
            ax.set_ylim(cy + half_h, cy - half_h)  # page coordinates: y grows downwards
            ax.set_title(f"{models[i]['label']}  k = {f['k']}, t = {f['t']:.1f} s", fontsize=_TITLE_PT)
        canvas.draw()
        rgb = np.asarray(canvas.buffer_rgba())[:height, :width, :3].copy()
        rgb[height - legend_h :] = legend
        yield rgb


def _part(out: Path) -> Path:
    """The temporary file beside ``out`` (same ending: ffmpeg picks the container from it), moved over ``out`` when
    complete: never a partial video under the asked name."""
    return out.with_name(f".{out.stem}.part{out.suffix}")


def write_gif(data: dict[str, Any], out: Path, speed: float = 5.0, panel_px: int = 420) -> int:
    """Write the replay ``data`` as a looping GIF played at ``speed`` times real time; returns its size in bytes."""

    frames = [
        Image.fromarray(rgb).quantize(colors=128, method=Image.Quantize.FASTOCTREE)
        for rgb in render_frames(data, panel_px)
    ]
    duration = max(20, int(round(1000 * data["dt"] / speed)))
    part = _part(Path(out))
    try:
        frames[0].save(part, format="GIF", save_all=True, append_images=frames[1:], duration=duration, loop=0)
        os.replace(part, out)
    finally:
        part.unlink(missing_ok=True)
    return Path(out).stat().st_size


def require_mp4() -> Any:
    """The ``imageio_ffmpeg`` module (its ffmpeg binary), or one line saying how to install it."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise SoabenchError(f"MP4 output needs the imageio-ffmpeg package: {VIDEO_EXTRA}") from None
    return imageio_ffmpeg


def write_mp4(data: dict[str, Any], out: Path, speed: float = 5.0, panel_px: int = 420) -> int:
    """Write the replay ``data`` as an H.264 MP4 (yuv420p, one frame per scan) played at ``speed`` times real time;
    returns its size in bytes."""
    ffmpeg = require_mp4()
    frames = render_frames(data, panel_px)
    first = next(frames)
    part = _part(Path(out))
    try:
        writer = ffmpeg.write_frames(
            str(part), (first.shape[1], first.shape[0]), fps=speed / data["dt"], codec="libx264",
            pix_fmt_in="rgb24", pix_fmt_out="yuv420p", quality=7, macro_block_size=16, ffmpeg_log_level="error",
        )  # fmt: skip
        writer.send(None)
        writer.send(first)
        for rgb in frames:
            writer.send(rgb)
        writer.close()
        os.replace(part, out)
    except (OSError, RuntimeError) as exc:
        raise SoabenchError(f"cannot write the MP4 {str(out)!r}: {exc}") from None
    finally:
        part.unlink(missing_ok=True)
    return Path(out).stat().st_size


def write_video(data: dict[str, Any], out: Path) -> int:
    """The GIF or MP4 that ``out``'s ending names; returns its size in bytes."""
    return write_mp4(data, out) if Path(out).suffix.lower() == ".mp4" else write_gif(data, out)
