"""The Python API: the nouns and verbs a notebook needs, importable from one place.

    import kinfu_cli.api as kf

    with kf.open_recording("sample_data/tabletop/recording.mcap") as rec:
        vol = kf.TernaryVolume(size=1.2, voxel_size=0.01, origin=(-0.6, -0.6, 0.4))
        for frame in kf.iter_frames(rec, end_s=6.1):
            vol.integrate(frame.depth, frame.K, frame.T_world_camera, frame.color, frame.color_mask)
    pois = kf.detect_pois("sample_data/tabletop/recording.mcap").pois
    camera = kf.CameraModel(**kf.SENSOR_PRESETS["kinect_v1"])
    views = kf.rank_poi(vol.ternary_grid(), pois[0].position, camera, radius=pois[0].radius)

Conventions: metres, seconds; poses are 4x4 camera-to-world (`T_a_b` maps frame b into a); the ternary
labels are 1 occupied, 0 unknown, -1 empty. Every error is a `KinfuError` with a one-line message.
"""

from kinfu_cli.attention.detect import PoiDetection, detect_pois
from kinfu_cli.change.diff import ChangeParams, ChangeResult, diff_grids, diff_volumes
from kinfu_cli.core.camera import SENSOR_PRESETS, CameraModel, preset_intrinsics
from kinfu_cli.core.errors import KinfuError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, load_ternary, save_ternary
from kinfu_cli.core.pois import Poi, read_pois, write_pois
from kinfu_cli.core.poses import look_at, matrix_to_quaternion, quaternion_to_matrix
from kinfu_cli.evaluation.changes import score_change_pois
from kinfu_cli.evaluation.poi_loo import leave_one_user_out
from kinfu_cli.fusion.outputs import write_fusion_outputs
from kinfu_cli.fusion.pipeline import FusionResult, TrackedFrames, fuse_recording, track_frames
from kinfu_cli.fusion.volume import TernaryVolume, load_grid, load_volume
from kinfu_cli.grasp.plan import GraspOptions, plan_grasps
from kinfu_cli.io.frames import RGBDFrame, iter_frames
from kinfu_cli.io.hand import load_hand_trajectory
from kinfu_cli.io.recording import Recording, open_recording
from kinfu_cli.io.trajectory import Trajectory
from kinfu_cli.io.tum import read_tum, write_tum
from kinfu_cli.nbv.ranking import PoiRanking, rank_poi
from kinfu_cli.nbv.viewpoints import PAPER_SPHERE, SphereSpec
from kinfu_cli.nbv.workflow import NbvOptions, ObjectViews, PoiViews, rank_object_views, rank_poi_views
from kinfu_cli.segmentation.pipeline import SegmentOptions, SegmentResult, segment_volume

__all__ = [
    # recordings and frames
    "open_recording", "Recording", "iter_frames", "RGBDFrame", "load_hand_trajectory", "Trajectory",
    # the volume
    "TernaryVolume", "load_volume", "load_grid", "TernaryGrid", "load_ternary", "save_ternary",
    "OCCUPIED", "UNKNOWN", "EMPTY", "fuse_recording", "FusionResult", "write_fusion_outputs", "track_frames",
    "TrackedFrames",
    # cameras and poses
    "CameraModel", "SENSOR_PRESETS", "preset_intrinsics", "look_at", "matrix_to_quaternion",
    "quaternion_to_matrix", "read_tum", "write_tum",
    # points of interest
    "detect_pois", "PoiDetection", "Poi", "read_pois", "write_pois", "leave_one_user_out",
    # views
    "rank_poi", "PoiRanking", "SphereSpec", "PAPER_SPHERE", "rank_poi_views", "PoiViews", "NbvOptions",
    "rank_object_views", "ObjectViews",
    # segments
    "segment_volume", "SegmentOptions", "SegmentResult",
    # grasps on the segments' superquadrics
    "plan_grasps", "GraspOptions",
    # what changed between two volumes, and POIs scored on it
    "diff_volumes", "diff_grids", "ChangeParams", "ChangeResult", "score_change_pois",
    "KinfuError",
]
