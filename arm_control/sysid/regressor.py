"""The arm's dynamics, linear in its base parameters: τ = Y(θ, θ̇, θ̈)·π.

Pedersen's model with friction (``arm_control.model.dynamics``), θ = (θa, θb), elbow relative:

    τ_motor = M(θ)θ̈ + C(θ, θ̇)θ̇ + τg(θ) + b·θ̇ + c·tanh(θ̇/ω_s)

With the upper arm's length La, g and ω_s known, every term is linear in eight combinations
of the physical parameters, the base parameters π:

    α  = ma·ra² + Ia + mb·(La² + rb²) + Ib   shoulder inertia, forearm square (M00 at θb = 90°)
    γ  = mb·rb² + Ib                         forearm inertia about the elbow (M11)
    p1 = ma·ra + mb·La                       first moment of mass about the shoulder
    p2 = mb·rb                               forearm's first moment about the elbow
    b_a, c_a, b_b, c_b                       viscous (N·m·s/rad) and Coulomb (N·m) friction

The coupling β = mb·La·rb is La·p2, so M00 = α + 2·La·p2·cos θb, M01 = γ + La·p2·cos θb and
h = La·p2·sin θb in C. The rows of Y, from M, C and τg term by term:

    τa = α·θ̈a + γ·θ̈b + p1·g·cos θa
         + p2·[La·(cos θb·(2θ̈a + θ̈b) − sin θb·(2θ̇a + θ̇b)·θ̇b) + g·cos(θa + θb)]
         + b_a·θ̇a + c_a·tanh(θ̇a/ω_s)
    τb = γ·(θ̈a + θ̈b) + p2·[La·(cos θb·θ̈a + sin θb·θ̇a²) + g·cos(θa + θb)]
         + b_b·θ̇b + c_b·tanh(θ̇b/ω_s)

What motion can and cannot tell. The eight base parameters are identifiable from a motion
that excites every column (gravity at several angles, both directions of travel, speeds and
accelerations of both joints). The six inertial parameters (ma, ra, Ia, mb, rb, Ib) enter
only through α, γ, p1 and p2, so two degrees of freedom stay unknown whatever the motion:
a link's mass cannot be told from where its centre of mass is (only mb·rb and mb·rb² + Ib
are seen), nor the upper arm's from the forearm's (mb·La adds to ma·ra). Any choice that
keeps π moves the arm identically, so ``realise`` writes the one that keeps each link's
shape from the robot file -- its radius of gyration about its centre of mass, k² = I/m --
and solves mass, centre of mass and inertia from π; weigh a link to know its mass.
"""

from dataclasses import dataclass, replace
import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.dynamics import COULOMB_SMOOTHING_RAD_S

# (name, unit, what it is); the order of π.
BASE_PARAMETERS = (
    ('shoulder_inertia', 'kg m^2', 'alpha = ma ra^2 + Ia + mb (La^2 + rb^2) + Ib'),
    ('elbow_inertia', 'kg m^2', 'gamma = mb rb^2 + Ib'),
    ('shoulder_moment', 'kg m', 'p1 = ma ra + mb La'),
    ('elbow_moment', 'kg m', 'p2 = mb rb'),
    ('shoulder_viscous', 'N m s/rad', 'shoulder viscous friction b_a'),
    ('shoulder_coulomb', 'N m', 'shoulder Coulomb friction c_a'),
    ('elbow_viscous', 'N m s/rad', 'elbow viscous friction b_b'),
    ('elbow_coulomb', 'N m', 'elbow Coulomb friction c_b'),
)
BASE_NAMES = tuple(name for name, _, _ in BASE_PARAMETERS)
PARAMETER_COUNT = len(BASE_PARAMETERS)


def base_parameters(arm: ArmConfig) -> np.ndarray:
    """π of an arm description, in the order of ``BASE_PARAMETERS``."""
    upper, fore = arm.shoulder, arm.elbow
    ma, mb = upper.mass_kg, fore.mass_kg
    ra, rb, la = upper.com_from_joint_m, fore.com_from_joint_m, upper.length_m
    gamma = mb * rb ** 2 + fore.inertia_about_com_kgm2
    return np.array([
        ma * ra ** 2 + upper.inertia_about_com_kgm2 + mb * la ** 2 + gamma,
        gamma,
        ma * ra + mb * la,
        mb * rb,
        upper.viscous_friction_nm_s_per_rad, upper.coulomb_friction_nm,
        fore.viscous_friction_nm_s_per_rad, fore.coulomb_friction_nm,
    ])


def regressor(arm: ArmConfig, q, qd, qdd) -> np.ndarray:
    """Y with shape (N, 2, 8) for N samples of θ, θ̇, θ̈ (each (N, 2)): τ_motor = Y·π.

    Only La and g are taken from ``arm``.
    """
    q, qd, qdd = (np.atleast_2d(np.asarray(v, float)) for v in (q, qd, qdd))
    la, g = arm.shoulder.length_m, arm.gravity_mps2
    cos_b, sin_b = np.cos(q[:, 1]), np.sin(q[:, 1])
    outer = g * np.cos(q[:, 0] + q[:, 1])
    zero = np.zeros(len(q))
    shoulder = [
        qdd[:, 0], qdd[:, 1], g * np.cos(q[:, 0]),
        la * (cos_b * (2.0 * qdd[:, 0] + qdd[:, 1])
              - sin_b * (2.0 * qd[:, 0] + qd[:, 1]) * qd[:, 1]) + outer,
        qd[:, 0], np.tanh(qd[:, 0] / COULOMB_SMOOTHING_RAD_S), zero, zero,
    ]
    elbow = [
        zero, qdd[:, 0] + qdd[:, 1], zero,
        la * (cos_b * qdd[:, 0] + sin_b * qd[:, 0] ** 2) + outer,
        zero, zero, qd[:, 1], np.tanh(qd[:, 1] / COULOMB_SMOOTHING_RAD_S),
    ]
    return np.stack([np.stack(shoulder, axis=-1), np.stack(elbow, axis=-1)], axis=1)


class RealisationError(ValueError):
    """Identified base parameters that no arm description in arm.yaml's terms can hold."""


@dataclass(frozen=True)
class Realisation:
    """Physical parameters that give π exactly, per joint, and what had to be chosen."""

    values: dict            # {'shoulder.mass_kg': ..., ...}: only what identification sets
    notes: tuple            # sentences: the choices made (clamped friction, changed shapes)


def _link_from_moments(moment, inertia, shape_k2, name):
    """Mass m, centre of mass r, inertia about it I from m·r = ``moment`` and
    m·r² + I = ``inertia``, keeping I/m = ``shape_k2`` where that is possible.

    r² − (inertia/moment)·r + k² = 0: the root nearer a long link's is taken (the larger).
    With no real root the link is made as compact as it can be: r = inertia/(2·moment),
    I = inertia/2.
    """
    if inertia <= 0.0:
        raise RealisationError(f'the identified {name} inertia about its joint, '
                               f'{inertia:.4g} kg m^2, is not positive')
    if moment <= 1e-9 * inertia:
        return None
    ratio = inertia / moment
    discriminant = ratio ** 2 - 4.0 * shape_k2
    note = ''
    if discriminant < 0.0:
        discriminant = 0.0
        note = (f'the {name} is more compact than its file says (I/m = {shape_k2:.4g} m^2 '
                f'cannot hold m r = {moment:.4g} kg m and m r^2 + I = {inertia:.4g} kg m^2): '
                'written with I = half its inertia about the joint')
    radius = 0.5 * (ratio + math.sqrt(discriminant))
    mass = moment / radius
    return mass, radius, max(inertia - mass * radius ** 2, 0.0), note


def realise(base, nominal: ArmConfig) -> Realisation:
    """Masses, centres of mass and inertias (and friction) that realise π exactly.

    Each link keeps the nominal file's radius of gyration about its centre of mass where it
    can; the forearm is solved first from p2 and γ, then the upper arm from p1 − mb·La and
    α − γ − mb·La². The forearm's mass must lie between p2²/γ (inertia about its centre
    of mass ≥ 0) and what leaves the upper arm a moment and an inertia ≥ 0 (mb·La ≤ p1,
    mb·La² < α − γ); outside that, it is moved to the nearer end, with a note. A link whose
    first moment is zero keeps its nominal mass, with its centre of mass on the joint.
    Friction below zero (noise about a frictionless joint) is written as 0. Raises
    ``RealisationError`` when no arm in arm.yaml's terms has these π (centres of mass are
    distances from the joint, >= 0, and inertias are positive).
    """
    alpha, gamma, p1, p2 = (float(v) for v in base[:4])
    la = nominal.shoulder.length_m
    notes, values = [], {}

    def k2(joint):
        return joint.inertia_about_com_kgm2 / joint.mass_kg if joint.mass_kg > 0.0 else 0.0

    if p2 < -1e-6 * max(gamma, 1e-9):
        raise RealisationError(
            f'the identified forearm moment mb rb = {p2:.4g} kg m puts its centre of mass '
            'behind the elbow, which com_from_joint_m >= 0 cannot describe')
    if gamma <= 0.0:
        raise RealisationError(f'the identified forearm inertia about the elbow, '
                               f'{gamma:.4g} kg m^2, is not positive')
    p2 = max(p2, 0.0)
    lightest = p2 ** 2 / gamma
    heaviest = min(p1 / la, (1.0 - 1e-9) * (alpha - gamma) / la ** 2)
    if heaviest < lightest or heaviest <= 0.0:
        raise RealisationError(
            f'no forearm mass fits the identified moments and inertias (alpha = {alpha:.4g}, '
            f'gamma = {gamma:.4g} kg m^2, p1 = {p1:.4g}, p2 = {p2:.4g} kg m): it would need '
            f'at least {lightest:.4g} kg and at most {heaviest:.4g} kg')
    fore = _link_from_moments(p2, gamma, k2(nominal.elbow), 'forearm')
    if fore is None:
        fore = (nominal.elbow.mass_kg, 0.0, gamma, "the forearm's centre of mass is on the "
                "elbow: its mass is not seen, the file's is kept")
    mb = min(max(fore[0], lightest), heaviest)
    if mb != fore[0]:
        radius = p2 / mb if mb > 0.0 else 0.0
        fore = (mb, radius, max(gamma - mb * radius ** 2, 0.0),
                f"the forearm cannot keep its file's shape (that would make it {fore[0]:.4g} "
                f'kg, beyond what the moments allow): written as {mb:.4g} kg')
    upper_moment = max(p1 - mb * la, 0.0)
    upper_inertia = alpha - gamma - mb * la ** 2
    upper = _link_from_moments(upper_moment, upper_inertia, k2(nominal.shoulder), 'upper arm')
    if upper is None:
        upper = (nominal.shoulder.mass_kg, 0.0, upper_inertia,
                 "the upper arm's centre of mass is on the shoulder: its mass is not seen, "
                 "the file's is kept")
    for joint, (mass, radius, inertia, note) in (('shoulder', upper), ('elbow', fore)):
        values[f'{joint}.mass_kg'] = mass
        values[f'{joint}.com_from_joint_m'] = radius
        values[f'{joint}.inertia_about_com_kgm2'] = inertia
        if note:
            notes.append(note)
    for index, joint in ((4, 'shoulder'), (6, 'elbow')):
        for offset, field in ((0, 'viscous_friction_nm_s_per_rad'), (1, 'coulomb_friction_nm')):
            value = float(base[index + offset])
            if value < 0.0:
                notes.append(f'{joint}.{field} identified as {value:.4g}, written as 0')
                value = 0.0
            values[f'{joint}.{field}'] = value
    return Realisation(values, tuple(notes))


def with_values(arm: ArmConfig, values: dict) -> ArmConfig:
    """``arm`` with ``{'joint.field': value}`` changed (what a parameter overlay does)."""
    joints = {}
    for name, value in values.items():
        joint, field = name.split('.')
        joints.setdefault(joint, {})[field] = value
    return replace(arm, **{joint: replace(getattr(arm, joint), **fields)
                           for joint, fields in joints.items()})
