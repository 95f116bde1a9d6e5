"""The motion codec: whole trials -> keyframe bytes (``.sidq``) -> decoded motion."""
