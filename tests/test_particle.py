import numpy as np

from solver.geometry import line_normal
from solver.particle import (
    MovingBeaconFilter,
    PFParams,
    initial_particles,
    mirror_errors,
    pf_step,
    simulate_run,
    track,
)
from solver.placement import path_points

OBS, M, YAW = np.zeros(2), np.array([27.5, 65.0]), 38.0


def _run(seed=1):
    path = path_points("rectangular", (30.0, 60.0), 66.7, 4.0, 2.0, 6)
    params = PFParams()
    controls, obs, true = simulate_run(OBS, M, YAW, path, params, seed)
    return path, controls, obs, true, params


def test_filter_converges_on_the_mirror():
    path, controls, obs, _, params = _run()
    rho = line_normal(YAW) @ M
    est = track(OBS, path[0], controls, obs, (YAW - 15, YAW + 15), (rho - 8, rho + 8),
                n=4000, params=params, rng=2)
    yaw_err, off_err = mirror_errors(est, M, YAW)
    assert abs(yaw_err[-1]) < 0.5 and off_err[-1] < 0.2
    # error falls along the path: the last three steps beat the first three
    assert np.mean(np.abs(yaw_err[-3:])) < 0.25 * np.mean(np.abs(yaw_err[:3]))


def test_pure_step_and_class_agree():
    path, controls, obs, _, params = _run()
    rho = line_normal(YAW) @ M
    f = MovingBeaconFilter(OBS, path[0], (YAW - 15, YAW + 15), (rho - 8, rho + 8), n=500,
                           params=params, rng=9)
    w = f.weights.copy()
    # replay the class's generator from the same seed: the initial draws come first
    rng = np.random.default_rng(9)
    p = initial_particles(path[0], (YAW - 15, YAW + 15), (rho - 8, rho + 8), 500, params, rng)
    for c, z in zip(controls, obs, strict=True):
        f.step(c, z)
        p, w = pf_step(p, w, c, z, OBS, params, rng)
        assert np.array_equal(p, f.particles) and np.array_equal(w, f.weights)
