"""The solver's inputs as one value (reading them from a file is
:mod:`mirrorsim.formats.measurements`')."""

from __future__ import annotations

from dataclasses import dataclass

from solver.lsq import BeaconMeasurement, Sigma

# σ's beyond these are no measurement: a bearing known to ±45° or a distance to ±100 %
SIGMA_ALPHA_MAX_DEG = 45.0
SIGMA_D_REL_MAX = 1.0


@dataclass(frozen=True)
class Measurements:
    """The solver's inputs: observer, target observations, beacons, optional σ's."""

    observer: tuple[float, float]
    targets: list[tuple[float, float]]  # (alpha_deg, d_total) observations of the target
    beacons: list[BeaconMeasurement]
    sigma: Sigma | None = None

    def to_json(self) -> dict:
        """The measurements document (one target observation as an object, several as a
        list)."""
        t = [{"alpha_deg": a, "d_total": d} for a, d in self.targets]
        out = {"observer": list(self.observer),
               "target": t[0] if len(t) == 1 else t,
               "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                            "d_total": b.d_total} for b in self.beacons]}
        if self.sigma is not None:
            out["sigma"] = {"alpha_deg": self.sigma.alpha_deg,
                            "d_total_rel": self.sigma.d_total_rel}
        return out
