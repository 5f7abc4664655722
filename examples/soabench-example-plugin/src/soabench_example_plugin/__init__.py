"""Example soabench plugins: :class:`~.births.EdgeBirth` (a birth model for our GM-PHD filter) and
:class:`~.tracker.NearestNeighbourKF` (a whole tracker that is not a GM-PHD)."""
