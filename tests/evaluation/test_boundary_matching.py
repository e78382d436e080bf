"""Boundary matching of `kinfu eval segment`: the maximum one-to-one matching within T_eval equals the count of a
minimum-cost assignment that charges 100 x T_eval per unmatched point (Martin et al.'s benchmark, solved exactly by
scipy's sparse Jonker-Volgenant as the reference), and the greedy closest-first matching undercounts boundaries
that run side by side one point apart."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import min_weight_full_bipartite_matching
from scipy.spatial import cKDTree

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.segments import match_boundaries, score_segmentation
from kinfu_cli.io.labelled_cloud import write_labelled_cloud


def _min_cost_assignment_matches(a: np.ndarray, b: np.ndarray, t_eval: float, outlier: float = 100.0) -> int:
    """Reference: pairs of a minimum-cost assignment in which each point of a or b may instead take its own
    outlier at outlier x t_eval (dummies of matched pairs pair up at no cost), as in Martin et al."""
    sdm = cKDTree(a).sparse_distance_matrix(cKDTree(b), t_eval, output_type="ndarray")
    n, m, e = len(a), len(b), len(sdm)
    rows = np.concatenate([sdm["i"], np.arange(n), n + np.arange(m), n + sdm["j"]])
    cols = np.concatenate([sdm["j"], m + np.arange(n), np.arange(m), m + sdm["i"]])
    shift = t_eval  # the solver wants non-zero weights; a constant per pair leaves the optimum unchanged
    w = np.concatenate([sdm["v"], np.full(n + m, outlier * t_eval), np.zeros(e)]) + shift
    r, c = min_weight_full_bipartite_matching(coo_matrix((w, (rows, cols)), shape=(n + m, m + n)).tocsr())
    return int(np.sum((r < n) & (c < m)))


@pytest.mark.parametrize("seed", range(6))
def test_assignment_count_equals_the_min_cost_assignment_with_outlier_cost(seed):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 0.2, (150, 3)) * [1, 1, 0.05]
    b = np.r_[a[:120] + rng.normal(0, 0.008, (120, 3)), rng.uniform(0, 0.2, (40, 3)) * [1, 1, 0.05]]
    pts = np.r_[a, b]
    ia, ib = np.arange(len(a)), len(a) + np.arange(len(b))
    ours = match_boundaries(pts, ia, ib, 0.02)
    assert ours == _min_cost_assignment_matches(a, b, 0.02)
    assert match_boundaries(pts, ia, ib, 0.02, "greedy") <= ours


def test_greedy_undercounts_two_boundaries_one_point_apart():
    # a 1 cm grid; the true boundary holds the columns x = 0 and 1 cm, the predicted one x = 1 and 2 cm: every
    # predicted point has a true one within 1 cm, but closest-first pairs the shared column and strands the rest
    y = np.arange(30) * 0.01
    grid = np.array([(x, yy, 0.0) for x in (0.0, 0.01, 0.02) for yy in y])
    col = np.round(grid[:, 0] / 0.01).astype(int)
    gt, pred = np.flatnonzero(col <= 1), np.flatnonzero(col >= 1)
    assert match_boundaries(grid, pred, gt, 0.015) == len(pred)
    assert match_boundaries(grid, pred, gt, 0.015, "greedy") == len(y)


def test_shifted_labelling_scores_higher_with_the_assignment_and_bad_matching_is_named():
    g = np.stack(np.meshgrid(np.arange(40), np.arange(20), indexing="ij"), -1).reshape(-1, 2) * 0.012
    pts = np.c_[g, np.zeros(len(g))]
    gt = (pts[:, 0] >= 0.2).astype(int)
    shifted = (pts[:, 0] >= 0.21).astype(int)  # the boundary one point (1.2 cm) off: 2.4 cm between outer columns
    a = score_segmentation(pts, shifted, gt, object_ids=[1])
    gr = score_segmentation(pts, shifted, gt, object_ids=[1], matching="greedy")
    assert a.boundary_precision == 1.0 and a.boundary_recall == 1.0
    assert gr.boundary_precision < 0.9
    with pytest.raises(ConfigError, match="^matching: expected one of assignment, greedy"):
        score_segmentation(pts, shifted, gt, matching="hungarian")


def test_cli_records_the_matching_and_greedy_scores_lower(tmp_path):
    g = np.stack(np.meshgrid(np.arange(40), np.arange(20), indexing="ij"), -1).reshape(-1, 2) * 0.012
    pts = np.c_[g, np.zeros(len(g))]
    write_labelled_cloud(tmp_path / "gt.ply", pts, (pts[:, 0] >= 0.2).astype(int))
    write_labelled_cloud(tmp_path / "pred.ply", pts, (pts[:, 0] >= 0.21).astype(int))
    docs = {}
    for m in ("assignment", "greedy"):
        r = CliRunner().invoke(cli, ["eval", "segment", str(tmp_path / "pred.ply"), "--ground-truth",
                                     str(tmp_path / "gt.ply"), "--matching", m])
        assert r.exit_code == 0, r.output
        assert f"boundary matching: {m}" in r.stdout
        r = CliRunner().invoke(cli, ["eval", "segment", str(tmp_path / "pred.ply"), "--ground-truth",
                                     str(tmp_path / "gt.ply"), "--matching", m, "--json", "--quiet"])
        docs[m] = json.loads(r.output)
        assert docs[m]["matching"] == m
    assert docs["assignment"]["boundary_precision"] == 1.0 > docs["greedy"]["boundary_precision"]
