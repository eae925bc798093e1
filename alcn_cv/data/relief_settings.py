"""Settings of ``alcn data scenes`` (:mod:`alcn_cv.data.relief_scenes`): its lightings and frame counts, apart from
the renderer so that the command line's help and the benchmarks read them without importing it."""

from __future__ import annotations

__all__ = ["AZIMUTHS", "DIRECTIONAL_FRAMES", "ELEVATIONS", "FRAMES", "LIGHTINGS", "MAX_SIDE", "MIN_SIDE"]

#: The least side of the frames (pixels).
MIN_SIDE = 32
#: The largest side of the frames (pixels): a scene's frames are rendered together, about 3 GB at 1024 for the
#: default 12 frames and growing with the side's square (13 GB at 2048).
MAX_SIDE = 2048
#: The lightings of a run (see the module).
LIGHTINGS = ("families", "directional")
#: ``directional``: elevations of the probes' light above the ground (degrees); the gallery is lit from 90.
ELEVATIONS = (75, 55, 35, 20, 12)
#: ``directional``: probes per elevation, each from a random azimuth.
AZIMUTHS = 4
#: ``directional``: frames of a scene, the gallery then the probes, elevation by elevation.
DIRECTIONAL_FRAMES = 1 + len(ELEVATIONS) * AZIMUTHS
#: ``families``: frames of a scene unless given.
FRAMES = 12
