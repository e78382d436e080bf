"""Scoring against ground truth, with the papers' tables beside ours."""
