"""Mitsuba: a scene as a Mitsuba scene, backends, passes, camera effects, frame files."""
