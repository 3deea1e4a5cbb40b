"""What the arm's sensors report (arm paper §5.2).

Potentiometers on the joints: absolute angle with Gaussian noise. The motors' integrated
encoders: relative (zero where counting started), read through the gearbox, so the joint
can move inside the gear lash without the motor turning.
"""

from dataclasses import dataclass

import numpy as np


@dataclass
class Backlash:
    """The motor side's joint-equivalent angle, dragged along once the lash is taken up.

    The motor side lags the joint by at most half the lash in either direction.
    """

    lash_rad: float
    motor_side_rad: float

    def follow(self, joint_rad: float) -> float:
        half = 0.5 * self.lash_rad
        if joint_rad - self.motor_side_rad > half:
            self.motor_side_rad = joint_rad - half
        elif self.motor_side_rad - joint_rad > half:
            self.motor_side_rad = joint_rad + half
        return self.motor_side_rad


class Sensors:
    """Potentiometers and encoders of both joints; noise drawn from a seeded generator."""

    def __init__(self, joints, position, rng: np.random.Generator):
        self.rng = rng
        self.position_noise_rad = np.array([j.potentiometer_noise_rad for j in joints])
        self.velocity_noise_rad_s = np.array([j.velocity_noise_rad_s for j in joints])
        self.lash_rad = [j.encoder_backlash_rad for j in joints]
        self.zero(position)

    def zero(self, position) -> None:
        """Start counting the encoders from here (a power cycle)."""
        self.backlash = [Backlash(lash, float(p)) for lash, p in zip(self.lash_rad, position)]
        self.encoder_zero_rad = [float(p) for p in position]

    def follow(self, position) -> None:
        """Move the motor sides with the joints; call at every physics step."""
        for lash, angle in zip(self.backlash, position):
            lash.follow(angle)

    def potentiometers(self, position, velocity) -> tuple[np.ndarray, np.ndarray]:
        """Noisy absolute angles and velocities."""
        noise = self.rng.standard_normal(4)
        return (np.asarray(position, float) + self.position_noise_rad * noise[:2],
                np.asarray(velocity, float) + self.velocity_noise_rad_s * noise[2:])

    def encoders(self) -> np.ndarray:
        """Joint angles from the motors' encoders, relative to where they were zeroed."""
        return np.array([lash.motor_side_rad - zero
                         for lash, zero in zip(self.backlash, self.encoder_zero_rad)])
