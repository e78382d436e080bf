"""RANSAC plane of a point cloud, as open3d's `PointCloud.segment_plane` (ransac_n = 3) does it, in numpy.

Same rules as open3d 0.18-0.20: a hypothesis is the plane through 3 sampled points (degenerate triples
skipped); inliers are the points closer than `distance`; the best hypothesis has the highest inlier share,
then the lowest inlier RMS distance; after each improvement the search stops once more iterations were run than
log(1 - p) / log(1 - share^3) (p = 0.99999999), and the returned plane is the least-squares fit (open3d's
determinant formula) to the best hypothesis' inliers. The samples come from a numpy Generator, so a seed gives
one answer on any number of threads, and `kinfu segment` need not import open3d (0.4 s of its 2 s budget).

One step is ours: the fit is then repeated on the inliers of the plane just fitted until they no longer change
(at most POLISH_ROUNDS), and those inliers are returned. On a real table (7-Scenes kitchen, 8 mm) the RANSAC
plane's offset varied by 9 cm over seeds 0-5 and the mug joined a 1 m segment for 3 of them; polished, every
seed gives the same plane (and the mug alone), since it no longer depends on which triple won.
"""

from __future__ import annotations

import numpy as np

PROBABILITY = 0.99999999  # open3d's default: the chance that one of the iterations run saw only inliers
BATCH = 64  # hypotheses scored at once: (points x BATCH) distance arrays
POLISH_ROUNDS = 10  # least-squares re-fits to the inliers; the kitchen table settles in 2-5


def plane_from_points(points: np.ndarray) -> np.ndarray:
    """(a, b, c, d), unit (a, b, c), of the least-squares plane through `points`: open3d's GetPlaneFromPoints
    (the plane regressed along the axis where the points spread least); zeros when it is undefined."""
    if len(points) == 0:
        return np.zeros(4)
    c = points.mean(axis=0)
    r = points - c
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = r.T @ r  # one product: six strided dot products cost 10x more
    det_x, det_y, det_z = yy * zz - yz * yz, xx * zz - xz * xz, xx * yy - xy * xy
    if det_x > det_y and det_x > det_z:
        abc = np.array([det_x, xz * yz - xy * zz, xy * yz - xz * yy])
    elif det_y > det_z:
        abc = np.array([xz * yz - xy * zz, det_y, xy * xz - yz * xx])
    else:
        abc = np.array([xy * yz - xz * yy, xy * xz - yz * xx, det_z])
    norm = float(np.linalg.norm(abc))
    if norm == 0.0:
        return np.zeros(4)
    abc = abc / norm
    return np.append(abc, -abc @ c)


def ransac_plane(points: np.ndarray, distance: float, iterations: int, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(plane (a, b, c, d) with a unit normal, inlier indices) of `points` (N, 3): see the module docstring.
    A cloud without a non-degenerate triple gives zeros and no inliers."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n < 3:
        return np.zeros(4), np.zeros(0, dtype=np.int64)
    samples = rng.integers(0, n, size=(int(iterations), 3))
    best_share, best_rmse, best = 0.0, np.inf, None
    stop = np.inf  # open3d's break_iteration
    done = start = 0
    while start < len(samples) and done <= stop:
        tri = pts[samples[start:start + min(BATCH, 16 << (start // 16).bit_length())]]  # 16, 32, 64, 64, ...
        start += len(tri)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(normal, axis=1)
        ok = length > 0
        normal = normal / np.where(ok, length, 1.0)[:, None]
        offset = -np.einsum("ij,ij->i", normal, tri[:, 0])
        dist = pts @ normal.T  # (points x hypotheses), then in place: one array of that size
        dist += offset
        np.abs(dist, out=dist)
        inl = dist < distance
        count = inl.sum(axis=0)
        for j in np.flatnonzero(ok):  # in sample order, as open3d on one thread; collinear triples do not count
            if done > stop:
                break
            done += 1
            share = count[j] / n
            if share < best_share or count[j] == 0:
                continue
            rmse = float(np.sqrt(np.mean(dist[inl[:, j], j] ** 2)))
            if share > best_share or rmse < best_rmse:
                best_share, best_rmse, best = share, rmse, np.append(normal[j], offset[j])
                stop = min(np.log(1 - PROBABILITY) / np.log(1 - share ** 3), iterations) if share < 1.0 else 0
    if best is None:
        return np.zeros(4), np.zeros(0, dtype=np.int64)
    inliers = np.flatnonzero(np.abs(pts @ best[:3] + best[3]) < distance)
    plane = plane_from_points(pts[inliers])
    for _ in range(POLISH_ROUNDS):
        settled = np.flatnonzero(np.abs(pts @ plane[:3] + plane[3]) < distance)
        if len(settled) < 3 or np.array_equal(settled, inliers):
            break
        inliers, plane = settled, plane_from_points(pts[settled])
    return plane, inliers
