"""Equivalence classes of candidate effects and the held-out test that separates their members.

Several forms of missing physics leave nearly the same residual on a given set of logs: a servo whose
kp is low and a series spring both soften a joint; an encoder offset, gear backlash under a one-sided
load and a centre of mass off the joint axis all shift a joint's static angle. A family is named
(*Found*) only when its best fit beats the best fit of every other member of its class on held-out
logs beyond the noise; otherwise the report names the class, its candidates, and the excitation
segment (:mod:`sysid.excitation`) that would tell them apart.

The test (:func:`heldout_test`) compares the two fitted models' Gaussian log-likelihoods on the
held-out windows, ℓ = -½ Σ (e / floor)², against the part of their difference that noise of the
residual's level and autocorrelation could make: a likelihood-ratio test of two fitted models on
held-out data (Q. H. Vuong, "Likelihood ratio tests for model selection and non-nested hypotheses",
Econometrica 57(2), 1989).

Classes (:data:`CLASSES`) and the segments that separate their members (:data:`SEPARATING`) are this
library's; a family may be in more than one class (an encoder offset is a static offset and a
static load alike). Its rivals are the members of all its classes (:func:`rival_families`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from sysid.candidates import COM_AXES, FAMILIES, Term, com_target, joints_above, links_below, term_allowed, term_link


@dataclass(frozen=True)
class EffectClass:
    """Families that can leave the same residual on one joint or link.

    Attributes:
        name: class name.  words: what the report calls what they share (e.g. "actuator stiffness").
        families: the members (names of :data:`sysid.candidates.FAMILIES`).
    """

    name: str
    words: str
    families: tuple[str, ...]


CLASSES: dict[str, EffectClass] = {c.name: c for c in (
    EffectClass("stiffness", "actuator stiffness", ("pd_gain", "torque_constant", "joint_compliance")),
    EffectClass("damping", "joint damping", ("kd_gain", "viscous_damping")),
    EffectClass("offset", "static angle offset", ("sensor_bias", "encoder_offset", "backlash_motor", "link_com")),
    EffectClass("play", "gear play", ("backlash", "backlash_motor", "backlash_link")),
    EffectClass("transmission", "transmission (a series spring or gear play)",
                ("joint_compliance", "backlash", "backlash_motor", "backlash_link")),
    EffectClass("lag", "command lag", ("latency", "command_lowpass")),
    EffectClass("load", "static load", ("link_mass", "link_com", "pd_gain")),
    EffectClass("saturation", "actuator torque limit", ("torque_limit", "joint_torque_limit", "back_emf")),
    EffectClass("dry_friction", "dry joint friction", ("coulomb_friction", "stribeck_friction")),
    EffectClass("hysteresis", "hysteresis (stiction or play)", ("coulomb_friction", "backlash", "backlash_motor")),
    EffectClass("inertia", "joint inertia", ("armature", "link_inertia")),
)}

#: Excitation segment (:data:`sysid.excitation.KNOWN_SEGMENTS`) and what it shows, per pair of families.
SEPARATING: dict[frozenset, tuple[str, str]] = {
    frozenset({"pd_gain", "torque_constant"}): (
        "velocity_sweep", "moves at several constant speeds: a kp-only error changes the lag behind a ramp "
                          "(kd qdot / kp), a torque-constant error scales kp and kd together and keeps it"),
    frozenset({"pd_gain", "joint_compliance"}): (
        "velocity_sweep", "moves at several constant speeds and their stops: a series spring takes the servo damping "
                          "off the output (it rings after each stop), a kp error keeps it"),
    frozenset({"torque_constant", "joint_compliance"}): (
        "velocity_sweep", "moves at several constant speeds and their stops: a series spring takes the servo "
                          "damping off the output, a torque-constant error keeps its ratio to the stiffness"),
    frozenset({"kd_gain", "viscous_damping"}): (
        "saturation", "steps into the torque limit: the servo's damping is clipped with its torque, a viscous "
                      "friction acts beyond it"),
    frozenset({"sensor_bias", "backlash"}): (
        "load_reversal", "slow sweeps through the angle where the gravity load changes sign: backlash flips the "
                         "offset with the load, an encoder offset stays"),
    frozenset({"sensor_bias", "backlash_motor"}): (
        "load_reversal", "slow sweeps through the angle where the gravity load changes sign: backlash flips the "
                         "offset with the load, an encoder offset stays"),
    frozenset({"backlash", "backlash_motor"}): (
        "load_reversal", "slow sweeps through the load reversal: with the play behind the servo the link swings "
                         "free and undamped across it, with the dead band in the servo's error it is damped"),
    frozenset({"sensor_bias", "link_com"}): (
        "load_reversal", "slow sweeps over a wide range of angles: a centre-of-mass offset's torque changes with "
                         "the posture, an encoder offset is the same at every angle"),
    frozenset({"backlash", "link_com"}): (
        "load_reversal", "slow sweeps through the load reversal: backlash jumps by the play there, a centre-of-mass "
                         "offset changes the load smoothly"),
    frozenset({"backlash_motor", "link_com"}): (
        "load_reversal", "slow sweeps through the load reversal: backlash jumps by the play there, a centre-of-mass "
                         "offset changes the load smoothly"),
    frozenset({"sensor_bias", "encoder_offset"}): (
        "load_reversal", "sweeps over a wide range of angles: an offset the servo sees moves the link and with it "
                         "the gravity torque, an offset of the log alone does not"),
    frozenset({"encoder_offset", "link_com"}): (
        "load_reversal", "slow sweeps over a wide range of angles: a centre-of-mass offset's torque changes with "
                         "the posture, an encoder offset's shift of the link does not"),
    frozenset({"encoder_offset", "backlash_motor"}): (
        "load_reversal", "slow sweeps through the angle where the gravity load changes sign: backlash flips the "
                         "offset with the load, an encoder offset stays"),
    frozenset({"backlash_link", "backlash"}): (
        "load_reversal", "slow sweeps through the load reversal: an encoder on the motor shaft hides the link's "
                         "travel across the play, one on the output shows it"),
    frozenset({"backlash_link", "backlash_motor"}): (
        "load_reversal", "slow sweeps through the load reversal: an encoder on the motor shaft hides the link's "
                         "travel across the play, one on the output shows it"),
    frozenset({"joint_compliance", "backlash"}): (
        "load_reversal", "slow sweeps through the load reversal: a series spring's deflection follows the load "
                         "smoothly through zero, gear play jumps by its width there"),
    frozenset({"joint_compliance", "backlash_motor"}): (
        "load_reversal", "slow sweeps through the load reversal: a series spring's deflection follows the load "
                         "smoothly through zero, gear play jumps by its width there"),
    frozenset({"joint_compliance", "backlash_link"}): (
        "load_reversal", "slow sweeps through the load reversal: a series spring's deflection follows the load "
                         "smoothly through zero, gear play jumps by its width there"),
    frozenset({"latency", "command_lowpass"}): (
        "chirp", "a chirp to 4 Hz or beyond: a delay's phase lag grows in proportion to the frequency at full "
                 "amplitude, a low-pass's levels off while its amplitude falls"),
    frozenset({"pd_gain", "link_mass"}): (
        "holds", "posture holds in several postures plus a chirp: a mass error follows the posture-dependent "
                 "gravity torque, a kp error also shifts the servo resonance"),
    frozenset({"pd_gain", "link_com"}): (
        "load_reversal", "slow sweeps through the load reversal: a kp error's offset is in proportion to the "
                         "gravity torque at every angle, a centre-of-mass offset turns the torque"),
    frozenset({"link_mass", "link_com"}): (
        "holds", "posture holds in several postures: a mass error scales the gravity torque, a centre-of-mass "
                 "offset turns it"),
    frozenset({"torque_limit", "joint_torque_limit"}): (
        "saturation", "steps into the torque limit on every joint: a limit common to all joints saturates them all "
                      "at the same share of their effort"),
    frozenset({"torque_limit", "back_emf"}): (
        "saturation", "saturating steps from rest and at speed: a back-EMF limit lowers the torque as the joint "
                      "speeds up, a torque limit does not"),
    frozenset({"joint_torque_limit", "back_emf"}): (
        "saturation", "saturating steps from rest and at speed: a back-EMF limit lowers the torque as the joint "
                      "speeds up, a torque limit does not"),
    frozenset({"coulomb_friction", "stribeck_friction"}): (
        "velocity_sweep", "moves at several constant speeds: Stribeck friction breaks away above its sliding "
                          "level and falls with speed, Coulomb friction is the same at every speed"),
    frozenset({"coulomb_friction", "backlash"}): (
        "velocity_sweep", "moves at several speeds and their reversals: dry friction dissipates energy and its lag "
                          "behind a reversal grows with the load, backlash crosses its play at any speed"),
    frozenset({"coulomb_friction", "backlash_motor"}): (
        "velocity_sweep", "moves at several speeds and their reversals: dry friction dissipates energy and its lag "
                          "behind a reversal grows with the load, backlash crosses its play at any speed"),
    frozenset({"armature", "link_inertia"}): (
        "chirp", "a chirp to 4 Hz with the joints above and below moving: armature loads one joint, a link's "
                 "inertia every joint above it"),
}

#: Two-sided level of the held-out test: a family beats a rival when its held-out log-likelihood is
#: higher beyond this quantile of the noise's.
LEVEL = 0.95


def classes_of(family: str) -> list[EffectClass]:
    """The classes ``family`` is a member of (possibly none)."""
    return [c for c in CLASSES.values() if family in c.families]


def rival_families(family: str, families=None) -> list[str]:
    """The other members of ``family``'s classes (among ``families`` when given), in class order."""
    out = []
    for c in classes_of(family):
        for g in c.families:
            if g != family and g not in out and (families is None or g in families):
                out.append(g)
    return out


def separating(a: str, b: str) -> tuple[str, str]:
    """(segment, what it shows) that tells families ``a`` and ``b`` apart; a chirp and posture holds
    when this library has no better one."""
    return SEPARATING.get(frozenset({a, b}), ("chirp", "a longer chirp (0.3-4 Hz) and posture holds on the "
                                                       "joints involved"))


def class_words(a: str, b: str) -> str:
    """What families ``a`` and ``b`` share (the words of their first common class), or ``"effect"``."""
    for c in classes_of(a):
        if b in c.families:
            return c.words
    return "effect"


def place_joint(term: Term, robot) -> str | None:
    """The joint a term sits at: its own joint, or for a link term the joint directly above the link."""
    if term.fam.scope == "joint":
        return term.target
    if term.fam.scope == "link":
        above = joints_above(robot, term_link(term))
        return above[0] if above else None
    return None


def rival_terms(term: Term, family: str, robot) -> list[Term]:
    """The terms of ``family`` that stand in for ``term`` at its place: the same joint (joint
    families), the link below its joint (link families at a joint term; a centre-of-mass offset
    on its three axes), the joint above its link (joint families at a link term), or the family's
    global term. Empty when the family has no term there (e.g. a series spring on a coupled joint).
    """
    fam = FAMILIES[family]
    if fam.scope == "global":
        return [Term(family)]
    joint = place_joint(term, robot)
    if fam.scope == "joint":
        if joint is None:
            return []
        t = Term(family, joint)
        return [t] if term_allowed(t, robot) else []
    if term.fam.scope == "link":
        link = term_link(term)
    elif joint is not None:
        below = links_below(robot, joint)
        link = below[0] if below else None
    else:
        link = None
    if link is None:
        return []
    if family == "link_com":
        return [Term(family, com_target(link, a)) for a in COM_AXES]
    return [Term(family, link)]


@dataclass
class HeldoutTest:
    """Outcome of :func:`heldout_test` between models a and b.

    Attributes:
        z: held-out log-likelihood difference (a - b) over its standard deviation under the noise
            (positive: a fits better).
        z_crit: the two-sided normal quantile at :data:`LEVEL`.
        cost_a, cost_b: held-out costs (the diagnosis's C, Σ_channels mean((e/floor)²)).
        tau: the integrated autocorrelation time [samples] the noise was taken to have.
    """

    z: float
    z_crit: float
    cost_a: float
    cost_b: float
    tau: float

    @property
    def a_better(self) -> bool:
        """a fits the held-out logs better than b beyond the noise."""
        return self.z > self.z_crit

    @property
    def b_better(self) -> bool:
        """b fits the held-out logs better than a beyond the noise."""
        return self.z < -self.z_crit


def heldout_test(problem, values_a: dict, values_b: dict) -> HeldoutTest:
    """Held-out likelihood test of two parameter sets: does one fit the held-out logs better than the
    other beyond what the noise can do?

    With predictions ŷ_a, ŷ_b and measurements y on the held-out windows, all divided by the channel's
    noise floor, the Gaussian log-likelihood difference is Δℓ = ½ Σ [(y - ŷ_b)² - (y - ŷ_a)²]. If what
    the better model leaves, r = y - ŷ_best, were noise of per-channel variance s_c² and integrated
    autocorrelation time τ, the part of Δℓ the noise makes, Σ (ŷ_a - ŷ_b) r, would have variance
    τ Σ_c s_c² Σ_t (ŷ_a - ŷ_b)²; z = Δℓ / sqrt(that). Unexplained systematic error in the residual
    counts as noise (larger s_c, longer τ): a family beats its rival only by more than what neither
    explains. Two models that predict the same give z = 0 (the logs cannot tell them apart).
    (The likelihood-ratio test of two fitted models on held-out data: Q. H. Vuong, Econometrica 57(2),
    1989, with the noise's variance from the residual instead of the sample spread of Δℓ.)

    Args:
        problem: the :class:`sysid.identify.Problem` (its held-out windows and floor).
        values_a, values_b: Term -> value (on top of the problem's base model).

    Returns:
        :class:`HeldoutTest`.
    """
    from sysid.stats import integrated_autocorr

    preds = problem.predict([values_a, values_b], "heldout")
    c = problem.cost([values_a, values_b], "heldout")
    best = 0 if c[0] <= c[1] else 1
    dll, dd, res = 0.0, np.zeros(problem.k), []
    ss, nn = np.zeros(problem.k), 0
    for ym, yp in zip(problem.meas["heldout"], preds):
        ea = (ym[1:] - yp[0, 1:]) / problem.floor
        eb = (ym[1:] - yp[1, 1:]) / problem.floor
        ea[~np.isfinite(ea)] = 1e3
        eb[~np.isfinite(eb)] = 1e3
        dll += 0.5 * float((eb ** 2).sum() - (ea ** 2).sum())
        d = eb - ea  # = (ŷ_a - ŷ_b) / floor
        dd += (d ** 2).sum(axis=0)
        r = ea if best == 0 else eb
        res.append(np.vstack([np.zeros((1, r.shape[1])), r]))  # integrated_autocorr skips row 0
        ss += (r ** 2).sum(axis=0)
        nn += len(r)
    tau = max(1.0, integrated_autocorr(res))
    s2 = ss / max(nn, 1)
    var = tau * float((s2 * dd).sum())
    z_crit = float(norm.ppf(0.5 + LEVEL / 2))
    z = 0.0 if var <= 1e-18 else dll / math.sqrt(var)
    return HeldoutTest(float(z), z_crit, float(c[0]), float(c[1]), float(tau))
