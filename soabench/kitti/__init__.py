"""KITTI tracking data: a second source of the same Scans the SUMO path makes (docs/method.md §5.9).

* :mod:`soabench.kitti.formats`: the file formats (labels, detections in KITTI result or AB3DMOT form, calib, oxts,
  semantics);
* :mod:`soabench.kitti.reader`: a sequence -> :class:`~soabench.types.Scans` + scene map;
* :mod:`soabench.kitti.protocol`: the paper's k-fold protocol (``soabench kitti``);
* :mod:`soabench.kitti.export`: SUMO trials written in the KITTI layout (``soabench export kitti``).
"""
