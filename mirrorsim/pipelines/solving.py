"""How a scene's measurements are solved: the error model chosen for its bench (the
shipped one, or the user's), the nuisances and priors that model's benches call for,
and of those only the ones the frames separate (:func:`solve_separated`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mirrorsim.errors import BadParameter
from mirrorsim.formats.error_model import ErrorModel
from mirrorsim.formats.error_model_file import default_error_model, load_error_model
from mirrorsim.scene import imperfections
from mirrorsim.scene.model import Scene
from solver.errors import SolverError
from solver.lsq import solve_measurements
from solver.measurements import BeaconMeasurement, ObjectSigmas
from solver.selfcal import NUISANCES, PLAIN, SelfCalibration, describe_priors
from solver.sltr import Solution

# a nuisance the frames determine no better than this (its σ from the solve's Fisher
# information, the mirror's pose marginalized) is not separated from the mirror: a
# pan σ of half a degree, a range scale's of 2 %, a power's of 1/(500 cm)
SEPARATED_SD = {"pan": 0.5, "scale": 0.02, "power": 2e-3}


# a nuisance whose prior holds it but which comes out held no tighter than this share
# of the prior's σ was held by the prior, not measured
HELD_SHARE = 0.8


# an estimate this many of its prior's σ's from its neutral value is outside what the
# bench's tolerances allow
FAR_SIGMAS = 3.0


def solve_separated(observer: tuple[float, float], beacons: list[BeaconMeasurement],
                    targets: list[tuple[float, float]], *, sigma: ObjectSigmas,
                    calibration: SelfCalibration, model: ErrorModel
                    ) -> tuple[Solution, SelfCalibration, list[str]]:
    """Solve, then hold every nuisance the beacons do not separate from the mirror.

    A nuisance estimated without a prior whose σ comes out above :data:`SEPARATED_SD`
    (the Fisher information's conditioning, whatever the beacon count) is solved again
    held at the prior the model's bench gives it, or at its neutral value where it gives
    none; the lines returned say so, and name the nuisances their priors held
    (:data:`HELD_SHARE`) and any estimate :data:`FAR_SIGMAS` prior σ's from neutral.

    Returns
    -------
    solution, the calibration it was solved with, the lines to print
    """
    sol = solve_measurements(observer, beacons, targets, sigma=sigma, calibration=calibration)
    said: list[str] = []
    sd = {n: sol.nuisance_sd.get(NUISANCES[n][0], 0.0) for n in calibration.nuisances}
    loose = [n for n in calibration.nuisances
             if n not in calibration.priors and sd[n] > SEPARATED_SD[n]]
    if loose:
        bench = model.tolerances.priors()
        calibration = SelfCalibration(
            tuple(n for n in calibration.nuisances if n not in loose or n in bench),
            calibration.position_sigma,
            {**calibration.priors, **{n: bench[n] for n in loose if n in bench}})
        for n in loose:
            said.append(f"{n}: the beacons do not separate it from the mirror (its σ would "
                        f"be {describe_priors({n: sd[n]}).split(' ', 1)[1]}); "
                        + (f"held at its prior {describe_priors({n: bench[n]})}" if n in bench
                           else "held at its neutral value"))
        sol = solve_measurements(observer, beacons, targets, sigma=sigma, calibration=calibration)
    held, far = [], []
    for n, prior in calibration.priors.items():
        if n == "pan" and sigma.shared_alpha_deg:
            prior = float(np.hypot(prior, sigma.shared_alpha_deg))
        name, neutral = NUISANCES[n]
        if sol.nuisance_sd.get(name, 0.0) > HELD_SHARE * prior:
            held.append(n)
        off = abs(sol.nuisances.get(name, neutral) - neutral) / prior
        if off > FAR_SIGMAS:
            far.append(f"{n} came out {off:.1f} of its prior's σ's from {neutral:g}")
    if held:
        said.append(f"held by their priors (the beacons do not separate them from the "
                    f"mirror): {', '.join(held)}")
    if far:
        said.append("warning: " + "; ".join(far) + ": beyond what the bench's tolerances "
                    "allow (a bench error larger than stated, or a bad image)")
    if calibration.nuisances or calibration.position_sigma:
        said += moved_from_plain(sol, solve_plain(observer, beacons, targets, sigma=sigma))
    return sol, calibration, said


# a self-calibrated target this far (cm) from plain least squares' estimate on the same
# measurements is said, with which of the two the beacons support: of 39 independent
# three-beacon benches, 10 came out worse than plain by over 0.1 cm (the largest 0.21 cm
# worse, nothing said where its nuisances were separated)
MOVED_CM = 0.1
# the Hausman test's level: below it, the move is more than the nuisances' added
# variance explains, and the bench's errors are shown
MOVED_P = 0.05


def solve_plain(observer: tuple[float, float], beacons: list[BeaconMeasurement],
                targets: list[tuple[float, float]], *, sigma: ObjectSigmas) -> Solution | None:
    """Plain least squares on the same measurements and σ's (None where it fails)."""
    try:
        return solve_measurements(observer, beacons, targets, sigma=sigma)
    except SolverError:
        return None


def moved_from_plain(sol: Solution, plain: Solution | None) -> list[str]:
    """A line where the self-calibrated target lies over MOVED_CM from plain least
    squares' (``plain``; none where equal or absent), saying whether the beacons support
    the move: Hausman's χ² of the difference against the variance the nuisances add
    (the calibrated covariance less plain's), efficient plain against consistent
    calibrated (the same at p ≥ MOVED_P: no bench error shows beyond the noise)."""
    from scipy.stats import chi2

    if plain is None or sol.target_covariance is None or plain.target_covariance is None:
        return []
    delta = np.asarray(sol.target, float) - np.asarray(plain.target, float)
    dist = float(np.hypot(*delta))
    if dist <= MOVED_CM:
        return []
    # the two covariances are taken at different points: a direction the nuisances add
    # under a thousandth of the largest variance to is numerical, not tested
    w, u = np.linalg.eigh(sol.target_covariance - plain.target_covariance)
    keep = w > 1e-3 * max(float(w.max()), 1e-30)
    x, y = (float(v) for v in plain.target)
    said = (f"self-calibration moved the target {dist:.2f} cm from plain least squares' "
            f"({x:.2f}, {y:.2f})")
    if not keep.any():
        return [said]
    stat = float(sum((u[:, k] @ delta) ** 2 / w[k] for k in np.flatnonzero(keep)))
    dof = int(keep.sum())
    p = float(chi2.sf(stat, dof))
    verdict = ("the beacons show bench errors that plain leaves in" if p < MOVED_P else
               "the beacons show no bench error beyond their noise: plain's is as likely")
    return [f"{said}; {verdict} (χ² {stat:.1f} on {dof}, p {p:.3f})"]


def as_error_model(error_model: object) -> ErrorModel | None:
    """``error_model`` as a model: None (the shipped one the scene calls for), a model,
    or a model file's path (read and checked now, before anything renders).

    Raises
    ------
    BadParameter
        Anything else.
    ErrorModelError
        A path to a file that is not a valid model.
    """
    if error_model is None or isinstance(error_model, ErrorModel):
        return error_model
    if isinstance(error_model, str | Path):
        return load_error_model(error_model)
    raise BadParameter("error_model", f"{error_model!r}: give an ErrorModel, a model file's "
                       "path, or None for the shipped model")


def model_for(scene: Scene, error_model: ErrorModel | None = None) -> ErrorModel:
    """``error_model``, or the model shipped for the scene's bench: the bench model for a
    scene with bench imperfections (their presence, never their values), the ideal
    model otherwise."""
    error_model = as_error_model(error_model)
    if error_model is not None:
        return error_model
    return default_error_model("bench" if imperfections.sources(scene) else "ideal")


def model_calibration(model: ErrorModel, asked: SelfCalibration = PLAIN) -> SelfCalibration:
    """What a solve with ``model``'s σ's estimates: the nuisances ``asked`` for, and every
    shared error of the model's benches (:class:`~mirrorsim.formats.error_model.
    BenchTolerances`) with its prior; a prior ``asked`` gives (what the user states of
    their bench) wins over the model's, and a position σ ``asked`` over its own.  An
    ideal-bench model adds nothing."""
    bench = model.tolerances.calibration()
    if not bench.nuisances and not bench.position_sigma:
        return asked
    nuisances = asked.nuisances + tuple(n for n in bench.nuisances if n not in asked.nuisances)
    priors = {**{n: s for n, s in bench.priors.items() if n in nuisances}, **asked.priors}
    return SelfCalibration(nuisances, asked.position_sigma or bench.position_sigma, priors)
