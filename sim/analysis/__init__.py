"""Analysis of motions on the humanoid: the physics job (IK, contacts, dynamics, support) of a
subject and point set, and the figures it reports, above ``sim.physics`` and ``sim.replay``."""
