"""Forward simulation of the humanoid: a tracking controller, synthetic motion generation."""
