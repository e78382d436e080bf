"""File suffixes by the kind of file they name: what an output path's name may be, shared by the commands'
option checks and the library's writers (a recording writer given results.json would make a ROS 2 bag folder of
that name)."""

from __future__ import annotations

#: Figure formats matplotlib's Agg backend writes by suffix (save_figure writes PNG for a path without one).
IMAGE_SUFFIXES = frozenset({".png", ".pdf", ".svg", ".svgz", ".eps", ".ps", ".jpg", ".jpeg", ".tif", ".tiff",
                            ".webp", ".pgf", ".raw", ".rgba"})
#: Geometry files open3d writes by suffix (an error mesh, or a cloud when the reconstruction is one).
GEOMETRY_SUFFIXES = frozenset({".ply", ".obj", ".stl", ".off", ".gltf", ".glb", ".pcd", ".xyz", ".xyzn", ".pts"})
RECORDING_SUFFIXES = frozenset({".mcap", ".bag"})
#: Suffixes of files kinfu reads or writes that are not JSON: a JSON result or a folder named so is a mistake.
OTHER_FILE_SUFFIXES = (IMAGE_SUFFIXES | GEOMETRY_SUFFIXES | RECORDING_SUFFIXES
                       | {".npz", ".npy", ".db3", ".tum", ".traj", ".res", ".csv", ".yaml", ".yml", ".zip", ".gz"})

#: Suffixes a folder (or a ROS 2 bag folder) is not named with: results, text, and every other file kinfu knows.
FILE_SUFFIXES = OTHER_FILE_SUFFIXES | {".json", ".txt", ".log", ".md", ".html"}
