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
    return sol, calibration, said


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
