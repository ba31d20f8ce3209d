"""What a track reports: each pose's record (the filter's estimate, the truth beside
it, the errors) and the whole run's, with its JSON."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solver.measurements import BeaconMeasurement


@dataclass(frozen=True)
class TrackStep:
    """One pose: where the beacon was and what the filter made of it."""

    step: int  # 0: the start
    commanded: tuple[float, float]  # the believed position
    path_length_cm: float  # commanded distance travelled so far
    beacon_position: tuple[float, float]  # the true one
    seen: bool
    why_unseen: str
    mirror_yaw_error_deg: float
    mirror_offset_error_cm: float
    target: tuple[float, float]
    target_error_cm: float
    yaw_spread_deg: float
    offset_spread_cm: float
    # the true mirror's squared Mahalanobis distance in the filter's (yaw, offset)
    # spread: χ²₂ (≤ 5.99 in 95 % of steps) where the filter's spread is honest
    mirror_nees: float = float("nan")

    def to_json(self) -> dict:
        """The step as docs/files.md's track report writes it."""
        return {"step": self.step, "beacon_position": list(self.beacon_position),
                "commanded_position": list(self.commanded),
                "path_length_cm": self.path_length_cm, "seen": self.seen,
                **({"why_unseen": self.why_unseen} if not self.seen else {}),
                "mirror_yaw_error_deg": self.mirror_yaw_error_deg,
                "mirror_offset_error_cm": self.mirror_offset_error_cm,
                "target": list(self.target), "target_error_cm": self.target_error_cm,
                "particle_spread": {"yaw_deg": self.yaw_spread_deg,
                                    "offset_cm": self.offset_spread_cm},
                "mirror_nees": self.mirror_nees}


@dataclass(frozen=True)
class TrackReport:
    """A whole track; ``snapshots`` (particles' mirror lines per step) feed the animation."""

    scene: str
    path: str
    heading: str
    odometry_sigma: float
    seed: int
    steps: tuple[TrackStep, ...]
    snapshots: tuple[np.ndarray, ...] = field(default=(), repr=False)
    # the beacons that stood still beside the moving one: believed position and the
    # observation (α_deg, d_total) the filter weighed once, the position known to
    # fixed_sigma cm per axis
    fixed: tuple[BeaconMeasurement, ...] = ()
    fixed_sigma: float = 0.0

    @property
    def final(self) -> TrackStep:
        """The last step."""
        return self.steps[-1]

    def to_json(self) -> dict:
        """docs/files.md's track report."""
        f = self.final
        return {"scene": self.scene, "path": self.path, "heading": self.heading,
                "odometry_sigma_cm": self.odometry_sigma,
                "seed": self.seed, "steps": [s.to_json() for s in self.steps],
                "fixed_beacons": [{"known_position": list(b.position),
                                   "position_sigma_cm": self.fixed_sigma,
                                   "alpha_deg": b.alpha_deg, "d_total": b.d_total}
                                  for b in self.fixed],
                "final": {"target": list(f.target),
                          "mirror_yaw_error_deg": f.mirror_yaw_error_deg,
                          "mirror_offset_error_cm": f.mirror_offset_error_cm,
                          "target_error_cm": f.target_error_cm,
                          "seen_poses": sum(s.seen for s in self.steps),
                          "poses": len(self.steps)}}
