"""The scene as data: the frozen model and the registry of bench imperfections."""
