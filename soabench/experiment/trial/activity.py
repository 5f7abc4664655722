"""What a pool worker is doing, noted for the driver: the trial and the plugin run it is in (so that the driver can
name them when a worker dies). The worker's initializer (:func:`soabench.experiment.execution.workers.init_worker`)
gives the notes folder; a trial notes each plugin run it starts (:mod:`soabench.experiment.trial.trial`)."""

from __future__ import annotations

import json
import os

#: what a worker notes while no plugin runs
OWN_CODE = "soabench's own code (no plugin was running)"
_NOTES: list[str | None] = [None]  #: this worker's notes folder (None: not a pool worker, nothing is noted)


def keep_notes_in(folder: str | None) -> None:
    """This process is a pool worker that notes what it does in ``folder`` (None: nothing is noted)."""
    _NOTES[0] = folder


def note_activity(trial: int, doing: str) -> None:
    """Note that this worker now runs ``doing`` in trial ``trial`` (a no-op outside a pool worker with notes)."""
    folder = _NOTES[0]
    if folder is None:
        return
    try:
        with open(os.path.join(folder, str(os.getpid())), "w", encoding="utf-8") as f:
            f.write(json.dumps({"trial": int(trial), "doing": doing}))
    except OSError:  # a note is a courtesy; the trial does not depend on it
        pass


def last_activity(folder: str, pid: int) -> dict | None:
    """What worker ``pid`` noted last (``{"trial", "doing"}``), or None."""
    try:
        with open(os.path.join(folder, str(pid)), encoding="utf-8") as f:
            note = json.loads(f.read())
    except (OSError, ValueError):
        return None
    return note if isinstance(note, dict) and isinstance(note.get("trial"), int) else None
