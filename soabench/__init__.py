"""soabench: a SUMO-driven benchmark of GM-PHD birth models (S-OA and four baselines).

Pipeline (docs/development.md): scenario -> Recording -> sensor -> Scans -> gmphd + birth -> Estimates -> metrics
-> TrialResult -> experiment (trials, sweeps, tables, figures).
"""

__version__ = "0.1.0"
