"""Shadow representations that are not a depth map per light direction (one module each).

- :mod:`.vsv`: voxelized shadow volumes (Wyman 2011), a binary voxel grid in epipolar space.
"""
