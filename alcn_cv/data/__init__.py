"""Illumination data engine (issue 3): rendered training windows, a detection benchmark and pose sequences."""
