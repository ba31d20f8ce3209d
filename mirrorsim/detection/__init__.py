"""Pixels + capture record -> measurements (edges, pixel geometry, beacons, the detector).

Nothing here imports the truth, the optics or the scene-file reader (a test keeps it so)."""
