"""Evaluation: the protocol and Table 3, rate/distortion, and the physical-validation report."""
