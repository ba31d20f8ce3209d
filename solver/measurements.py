"""The solver's inputs as one value (reading them from a file is
:mod:`mirrorsim.formats.measurements`')."""

from __future__ import annotations

from dataclasses import dataclass

from solver.lsq import BeaconMeasurement, ObjectSigmas

# σ's beyond these are no measurement: a bearing known to ±45° or a distance to ±100 %
SIGMA_ALPHA_MAX_DEG = 45.0
SIGMA_D_REL_MAX = 1.0


@dataclass(frozen=True)
class Measurements:
    """The solver's inputs: observer, target observations, beacons, optional σ's per
    observation."""

    observer: tuple[float, float]
    targets: list[tuple[float, float]]  # (alpha_deg, d_total) observations of the target
    beacons: list[BeaconMeasurement]
    sigma: ObjectSigmas | None = None
    # the optical axis's bearing (deg), where known: an error model's σ's depend on how
    # far off the axis each image is
    observer_pan_deg: float | None = None

    def to_json(self) -> dict:
        """The measurements document (one target observation as an object, several as a
        list)."""
        t = [{"alpha_deg": a, "d_total": d} for a, d in self.targets]
        out = {"observer": list(self.observer),
               "target": t[0] if len(t) == 1 else t,
               "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                            "d_total": b.d_total} for b in self.beacons]}
        if self.observer_pan_deg is not None:
            out["observer_pan_deg"] = self.observer_pan_deg
        if self.sigma is not None:
            out["sigma"] = sigma_json(self.sigma)
        return out


def sigma_json(sigma: ObjectSigmas) -> dict:
    """A ``sigma`` block: one pair where every observation shares it, else the target's
    and the beacons' (d_total_rel a fraction: 0.002 = 0.2 %)."""
    pair = lambda s: {"alpha_deg": s.alpha_deg, "d_total_rel": s.d_total_rel}  # noqa: E731
    if sigma.beacons == (sigma.target,) and not sigma.shared_alpha_deg:
        return pair(sigma.target)
    beacons = pair(sigma.beacons[0]) if len(sigma.beacons) == 1 else [pair(b) for b in
                                                                      sigma.beacons]
    out = {"target": pair(sigma.target), "beacons": beacons}
    if sigma.shared_alpha_deg:
        out["shared_alpha_deg"] = sigma.shared_alpha_deg
    return out
