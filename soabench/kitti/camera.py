"""The camera of ``soabench export kitti``: which objects it sees and their 2-D boxes (docs/user-guide/outputs.md,
"The KITTI export"), with the KITTI tracking devkit's conventions.

* A 3-D box is (h, w, l) with its bottom centre (x, y, z) in the rectified camera frame (x right, y down, z forward)
  and rotation_y about the camera's y axis; its corners follow the devkit's ``computeBox3D``: length along
  R(ry) x, width along R(ry) z, height along -y, with R(ry) = [[cos, 0, sin], [0, 1, 0], [-sin, 0, cos]].
* The devkit projects a box only where it lies in front of the camera: corners closer than ``NEAR`` = 0.1 m to the
  image plane are not drawn. Here the box is clipped at z = ``NEAR`` (its edges cut there), so an object partly
  beside the camera still gets the 2-D box of its visible part.
* The 2-D box is the bounding box of the projected corners (``P2 X``), clipped to the image as KITTI's labels are:
  left, top, right, bottom within [0, W - 1] x [0, H - 1] pixels.
* An object is seen when its box overlaps the image [0, W] x [0, H] (the extent from which the horizontal FOV
  2 atan(W / 2 f_x) of :meth:`~soabench.kitti.formats.Calib.fov_deg` is measured). Its truncation level (the
  tracking devkit's integer 0, 1, 2) is 0 when clipping leaves the box as it is, 1 when the clipped box keeps more
  than half of its area, 2 otherwise.
"""

from __future__ import annotations

import math

import numpy as np

from soabench.kitti.formats import NOMINAL_IMAGE_WIDTH as IMAGE_WIDTH

IMAGE_HEIGHT = 375  #: height (px) of the KITTI tracking colour images (their width: ``IMAGE_WIDTH`` = 1242)
NEAR = 0.1  #: the devkit's near limit (m): box corners closer to the image plane are not projected
_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))


def box_corners(hwl, xyz, ry: float) -> np.ndarray:
    """(8, 3) corners of a 3-D box in the rectified camera frame (devkit ``computeBox3D`` order: bottom 0-3, top
    4-7)."""
    h, w, length = (float(v) for v in hwl)
    x = 0.5 * length * np.array([1.0, 1.0, -1.0, -1.0, 1.0, 1.0, -1.0, -1.0])
    y = -h * np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0])
    z = 0.5 * w * np.array([1.0, -1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0])
    c, s = math.cos(ry), math.sin(ry)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return (R @ np.vstack([x, y, z])).T + np.asarray(xyz, dtype=float)


def in_front(corners: np.ndarray) -> np.ndarray:
    """The part of a box at z >= NEAR: its corners there and the points where its edges cross z = NEAR."""
    keep = [corners[corners[:, 2] >= NEAR]]
    for a, b in _EDGES:
        za, zb = corners[a, 2], corners[b, 2]
        if (za - NEAR) * (zb - NEAR) < 0.0:
            t = (NEAR - za) / (zb - za)
            keep.append((corners[a] + t * (corners[b] - corners[a]))[None, :])
    return np.concatenate(keep)


def project(P2: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(n, 2) pixel coordinates (u, v) of rectified-camera points: ``P2 [X; 1]`` divided by its third row."""
    X = np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(P2, dtype=float).T
    return X[:, :2] / X[:, 2:3]


def image_box(
    P2: np.ndarray, hwl, xyz, ry: float, width: float = IMAGE_WIDTH, height: float = IMAGE_HEIGHT
) -> tuple[np.ndarray, int] | None:
    """The clipped 2-D box (left, top, right, bottom) of a 3-D box and its truncation level, or None when the camera
    does not see the box (nothing in front of the camera, or no overlap with the image)."""
    pts = in_front(box_corners(hwl, xyz, ry))
    if len(pts) == 0:
        return None
    uv = project(P2, pts)
    (left, top), (right, bottom) = uv.min(axis=0), uv.max(axis=0)
    if right <= 0.0 or left >= width or bottom <= 0.0 or top >= height:
        return None
    box = np.clip([left, top, right, bottom], 0.0, [width - 1.0, height - 1.0, width - 1.0, height - 1.0])
    if (box == [left, top, right, bottom]).all():
        return box, 0
    area = (right - left) * (bottom - top)
    kept = (box[2] - box[0]) * (box[3] - box[1])
    return box, 1 if area > 0.0 and kept > 0.5 * area else 2
