"""Replay of point motion on bone capsules in MuJoCo: geometric checks and offscreen rendering."""
