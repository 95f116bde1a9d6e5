"""Motion on the humanoid: retargeting, true velocities, clips, ingest, batch datasets, procedural motion."""
