"""The keyframe problem: spherical chart, reconstruction, segment costs, optimum, methods, metrics."""
