"""Object-driven vs standard view planning in a closed loop (thesis ch. 3, Table 3.1 and Fig. 3.17).

The loop itself is `kinfu_cli.evaluation.nbv_loop.run_exploration` (the same simulated sensor, fusion,
view execution and scoring as `kinfu eval nbv`); this module runs it on a generated scenario (no files),
for benchmarks and tests over several seeds.
"""

from __future__ import annotations


def compare_strategies(seed: int = 0, *, views: int = 5, scan_frames: int = 8, score_px: int = 80,
                       voxel_size: float = 0.01, width: int | None = 160, height: int | None = 120,
                       strategies=("objects", "standard"), log=None, quiet: bool = True, **config) -> dict:
    """Thesis Fig. 3.17 / Table 3.1 in simulation on `make_scenario(seed)`: from a short one-sided scan
    (`scan_frames` poses), take `views` NBVs with each strategy, counting unknown voxels inside the true
    objects' bounding spheres + 0.2 m after each view, candidate views ray-cast and planning time.
    Views are scored on a `score_px`-wide image of the sensor's field of view. Extra keyword arguments
    are `LoopConfig` fields. Returns the `run_exploration` document."""
    from kinfu_cli.evaluation.nbv_loop import LoopConfig, run_exploration, scene_from_scenario

    cfg = LoopConfig(strategies=tuple(strategies), views=views, scan_frames=scan_frames, score_width=score_px,
                     voxel_size=voxel_size, width=width, height=height, seed=seed, **config)
    cfg.check()
    return run_exploration(scene_from_scenario(seed), cfg, quiet=quiet, scene_name=f"scenario seed {seed}", log=log)
