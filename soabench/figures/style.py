"""One plotting style for every figure of the package: paper sizes, fonts, model and mode styles, titles.

Every figure module (run figures, sweep figures, the key figure, scene, sensor and birth overlays) draws through
this module, so a figure reads the same wherever it comes from:

* sizes follow a two-column paper: :data:`SINGLE` (3.5 in) and :data:`DOUBLE` (7.16 in) wide; fonts (:data:`RC`)
  are readable when the PNG is printed at that width;
* a birth model has one colour, marker and display name everywhere (:func:`model_style`, :func:`model_label`); the
  display names are the birth-model registry's own (:data:`soabench.birth.LABEL`), and a model outside the registry
  (a plugin) gets a stable colour of its own and its registry name;
* a probability mode has one line style everywhere: static solid, dynamic dashed, dynamic+occ dotted
  (:func:`mode_style`); bars of a non-static mode are hatched;
* panels are titled ``"(a) ..."`` (:func:`panel_title`), never ``"Fig. N: ..."``.

Figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas (no pyplot, no global backend state);
:func:`figure` creates one inside :data:`RC` and :func:`save_png` writes it atomically.
"""

from __future__ import annotations

import contextlib
import io
import os
import weakref
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, PathPatch, Rectangle
from matplotlib.path import Path as MplPath
from matplotlib.transforms import offset_copy

from soabench.birth import LABEL

#: width of one paper column and of the full page (inches), IEEE two-column layout
SINGLE = 3.5
DOUBLE = 7.16
#: PNG resolution: 7.16 in x 200 dpi = 1432 px, sharp on screen and in print
DPI = 200

#: rcParams of every figure: 8 pt text is the caption size of a two-column paper
RC: dict[str, object] = {
    "font.size": 8,
    "axes.titlesize": 8,
    "axes.labelsize": 8,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "legend.fontsize": 7,
    "legend.title_fontsize": 7,
    "figure.titlesize": 9,
    "axes.titlelocation": "left",
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.5,
    "axes.linewidth": 0.6,
    "lines.linewidth": 1.2,
    "lines.markersize": 4,
    "errorbar.capsize": 2,
    "legend.framealpha": 0.9,
    "legend.borderaxespad": 0.4,
    "savefig.dpi": DPI,
    "savefig.bbox": "tight",
    "savefig.pad_inches": 0.03,
    "hatch.linewidth": 0.6,
}


@dataclass(frozen=True)
class Style:
    """How one model or mode is drawn."""

    color: str
    marker: str = "o"
    linestyle: str = "-"
    hatch: str = ""


#: the six built-in birth models (colours of the paper's Fig. 2 where it has one: S-OA green)
MODEL_STYLES: dict[str, Style] = {
    "soa": Style("tab:green", "o"),
    "pubm": Style("tab:blue", "s"),
    "ubm": Style("tab:purple", "^"),
    "ubm-ws": Style("tab:pink", "P"),
    "atbm": Style("tab:red", "D"),
    "gmbm": Style("tab:gray", "v"),
}
#: colours and markers for models outside the registry (plugins), picked by a stable hash of the name
_EXTRA_COLORS = ("tab:orange", "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "black")
_EXTRA_MARKERS = ("P", "X", "h", "*", "<", ">")

#: probability modes: static solid, dynamic dashed (and hatched bars), dynamic+occ dotted, static+occ dash-dotted
MODE_STYLES: dict[str, Style] = {
    "static": Style("0.15", "o", "-", ""),
    "dynamic": Style("0.15", "s", "--", "////"),
    "dynamic+occ": Style("0.15", "^", ":", "...."),
    "static+occ": Style("0.15", "D", "-.", "\\\\"),
}


def model_label(name: str) -> str:
    """Display name of a birth model (S-OA, PUBM, UBM, ATBM, GMBM; a plugin keeps its own name)."""
    return LABEL.get(name, name)


def tick_label(name: str) -> str:
    """A model's display name for a category axis: a qualifier on its own line ("UBM (FOV)" -> "UBM\n(FOV)"), so
    that six neighbouring labels do not run into each other."""
    return model_label(name).replace(" (", "\n(")


def model_style(name: str) -> Style:
    """Colour and marker of a birth model, the same in every figure."""
    if name in MODEL_STYLES:
        return MODEL_STYLES[name]
    h = zlib.crc32(name.encode())
    return Style(_EXTRA_COLORS[h % len(_EXTRA_COLORS)], _EXTRA_MARKERS[h % len(_EXTRA_MARKERS)])


def mode_style(mode: str) -> Style:
    """Line style, marker and bar hatch of a probability mode."""
    return MODE_STYLES.get(mode, Style("0.15", "x", "-.", "xx"))


def panel_title(ax, letter: str | None, text: str) -> None:
    """Title a panel ``"(a) text"`` (the package's one title scheme); no letter for a single-panel figure."""
    ax.set_title(f"({letter}) {text}" if letter else text, loc="left", fontsize=RC["axes.titlesize"])


def letters(n: int, start: str = "a") -> list[str | None]:
    """The panel letters ``a, b, c, ...`` of an ``n``-panel figure (a figure of one panel has none)."""
    return [None] if n == 1 else [chr(ord(start) + i) for i in range(n)]


@contextlib.contextmanager
def style() -> Iterator[None]:
    """Apply :data:`RC` while a figure is drawn (text and lines read rcParams when they are created)."""
    with matplotlib.rc_context(RC):
        yield


def figure(width: float | str = "double", height: float = 2.6) -> Figure:
    """A new Agg-backed figure ``width`` ("single", "double" or inches) x ``height`` inches.

    Call it (and draw on it) inside :func:`style` so the fonts of :data:`RC` apply.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    w = {"single": SINGLE, "double": DOUBLE}.get(width, width) if isinstance(width, str) else float(width)
    fig = Figure(figsize=(float(w), float(height)), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def png_bytes(fig: Figure) -> bytes:
    """The figure as PNG bytes at :data:`DPI`."""
    buf = io.BytesIO()
    with style():
        fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight", pad_inches=0.03)
    return buf.getvalue()


def save_png(fig: Figure, path: Path) -> Path:
    """Write the figure as a PNG atomically (a reader never sees half a file); return ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")  # opened normally: the user's umask applies
    try:
        tmp.write_bytes(png_bytes(fig))
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def model_handles(models: Sequence[str], marker: bool = True) -> list:
    """Legend handles: one coloured line (with marker) per model, labelled with its display name."""

    return [
        Line2D([], [], color=s.color, marker=s.marker if marker else None, label=model_label(m))
        for m, s in ((m, model_style(m)) for m in models)
    ]


def mode_handles(modes: Sequence[str], bars: bool = False) -> list:
    """Legend handles: one black line (or hatched patch for bar charts) per probability mode."""

    if bars:
        return [Patch(facecolor="white", edgecolor="k", hatch=mode_style(m).hatch, label=m) for m in modes]
    return [Line2D([], [], color="k", ls=mode_style(m).linestyle, label=m) for m in modes]


def mode_handles_combined(modes: Sequence[str]) -> list:
    """Legend handles for figures with both bars and lines: per mode, its bar hatch and its line style together."""

    return [
        (
            Patch(facecolor="white", edgecolor="k", hatch=mode_style(m).hatch),
            Line2D([], [], color="k", ls=mode_style(m).linestyle),
        )
        for m in modes
    ]


def legend_below(fig: Figure, handles: Sequence, labels: Sequence[str] | None = None, ncol: int = 5, **kw):
    """One figure legend under the panels, filled row by row (matplotlib fills columns first)."""

    labels = list(labels) if labels is not None else [h.get_label() for h in handles]
    handles = list(handles)
    ncol = max(1, min(ncol, len(handles)))
    nrow = -(-len(handles) // ncol)
    blank = Rectangle((0, 0), 0, 0, fill=False, edgecolor="none", visible=False)
    pad = nrow * ncol - len(handles)
    handles += [blank] * pad
    labels += [""] * pad
    order = [r * ncol + c for c in range(ncol) for r in range(nrow)]
    return fig.legend(
        [handles[i] for i in order],
        [labels[i] for i in order],
        loc="outside lower center",
        ncol=ncol,
        handler_map={tuple: HandlerTuple(ndivide=None, pad=0.4)},
        **kw,
    )


# ------------------------------------------------------------------------------------------------ maps
def fill_geometry(ax, geom, **style) -> list:
    """Fill every polygon of a shapely geometry on ``ax`` with its holes left open (one path per polygon, the
    interiors as inner rings), so what lies under a hole (a road inside a ring of sidewalk) stays visible.
    Returns the added patches."""
    import shapely

    if geom is None or geom.is_empty:
        return []
    patches = []
    for part in shapely.get_parts(shapely.get_parts(np.asarray([geom], dtype=object))):
        if part.is_empty or part.geom_type != "Polygon":
            continue
        rings = [np.asarray(part.exterior.coords)[:, :2]] + [np.asarray(r.coords)[:, :2] for r in part.interiors]
        codes = []
        for ring in rings:
            codes += [MplPath.MOVETO] + [MplPath.LINETO] * (len(ring) - 2) + [MplPath.CLOSEPOLY]
        patches.append(ax.add_patch(PathPatch(MplPath(np.concatenate(rings), codes), **style)))
    return patches


_LEGENDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def extend_legend(ax, handles: Sequence, ncol: int = 4):
    """Add ``handles`` to the one legend under a map ``ax`` (scene, sensor and birth layers each add theirs);
    a handle whose label is already listed is not repeated. Returns the legend."""

    held = _LEGENDS.setdefault(ax, [])
    labels = {h.get_label() for h in held}
    held += [h for h in handles if h.get_label() not in labels]
    if ax.get_legend() is not None:
        ax.get_legend().remove()
    with style():
        return ax.legend(
            handles=held,
            loc="upper center",
            bbox_to_anchor=(0.5, 0.0),  # 28 pt under the map: below the x tick labels and axis label
            bbox_transform=offset_copy(ax.transAxes, ax.figure, y=-28, units="points"),
            ncol=min(ncol, len(held)) or 1,
            frameon=False,
        )
