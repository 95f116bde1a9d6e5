"""The MuJoCo humanoid: MJCF generation from a skeleton, rotations, quaternions, the FK oracle."""
