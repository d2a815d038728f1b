"""The simulator: the Husky A200 in a PyBullet world (geometry from its URDF, published specs,
skid-steer drive with its limits, sensing, collision), the closed-loop episode, its metrics and
trace, the kinematic reference loop and open-loop driving. Knows nothing of files or commands."""
