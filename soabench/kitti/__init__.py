"""KITTI tracking data: a second source of the same Scans the SUMO path makes (docs/method.md §5.9).

* :mod:`soabench.kitti.formats`: the file formats (labels, detections in KITTI result or AB3DMOT form, calib, oxts,
  semantics);
* :mod:`soabench.kitti.reader`: a sequence -> :class:`~soabench.types.Scans` + scene map;
* :mod:`soabench.kitti.export`: SUMO trials written in the KITTI layout (``soabench export kitti``).

The paper's k-fold protocol over these sequences is a campaign: :mod:`soabench.experiment.campaigns.kitti`.
"""
