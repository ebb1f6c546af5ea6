"""Each command's stages in order: ``deblur`` (load, calibrate, poses, train, outputs, score), the
pose stage, and ``calibrate --refine``."""
