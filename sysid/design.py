"""D-optimal excitation design: how much of a log each protocol segment should take.

Before anything is recorded, the plain sim predicts how much each segment of the excitation
protocol (:mod:`sysid.excitation`) tells about each candidate term of the library
(:mod:`sysid.candidates`). For segment s, the sensitivity of the replayed encoder angles to every
term is taken by finite differences at the term's screening probe (the same columns the
diagnosis screens with: :func:`sysid.identify._columns_terms`), in units of the encoder noise σ
per smallest reported effect of the term (``min_effect``). Its Fisher information per second of
recording is

    F_s = J_sᵀ J_s / T_s                          (J_s: (samples × joints, terms), T_s [s])

(Gaussian white encoder noise; Ljung, *System Identification*, 2nd ed., 1999, §13.3). A design
gives segment s the share w_s of a log of T seconds; its information is T Σ_s w_s F_s. The
D-optimal shares maximise log det Σ_s w_s F_s over the simplex (Kiefer & Wolfowitz, Canad. J.
Math. 12, 1960), found by the multiplicative algorithm of Silvey, Titterington & Torsney
(Comm. Statist. Theory Methods 7(14), 1978): w_s ← w_s tr(M(w)⁻¹ F_s) / p, which increases the
criterion at every step and converges to the optimum.

The expected identifiability of a term under a design is its predicted standard error
se = sqrt((T M(w))⁻¹)_ii in units of its smallest reported effect: the term is *identifiable*
when 1.96 se < 1, i.e. a departure of the smallest reported size would stand out of the noise at
95 %. Terms are judged jointly (the inverse of the whole information matrix), so two terms that
only move the data together (a kp error and a series spring in holds) count as poorly
identifiable even when each alone would show.

Finite differences at one probe linearise the dead-zone families (backlash, Coulomb friction,
latency) around that probe: the numbers rank segments, they are not a promise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from common.defaults import CONTROL_DT, PHYSICS_DT
from robots import RobotModel
from sysid.candidates import FAMILIES, FIXED_BASE_FAMILIES, family_for, mass_links, term_min_effect
from sysid.data import Log
from sysid.excitation import SEGMENTS, SEGMENT_SHARES, protocol
from sysid.identify import Problem, _columns_terms, _dictionary
from sysid.replay import predict, whole_logs

#: z of a two-sided 95 % interval: a term is identifiable when z * se < its smallest reported effect.
Z95 = 1.959964
#: Ridge on the information matrix, relative to its mean diagonal (terms no segment moves would
#: make it singular; they come out unidentifiable rather than breaking the determinant).
RIDGE = 1e-9


@dataclass
class Design:
    """Outcome of :func:`d_optimal`.

    Attributes:
        segments: the segments considered, in protocol order.
        shares: D-optimal share of the log per segment (sums to 1).
        default_shares: the protocol's own shares of the same segments (normalised).
        terms: term labels, in the columns' order.  families: family per term.
        se_default, se_optimal: (p,) predicted standard error of each term for a log of ``seconds``,
            in units of the term's smallest reported effect.
        seconds: the log duration the standard errors are for [s].
        info_per_s: segment -> (p, p) Fisher information per second (σ and min_effect units).
        logdet_default, logdet_optimal: log det of the information per second under each design.
        iterations: multiplicative-algorithm iterations run.
    """

    segments: list[str]
    shares: dict
    default_shares: dict
    terms: list[str]
    families: list[str]
    se_default: np.ndarray
    se_optimal: np.ndarray
    seconds: float
    info_per_s: dict = field(repr=False, default_factory=dict)
    logdet_default: float = 0.0
    logdet_optimal: float = 0.0
    iterations: int = 0

    def identifiable(self, which: str = "optimal") -> np.ndarray:
        """(p,) bool: 1.96 se < 1 smallest reported effect, under the ``"optimal"`` or ``"default"`` design."""
        se = self.se_optimal if which == "optimal" else self.se_default
        return Z95 * se < 1.0

    def by_family(self) -> list[dict]:
        """Per family: terms, identifiable under the default and the D-optimal shares, median se."""
        out = []
        fams = np.array(self.families)
        for f in dict.fromkeys(self.families):
            m = fams == f
            out.append({"family": f, "terms": int(m.sum()),
                        "identifiable_default": int(self.identifiable("default")[m].sum()),
                        "identifiable_optimal": int(self.identifiable("optimal")[m].sum()),
                        "median_se_default": float(np.median(self.se_default[m])),
                        "median_se_optimal": float(np.median(self.se_optimal[m]))})
        return out

    def to_json(self) -> dict:
        """The design as JSON values (no information matrices)."""
        return {"segments": self.segments, "shares": self.shares, "default_shares": self.default_shares,
                "seconds": self.seconds, "logdet_per_s_default": self.logdet_default,
                "logdet_per_s_optimal": self.logdet_optimal, "iterations": self.iterations,
                "families": self.by_family(),
                "terms": [{"term": t, "se_default": float(a), "se_optimal": float(b)}
                          for t, a, b in zip(self.terms, self.se_default, self.se_optimal)]}


def _segment_log(robot: RobotModel, segment: str, seconds: float, seed: int) -> Log:
    """A fixed-base log of one protocol segment, its "measurement" the plain sim's replay."""
    cmd = robot.expand_action(protocol(robot, seconds + 0.7, seed=seed, segments=(segment,)))
    n = len(cmd)
    lg = Log(name=f"design_{segment}", t=np.arange(n) * CONTROL_DT, cmd=cmd, q=np.tile(robot.pose("crouch"), (n, 1)),
             dq=None, control_dt=CONTROL_DT, physics_dt=PHYSICS_DT, fixed_base=True,
             meta={"robot": robot.name, "control_dt": CONTROL_DT})
    lg.q = predict([lg], whole_logs([lg]), [{}])[0][0]
    return lg


def segment_information(robot: RobotModel, segments=SEGMENTS, *, seconds: float = 3.0, seed: int = 0,
                        families=FIXED_BASE_FAMILIES, joints=None, progress=None) -> tuple[dict, list, list]:
    """Fisher information per second of each segment for every term of ``families``.

    Args:
        robot: the robot (fixed base).  segments: protocol segments (fixed-base ones).
        seconds: simulated duration of each segment [s] (plus the protocol's 0.7 s of holds).
        seed: trajectory seed.  families: candidate families (stochastic and contact ones are skipped).
        joints: joints whose terms are considered (default all); link masses: the links below them.
        progress: callable(str) for a line per segment.

    Returns:
        (segment -> (p, p) information per second, term labels (p,), family per term (p,)); units:
        encoder σ per smallest reported effect of each term.

    Raises:
        ValueError: an unknown or floating-base-only segment.
    """
    fams = [f for f in families if not FAMILIES[f].stochastic and not FAMILIES[f].contact]
    joints = list(robot.joint_names if joints is None else joints)
    joints = list(dict.fromkeys(robot.mimic.get(j, j) for j in joints))
    links = mass_links(robot, joints, False)
    cols = _columns_terms(robot, fams, {}, joints, links)
    cols = [c for c in cols if c.negate_of is None and len(c.terms) == 1]  # one term each, no mirrors
    info, labels, fam_of = {}, [c.label for c in cols], [c.family for c in cols]
    for s in segments:
        if s not in SEGMENT_SHARES or s in ("slip", "stepping"):
            raise ValueError(f"segment {s!r} is not a fixed-base protocol segment")
        lg = _segment_log(robot, s, seconds, seed)
        noise = 1e-3  # σ of the columns' unit; F scales as 1/σ², which the shares do not depend on
        prob = Problem([lg], whole_logs([lg]), whole_logs([lg]), np.full(len(robot.joint_names), noise))
        D, _ = _dictionary(prob, {}, cols)
        scale = []
        for c in cols:
            (t, pv), = c.terms.items()
            delta = pv - family_for(t.family, robot).nominal
            scale.append(term_min_effect(t, robot) / delta if delta else 0.0)
        J = -D * np.array(scale)[None]  # residual change per min_effect, in σ
        J[~np.isfinite(J)] = 0.0
        T = (len(lg) - 1) * lg.control_dt
        info[s] = J.T @ J / T
        if progress:
            progress(f"design: segment {s}: {len(cols)} terms, {T:.1f} s simulated")
    return info, labels, fam_of


def _logdet(M: np.ndarray) -> float:
    sign, val = np.linalg.slogdet(M)
    return float(val) if sign > 0 else -math.inf


def d_optimal(info: dict, *, min_share: float = 0.0, iterations: int = 500, tol: float = 1e-7) -> tuple[dict, int]:
    """D-optimal shares of the segments of ``info`` (segment -> (p, p) information per second) by the
    multiplicative algorithm (Silvey, Titterington & Torsney 1978), every segment keeping at least
    ``min_share`` of the log: w_s = m + (1 - S m) v_s with v on the simplex, and the algorithm run on v
    with the fixed information m Σ_s F_s as prior information (Pukelsheim, *Optimal Design of
    Experiments*, 1993, §5.15). Returns (segment -> share, iterations).

    Raises:
        ValueError: ``info`` is empty; ``min_share`` outside [0, 1 / number of segments].
    """
    if not info:
        raise ValueError("no segments to design over")
    segs = list(info)
    if not 0.0 <= min_share <= 1.0 / len(segs):
        raise ValueError(f"min_share must be in [0, 1/{len(segs)}], got {min_share}")
    F = np.stack([info[s] for s in segs])
    p = F.shape[1]
    ridge = RIDGE * max(float(np.mean([np.trace(f) for f in F])) / p, 1e-300)
    free = 1.0 - len(segs) * min_share
    M0 = min_share * F.sum(axis=0) + ridge * np.eye(p)
    v = np.full(len(segs), 1.0 / len(segs))
    it = 0
    for it in range(1, iterations + 1):
        if free <= 0:
            break
        Minv = np.linalg.inv(M0 + free * np.tensordot(v, F, axes=1))
        d = np.einsum("ij,sji->s", Minv, F)  # tr(M⁻¹ F_s)
        v_new = v * d / max(float(v @ d), 1e-300)
        done = np.max(np.abs(v_new - v)) < tol
        v = v_new
        if done:
            break
    w = min_share + free * v / v.sum()
    return dict(zip(segs, (w / w.sum()).tolist())), it


def _se(info: dict, shares: dict, seconds: float) -> tuple[np.ndarray, float]:
    F = np.stack([info[s] for s in shares])
    w = np.array([shares[s] for s in shares])
    M = np.tensordot(w, F, axes=1)
    p = M.shape[0]
    M = M + RIDGE * max(float(np.trace(M)) / p, 1e-300) * np.eye(p)
    cov = np.linalg.inv(seconds * M)
    return np.sqrt(np.maximum(np.diag(cov), 0.0)), _logdet(M)


#: Share of the log every segment keeps in :func:`design` (each segment aims at a different family,
#: and a held-out split by trajectory wants every kind of motion in every log).
MIN_SHARE = 0.04


def design(robot: RobotModel, segments=SEGMENTS, *, seconds: float = 8.0, seed: int = 0, families=FIXED_BASE_FAMILIES,
           joints=None, progress=None, segment_seconds: float = 3.0, min_share: float = MIN_SHARE) -> Design:
    """The D-optimal shares of ``segments`` for a fixed-base log of ``seconds`` and the expected
    identifiability of every term under them and under the protocol's own shares.

    Args:
        robot: the robot.  segments: fixed-base protocol segments to weigh (``"saturation"`` included
            if given).  seconds: log duration the standard errors are for [s].
        seed: trajectory seed of the simulated segments.  families, joints: the candidate terms
            (:func:`segment_information`).  progress: callable(str).
        segment_seconds: simulated duration of each segment [s].
        min_share: share of the log every segment keeps (:func:`d_optimal`).

    Raises:
        ValueError: an unknown or floating-base-only segment; ``seconds`` not positive.
    """
    if not seconds > 0:
        raise ValueError(f"seconds must be positive, got {seconds}")
    if not segment_seconds >= 2.3:  # the protocol's 0.7 s of holds around it make a log of >= 3 s
        raise ValueError(f"segment_seconds must be >= 2.3 s, got {segment_seconds}")
    segments = list(segments)
    info, labels, fams = segment_information(robot, segments, seconds=segment_seconds, seed=seed, families=families,
                                             joints=joints, progress=progress)
    shares, it = d_optimal(info, min_share=min(min_share, 1.0 / len(segments)))
    tot = sum(SEGMENT_SHARES[s] for s in segments)
    default = {s: SEGMENT_SHARES[s] / tot for s in segments}
    se_d, ld_d = _se(info, default, seconds)
    se_o, ld_o = _se(info, shares, seconds)
    return Design(segments=segments, shares=shares, default_shares=default, terms=labels, families=fams,
                  se_default=se_d, se_optimal=se_o, seconds=seconds, info_per_s=info, logdet_default=ld_d,
                  logdet_optimal=ld_o, iterations=it)


def format_design(d: dict) -> str:
    """The design (``Design.to_json()``) as printed by ``sgatwalk excite --design d-optimal``."""
    lines = [f"D-optimal excitation design (fixed base, {d['seconds']:g} s per log; a term is identifiable when "
             "1.96 se is below its family's smallest reported effect)", "",
             f"  {'segment':12s} {'protocol':>9s} {'D-optimal':>9s}"]
    for s in d["segments"]:
        lines.append(f"  {s:12s} {100 * d['default_shares'][s]:8.0f}% {100 * d['shares'][s]:8.0f}%")
    lines.append(f"  log det of the information per second: {d['logdet_per_s_default']:.1f} -> "
                 f"{d['logdet_per_s_optimal']:.1f}")
    lines.append("")
    lines.append(f"  {'family':18s} {'terms':>5s} {'identifiable: protocol':>22s} {'D-optimal':>9s} "
                 f"{'median se: protocol':>19s} {'D-optimal':>9s}")
    for r in d["families"]:
        lines.append(f"  {r['family']:18s} {r['terms']:5d} {r['identifiable_default']:22d} {r['identifiable_optimal']:9d} "
                     f"{r['median_se_default']:19.2f} {r['median_se_optimal']:9.2f}")
    lines.append("  (se: predicted standard error, in units of each family's smallest reported effect)")
    return "\n".join(lines)
