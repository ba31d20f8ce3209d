"""Stages joined: render -> calibrate -> detect -> solve -> score; evaluate, budget,
track, dataset, error model, planning."""
