"""A superquadric fit's `converged`: a run that stopped at max_nfev already settled is converged (scipy's `success`
is False there), one stopped while still moving is not, and says why in segments.json's entry."""

from __future__ import annotations

import numpy as np

from kinfu_cli.segmentation import superquadric as sqm


def _cloud(seed: int) -> np.ndarray:
    """A noisy (4 mm) single view of a random superquadric, 150 points."""
    rng = np.random.default_rng(seed)
    true = sqm.Superquadric(rng.uniform(0.03, 0.08, 3), rng.uniform(0.2, 1.5, 2), np.zeros(3),
                            sqm.rpy_to_matrix(rng.uniform(-1, 1, 3)))
    return sqm.partial_view_cloud(true, sqm.arc_view_dirs(0.3, 1), n=150, noise=0.004, rng=rng)


def _fit(points: np.ndarray, monkeypatch, max_nfev: int):
    """The fit with one candidate axis, and scipy's result of its run (not the settle check's)."""
    runs = []
    solve = sqm._solve

    def recorded(*args, **kwargs):
        res = solve(*args, **kwargs)
        runs.append(res)
        return res

    monkeypatch.setattr(sqm, "_solve", recorded)
    fit = sqm.fit_superquadric(points, max_nfev=max_nfev, axis_candidates=1)
    monkeypatch.setattr(sqm, "_solve", solve)
    return fit, runs[0]


def _moved(fit, long) -> tuple[float, float, float, float, float]:
    """How far a long run moved the fit: semi-axes (m), exponents, centre (m), cost (relative), and the largest
    angle (deg) between matching axes (a superquadric is symmetric under each axis' flip, so up to sign)."""
    a, b = fit.superquadric, long.superquadric
    cosines = np.clip(np.abs(np.sum(a.rotation * b.rotation, axis=0)), 0.0, 1.0)
    return (float(np.max(np.abs(a.size - b.size))), float(np.max(np.abs(a.exponents - b.exponents))),
            float(np.linalg.norm(a.center - b.center)), (fit.cost - long.cost) / long.cost,
            float(np.degrees(np.arccos(cosines.min()))))


def test_a_fit_stopped_at_max_nfev_but_settled_reads_converged(monkeypatch):
    points = _cloud(14)
    fit, run = _fit(points, monkeypatch, max_nfev=15)
    assert run.status == 0 and not run.success and run.nfev == 15  # scipy: stopped at max_nfev, "not converged"
    long = sqm.fit_superquadric(points, max_nfev=2000, axis_candidates=1)
    size, exponent, centre, cost, turn = _moved(fit, long)
    assert long.success and size < 1e-3 and exponent < 0.05 and centre < 1e-3 and cost < 0.01  # it had settled
    assert turn < 2.0  # 1.2 deg: 1.4 mm at the 6.7 cm semi-axis, two nearly equal axes leave that turn loose
    assert fit.success and fit.to_json()["converged"] is True and "not_converged_reason" not in fit.to_json()


def test_a_fit_stopped_early_while_still_moving_is_not_converged_and_says_why(monkeypatch):
    points = _cloud(10)
    fit, run = _fit(points, monkeypatch, max_nfev=15)
    assert run.status == 0
    long = sqm.fit_superquadric(points, max_nfev=2000, axis_candidates=1)
    size, _, centre, cost, _ = _moved(fit, long)
    assert size > 0.05 and centre > 0.05 and cost > 0.05  # 9 cm and 6 % of its cost away from its optimum
    doc = fit.to_json()
    assert doc["converged"] is False and not fit.success
    assert doc["not_converged_reason"].startswith("stopped at max_nfev 15 short of its optimum: 20 more evaluations "
                                                  "lower its cost by ")


def test_the_settle_check_leaves_the_fitted_shape_as_it_was(monkeypatch):
    """The check restarts the optimiser from the fit but keeps the fit: the same shape, pose and cost as a fit
    whose check is skipped."""
    points = _cloud(14)
    fit, run = _fit(points, monkeypatch, max_nfev=15)
    assert np.array_equal(fit.superquadric.size, run.x[0:3]) and np.array_equal(fit.superquadric.exponents, run.x[3:5])
    assert fit.cost == float(run.cost)
    monkeypatch.setattr(sqm, "_settled", lambda *args, **kwargs: (True, ""))
    unchecked = sqm.fit_superquadric(points, max_nfev=15, axis_candidates=1)
    for name in ("size", "exponents", "center", "rotation"):
        assert np.array_equal(getattr(fit.superquadric, name), getattr(unchecked.superquadric, name)), name
    assert fit.cost == unchecked.cost and fit.residual == unchecked.residual
