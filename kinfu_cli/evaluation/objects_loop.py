"""Old home of `compare_strategies`, now in `kinfu_cli.evaluation.nbv_loop`.

Kept only for importers on other branches (benchmarks/bench_segment.py, tests/test_objects_nbv.py); delete once
they import it from nbv_loop.
"""

from kinfu_cli.evaluation.nbv_loop import compare_strategies

__all__ = ["compare_strategies"]
