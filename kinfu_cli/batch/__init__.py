"""`kinfu batch`: many recordings through the stages on a Dask cluster, resumable, with one manifest.

plan.py reads and checks the plan (TOML or YAML), stages.py is the vocabulary of a stage (what it needs,
reads, writes and how it runs; the table itself is given by the caller), fingerprint.py says when a stage's
outputs are still current, manifest.py is manifest.json, engine.py builds the task graph and runs it.
"""
