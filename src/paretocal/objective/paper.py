"""The paper's Chamfer distance exactly as written, kept as an option and a reference.

``E(X) = (1/n) sum_{p in image edge pixels} min_{q in projected points} |p - q|^2``

Summed over image edge pixels and divided by ``n``, it rewards spreading points across the image
(more coverage lowers every edge pixel's nearest distance) and does not penalise points that
leave the view; measured on KITTI it prefers poses far from the truth. It needs a nearest-
neighbour structure over the moving points, so it is evaluated candidate by candidate with a
KD-tree, as the paper did.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..camera import project
from .scene import Scene

NO_POINT_COST = 1e12  # no point in front of the camera: nothing to measure against


def paper_chamfer(scene: Scene, edge_uv: list[np.ndarray], T: np.ndarray,
                  n: np.ndarray) -> np.ndarray:
    """The paper's Chamfer per candidate, mean over frames, shape (C,).

    Parameters
    ----------
    scene : Scene
    edge_uv : list of ndarray, shape (E_f, 2)
        Image edge pixels per frame.
    T : ndarray, shape (C, 4, 4) or (C, 3, 4)
        Candidate extrinsics; points are projected through each frame's camera model and
        those valid for it (in front of a pinhole, inside the lens's monotonic radius) count.
    n : ndarray, shape (C,)
        Points per frame.
    """
    T = np.asarray(T, dtype=np.float64)
    C, F = len(T), len(scene.point_start) - 1
    out = np.zeros((C, F))
    for f in range(F):
        a, b = scene.point_start[f], scene.point_start[f + 1]
        P = np.column_stack([scene.x[a:b], scene.y[a:b], scene.z[a:b]]).astype(np.float64)
        cam = scene.cameras[f]
        for c in range(C):
            m = min(int(n[c]), b - a)
            uv, _, _ = project(P[:m], cam, T[c], scene.z_min)
            valid = np.isfinite(uv[:, 0])
            if not valid.any() or len(edge_uv[f]) == 0:
                out[c, f] = NO_POINT_COST
                continue
            d, _ = cKDTree(uv[valid]).query(edge_uv[f])
            out[c, f] = float(np.sum(d * d)) / max(m, 1)
    return out.mean(axis=1)
