"""Motion library: clips, skeleton, forward kinematics, centre of mass, BVH."""
