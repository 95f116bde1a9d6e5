"""Physics of motions on the humanoid: ground, contacts, inverse kinematics, dynamics."""
