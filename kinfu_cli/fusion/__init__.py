"""KinectFusion-style TSDF volume that keeps unknown / empty / occupied per voxel."""
