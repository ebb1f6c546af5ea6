"""Slow, obviously correct references of the fast paths, used only by the parity tests."""
