"""Poses and intrinsics from the data: COLMAP registration (pycolmap), focal profile, alignment."""
