"""Self-calibrating SLTR: a pan offset and a range scale shared by every measurement,
estimated with the mirror from several beacons at known positions."""

import numpy as np
import pytest

from solver.errors import SolverError
from solver.lsq import BeaconMeasurement, ObjectSigmas, Sigma, crlb, solve_measurements
from solver.sltr import observe

OBS = np.zeros(2)
MIRROR = (np.array([40.0, 40.0]), 20.0)
TARGET = np.array([52.0, 20.0])
BEACONS = [np.array([30.0, 25.0]), np.array([45.0, 28.0]), np.array([20.0, 30.0])]
SIG = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),))
RHO = float(np.array([-np.sin(np.radians(20)), np.cos(np.radians(20))]) @ MIRROR[0])


def _measure(rng, delta=0.0, scale=1.0, beacons=BEACONS):
    """Exact images, then the bench's pan offset and range scale, then detector noise."""
    bs = []
    for b in beacons:
        o = observe(OBS, *MIRROR, b)
        bs.append(BeaconMeasurement(tuple(b), float(o.alpha_deg) + delta + rng.normal(0, 0.003),
                                    float(o.d_total) * scale * (1 + rng.normal(0, 0.002))))
    o = observe(OBS, *MIRROR, TARGET)
    return bs, [(float(o.alpha_deg) + delta + rng.normal(0, 0.002),
                 float(o.d_total) * scale * (1 + rng.normal(0, 0.0005)))]


def test_self_calibration_removes_a_pan_offset_and_a_range_scale():
    """δ = 0.4°, s = 1.008 on three beacons: plain least squares is biased by them; the
    self-calibrated estimate's median error is under a third of it, its δ and s come
    out within 3 of their own σ's, and its error is what its CRLB says (RMS within 25 %)."""
    rng = np.random.default_rng(3)
    plain, cal, z = [], [], []
    for _ in range(300):
        bs, ts = _measure(rng, 0.4, 1.008)
        plain.append(np.linalg.norm(solve_measurements(OBS, bs, ts, SIG).target - TARGET))
        sol = solve_measurements(OBS, bs, ts, SIG, nuisances=("pan", "scale"))
        cal.append(np.linalg.norm(sol.target - TARGET))
        sd = np.sqrt(np.diag(sol.covariance))
        z.append([(sol.nuisances["pan_offset_deg"] - 0.4) / sd[4],
                  (sol.nuisances["range_scale"] - 1.008) / sd[5]])
    assert np.median(cal) < np.median(plain) / 3
    assert np.mean(np.abs(np.array(z)) < 3, axis=0).min() > 0.97
    bound = crlb(OBS, BEACONS, 20.0, RHO, TARGET, SIG, nuisances=("pan", "scale"))
    assert np.sqrt(np.mean(np.square(cal))) == pytest.approx(
        np.sqrt(np.trace(bound[2:4, 2:4])), rel=0.25)


def test_the_bound_with_nuisances_is_never_below_the_bound_without():
    plain = crlb(OBS, BEACONS, 20.0, RHO, TARGET, SIG)[2:4, 2:4]
    cal = crlb(OBS, BEACONS, 20.0, RHO, TARGET, SIG, nuisances=("pan", "scale"))[2:4, 2:4]
    assert np.all(np.linalg.eigvalsh(cal - plain) > -1e-12)


def test_self_calibration_refuses_what_it_cannot_observe():
    rng = np.random.default_rng(0)
    bs, ts = _measure(rng)
    with pytest.raises(SolverError, match="at least 2 beacon observations"):
        solve_measurements(OBS, bs[:1], ts, SIG, nuisances=("pan", "scale"))
    with pytest.raises(SolverError, match="unknown or repeated"):
        solve_measurements(OBS, bs, ts, SIG, nuisances=("roll",))
    # two beacons standing at one place: their images cannot separate δ and s
    same = [bs[0], BeaconMeasurement(bs[0].position, bs[0].alpha_deg, bs[0].d_total)]
    with pytest.raises(SolverError, match="do not separate"):
        solve_measurements(OBS, same, ts, SIG, nuisances=("pan", "scale"))
