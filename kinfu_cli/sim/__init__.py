"""The one home of synthetic data: tabletop scenes (meshes and exact distances), the Kinect-like depth sensor
(noise-free or with the Kinect v1 noise model), ideal TSDF volumes, surface sampling, camera paths, the robot
arm, hand trajectories and the `kinfu synth` recording."""
