"""The keyframe problem: spherical charts, reconstruction, metrics, selection methods,
environment, DQN and evaluation. Pure numpy/torch: never imports MuJoCo."""
