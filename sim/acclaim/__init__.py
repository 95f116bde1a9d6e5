"""Acclaim (ASF skeleton + AMC motion) files: reading (and, for the codec, writing)."""
