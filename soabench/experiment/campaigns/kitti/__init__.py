"""The KITTI campaign (docs/user-guide/kitti.md): the paper's k-fold protocol over the sequences the KITTI reader
(:mod:`soabench.kitti`) turns into scans (:mod:`.protocol`), its report (:mod:`.report`) and the tracking results in
KITTI's own format (:mod:`.results`)."""
