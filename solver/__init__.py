"""SLTR mathematics: pure numpy/scipy; imports nothing of mirrorsim, Mitsuba or OpenCV."""
