"""Baseline birth models (docs/method.md §3.2-3.5), each implementing soabench.protocols.BirthModel."""
