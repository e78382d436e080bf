"""Reading and writing recordings, trajectories and result files."""
