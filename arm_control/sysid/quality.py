"""Which base parameters a log pins down, and why not the others.

A parameter is written when the data either pin it down or contradict the robot file:

- pinned down: σ ≤ ``MAX_RELATIVE_SIGMA``·|π| -- the value is known to that share, and so
  lies more than 1/MAX_RELATIVE_SIGMA (2.5) standard errors from zero;
- contradicting the file: the robot file's value lies more than ``CONTRADICTS_SIGMA``
  standard errors from the estimate -- the estimate, loose as it is, is nearer the arm
  (a friction the file has and the arm lacks is written as near 0).

Otherwise the log cannot tell it from the file's value, and it is not written: the file's
value stays. The report gives its ±2σ, as a share of its value and as the share of its
joint's torque that band moves (2σ·RMS(its column) over RMS(torque)), the parameter its
estimate is most correlated with (the direction the excitation leaves open: collinear
columns make a large condition number), and, for Coulomb friction, whether the joint moved
both ways (c·tanh(θ̇/ω_s) needs both directions of travel to be told from gravity). A
parameter whose column the motion never excites (a joint that did not move) has σ = ∞. If
any of the four inertial base parameters is not written, no mass, centre of mass or
inertia is (they are solved from all four together).
"""

from dataclasses import dataclass

import numpy as np

from arm_control.config import ArmConfig
from arm_control.sysid.fit import FitResult, MIN_SAMPLES, PARAMETER_JOINT
from arm_control.sysid.regressor import (BASE_NAMES, BASE_PARAMETERS, base_parameters,
                                         Realisation, realise)

INERTIAL_FIELDS = ('mass_kg', 'com_from_joint_m', 'inertia_about_com_kgm2')
FRICTION_FIELDS = {4: 'shoulder.viscous_friction_nm_s_per_rad',
                   5: 'shoulder.coulomb_friction_nm',
                   6: 'elbow.viscous_friction_nm_s_per_rad', 7: 'elbow.coulomb_friction_nm'}
MAX_RELATIVE_SIGMA = 0.4
CONTRADICTS_SIGMA = 3.0
INERTIAL = 4                    # α, γ, p1, p2 come first in π
COULOMB = {5: 0, 7: 1}          # index in π: joint
JOINTS = ('shoulder', 'elbow')


@dataclass(frozen=True)
class Quality:
    """Per base parameter (in π's order): what the log says about it."""

    identified: np.ndarray           # (8,) bool
    pinned: np.ndarray               # (8,) bool: σ ≤ MAX_RELATIVE_SIGMA·|π|
    file_sigmas: np.ndarray          # (8,) |π − π_file|/σ
    relative_sigma: np.ndarray       # (8,) σ/|π|
    torque_share: np.ndarray         # (8,) 2σ·RMS(column) / RMS(joint torque)
    reasons: tuple                   # (8,) why not identified (a sentence), or None
    condition_number: float

    @property
    def inertial_identified(self) -> bool:
        return bool(np.all(self.identified[:INERTIAL]))

    @property
    def unidentified(self) -> list:
        return [name for name, ok in zip(BASE_NAMES, self.identified) if not ok]


def assess(fit: FitResult, nominal: ArmConfig) -> Quality:
    """What the log says of each base parameter of ``fit`` (see the module's rule)."""
    sigma = fit.standard_errors
    with np.errstate(divide='ignore', invalid='ignore'):
        relative = sigma / np.abs(fit.parameters)
        away = np.abs(fit.parameters - base_parameters(nominal)) / sigma
        scale = np.array([fit.torque_rms_nm[j] for j in PARAMETER_JOINT])
        share = 2.0 * sigma * fit.column_rms / scale
        correlations = fit.covariance / np.outer(sigma, sigma)
    finite = np.isfinite(sigma)
    pinned = finite & (relative <= MAX_RELATIVE_SIGMA)
    identified = pinned | (finite & (away > CONTRADICTS_SIGMA))
    reasons = []
    for k, (name, unit, _) in enumerate(BASE_PARAMETERS):
        if identified[k]:
            reasons.append(None)
            continue
        if not finite[k]:
            reasons.append('the motion never excites it: the joint did not move in the '
                           'samples used')
            continue
        correlation = np.where(finite, correlations[k], 0.0)
        correlation[k] = 0.0
        other = int(np.argmax(np.abs(correlation)))
        reason = (f'+/- 2 sigma = {2 * sigma[k]:.3g} {unit}: {relative[k]:.0%} of its value '
                  f'and {share[k]:.1%} of the {JOINTS[PARAMETER_JOINT[k]]} torque, and the '
                  f"robot file's value within {away[k]:.1f} sigma; most correlated with "
                  f'{BASE_NAMES[other]} ({correlation[other]:+.2f})')
        if k in COULOMB:
            backward, forward = fit.moving_samples[COULOMB[k]]
            if min(backward, forward) < MIN_SAMPLES:
                reason += (f'; the {JOINTS[COULOMB[k]]} moved one way in {backward} samples '
                           f'and the other in {forward}: Coulomb friction needs both')
        reasons.append(reason)
    return Quality(identified, pinned, away, relative, share, tuple(reasons),
                   fit.condition_number)


def identified_values(fit: FitResult, nominal: ArmConfig) -> tuple[Realisation, Quality]:
    """The physical values to write: ``realise`` of π with what is not identified left out
    (and a note for each). With the inertial part unidentified, the friction is realised
    beside the robot file's inertial base parameters; raises ``RealisationError`` (from
    ``realise``) when the identified inertial part is no arm."""
    quality = assess(fit, nominal)
    parameters = np.array(fit.parameters, float)
    notes = []
    if not quality.inertial_identified:
        parameters[:INERTIAL] = base_parameters(nominal)[:INERTIAL]
        notes.append('no mass, centre of mass or inertia written: '
                     + ', '.join(n for n in quality.unidentified if n in BASE_NAMES[:INERTIAL])
                     + ' not identified')
    realisation = realise(parameters, nominal)
    drop = set()
    if not quality.inertial_identified:
        drop |= {f'{joint}.{field}' for joint in JOINTS for field in INERTIAL_FIELDS}
    for k, name in FRICTION_FIELDS.items():
        if not quality.identified[k]:
            drop.add(name)
    for k, reason in enumerate(quality.reasons):
        if reason is not None:
            notes.append(f'{BASE_NAMES[k]} not identified ({reason}): not written')
    values = {name: v for name, v in realisation.values.items() if name not in drop}
    kept = [note for note in realisation.notes
            if not any(name.split('.')[1] in note for name in drop)]
    return Realisation(values, tuple(notes + kept)), quality
