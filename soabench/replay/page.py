"""The self-contained replay page: the replay's JSON embedded, drawn as inline SVG by a small script
(docs/user-guide/replay.md). No network is needed to view it; nothing in it is fetched.

The script writes its state into the ``<body>`` element's data attributes (``data-status`` "ok" or the error,
``data-frame``, ``data-frames`` and the counts of what the frame drew), so a headless browser's DOM dump shows
whether the page ran and which frame it shows. ``#frame=N`` in the address opens frame N.
"""

from __future__ import annotations

import html
import json
import re
from importlib import resources
from pathlib import Path
from typing import Any

from soabench.atomic import write_text_atomic

GENERATOR = "soabench replay"


def embed_json(data: Any) -> str:
    """JSON safe inside a ``<script>`` element (no ``</`` can close it)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    return text.replace("</", "<\\/").replace("<!--", "<\\!--")


def asset(name: str) -> str:
    """A stylesheet or script shipped beside this module (package data)."""
    return resources.files("soabench.replay").joinpath(name).read_text(encoding="utf-8")


def fill(template: str, **values: str) -> str:
    """``template`` with each ``%%NAME%%`` replaced by ``values[NAME]`` in one pass (inserted text is not scanned)."""
    return re.sub(r"%%([A-Z]+)%%", lambda m: values[m.group(1)], template)


def replay_html(data: dict[str, Any]) -> str:
    """The page for :func:`soabench.replay.frames.replay_data`'s output."""
    title = html.escape(f"soabench replay: {data['title']}")
    return fill(_TEMPLATE, TITLE=title, GENERATOR=GENERATOR, CSS=asset("replay.css"), JS=asset("replay.js"),
                DATA=embed_json(data))  # fmt: skip


def write_replay(data: dict[str, Any], out: Path) -> int:
    """Write the page to ``out`` (atomically); returns its size in bytes."""
    text = replay_html(data)
    write_text_atomic(out, text)
    return len(text.encode("utf-8"))


_TEMPLATE = r"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="generator" content="%%GENERATOR%%">
<title>%%TITLE%%</title>
<style>
%%CSS%%</style></head>
<body data-status="loading">
<h1 id="title"></h1>
<ul class="notes" id="notes"></ul>
<div class="controls"><button id="play" type="button">play</button>
<button id="prev" type="button">&#9664;</button><button id="next" type="button">&#9654;</button>
<input id="slider" type="range" min="0" value="0" step="1" aria-label="scan">
<span id="clock"></span>
<label>speed <select id="speed"><option value="1">1x</option><option value="2">2x</option>
<option value="5" selected>5x</option><option value="10">10x</option></select></label>
<label>view <select id="zoom"><option value="scene">whole scene</option>
<option value="ego">the FOV</option><option value="near">close up</option></select></label>
<button id="ego" type="button" title="centre the zoomed views on the ego again">centre on ego</button></div>
<div class="legend" id="legend"></div>
<div class="panels" id="panels"></div>
<div id="episodes"></div>
<script type="application/json" id="replay-data">%%DATA%%</script>
<script>
%%JS%%</script></body></html>
"""
