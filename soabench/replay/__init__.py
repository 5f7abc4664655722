"""Replays of one trial: a page or a video (docs/user-guide/replay.md).

:func:`replay_trial` re-simulates a trial of a finished run from its stored configuration and seeds;
:func:`replay_data` turns it into JSON-able frames and :func:`write_replay` into a self-contained page (a run
folder's ``report.html`` is :mod:`soabench.experiment.reports.html`'s).
"""

from soabench.replay.frames import replay_data
from soabench.replay.page import write_replay
from soabench.replay.simulate import TrialReplay, replay_trial

__all__ = ["TrialReplay", "replay_data", "replay_trial", "write_replay"]
