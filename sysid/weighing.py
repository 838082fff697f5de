"""The robot's mass from the weight on its feet: contact-aided identification of the floating base's
(the torso's) mass, without a replay.

Newton's second law for the whole robot along the vertical: dp_z/dt = F_z - M g, with F_z the
ground's vertical force on the feet and p_z = M v_z the vertical momentum of its centre of mass.
Averaged over a log of duration T:

    mean(F_z) = M g + M (v_z(T) - v_z(0)) / T.

A standing or stepping log starts and ends with the centre of mass nearly at rest, so the mean total
foot force (``fsr.L + fsr.R``, the normal force under each foot) is the weight M g, whatever the
contact model, the ground's compliance or the servos: a measurement the engine gap between two
simulators does not blur (logs of the strangers' PyBullet world without a hidden effect weigh within
a fraction of a per cent of the model's mass). On a floating base the diagnosis's
link terms are the root's only (:data:`sysid.candidates.FLOATING_BASE_FAMILIES`), so a difference
from the model's mass is reported as the torso's mass (a denser torso: a battery, added electronics,
a payload); the weight does not tell where on the robot the mass sits.

Assumptions, each a limit: the foot force sensors are calibrated (a gain error of x % reads as a
mass error of x %; an engine-gap calibration on logs of the same robot, :func:`sysid.diagnose.calibrate`,
takes their weighing as the reference and cancels it); the ground is nearly level (on a slope of
angle a the normal force carries M g cos a); nothing but the feet touches the ground (a fall breaks
it). Source: the momentum balance of a floating-base robot (e.g. Wensing and Orin, "Improved
computation of the humanoid centroidal dynamics", Humanoids 2013), reduced to its vertical mean.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from sysid.data import Log

#: Smallest mass difference reported, as a share of the robot's mass: below it, a slope of the ground,
#: the centre of mass's vertical velocity at the ends of the logs and the force sensors' calibration
#: are of the same size.
MIN_SHARE = 0.01


@dataclass(frozen=True)
class Weighing:
    """What the logs weigh against what they should.

    Attributes:
        per_log_kg: each log's mean total foot force over g [kg].  mass_kg: their mean [kg].
        reference_kg: what the logs should weigh [kg]: the model's mass (with the base model's root mass),
            or the mean of the calibration logs' weighings.  reference: which of the two, in words.
        model_kg: the model's mass with the base model [kg].  delta_kg: ``mass_kg - reference_kg``.
        delta_ci95: its 95 % interval [kg] (Student t over the logs, Welch's against a calibration's).
        root: the root link (the torso).  root_kg: its mass under the base model [kg].
        root_nominal_kg: its mass in the plain model [kg].
        found: the interval excludes 0 and ``|delta_kg|`` is at least :data:`MIN_SHARE` of ``model_kg``.
    """

    per_log_kg: tuple[float, ...]
    mass_kg: float
    reference_kg: float
    reference: str
    model_kg: float
    delta_kg: float
    delta_ci95: tuple[float, float]
    root: str
    root_kg: float
    root_nominal_kg: float
    found: bool

    @property
    def root_scale(self) -> float:
        """The root's mass with the difference, as a scale of its plain mass (``link_mass``'s unit)."""
        return (self.root_kg + self.delta_kg) / self.root_nominal_kg

    @property
    def root_scale_ci95(self) -> tuple[float, float]:
        """The 95 % interval of :attr:`root_scale`: ``delta_ci95`` put on the root's mass, (low, high)."""
        return tuple((self.root_kg + d) / self.root_nominal_kg for d in self.delta_ci95)

    def sentence(self) -> str:
        """The weighing in words, for the report."""
        return (f"the logs weigh {self.mass_kg:.3f} kg (mean foot force / g over {len(self.per_log_kg)} logs) against "
                f"{self.reference_kg:.3f} kg ({self.reference}): {1000 * self.delta_kg:+.0f} g "
                f"[{1000 * self.delta_ci95[0]:+.0f}, {1000 * self.delta_ci95[1]:+.0f}]")

    def to_dict(self) -> dict:
        return {**asdict(self), "root_scale": self.root_scale, "root_scale_ci95": list(self.root_scale_ci95),
                "min_share": MIN_SHARE, "text": self.sentence()}


def log_masses(logs: list[Log], gravity: float) -> np.ndarray | None:
    """Each log's mean total foot force over ``gravity`` [kg], shape (len(logs),); None when a log has
    no foot forces (``fsr``), has a fixed base or fewer than 3 rows. Row 0 (the state a recording
    starts from) is left out: a simulator's contact forces are not computed before its first step."""
    out = []
    for lg in logs:
        if lg.fixed_base or lg.fsr is None or len(lg.fsr) < 3:
            return None
        out.append(float(np.mean(lg.fsr[1:].sum(axis=1))) / gravity)
    return np.array(out)


def _ci(a: np.ndarray, b: np.ndarray | None) -> tuple[float, float]:
    """95 % interval of mean(a) - mean(b) (or of mean(a) when ``b`` is None): Student t, Welch's."""
    va = a.var(ddof=1) / len(a)
    if b is None:
        se, dof = np.sqrt(va), len(a) - 1
    else:
        vb = b.var(ddof=1) / len(b)
        se = np.sqrt(va + vb)
        dof = (va + vb) ** 2 / max(va ** 2 / (len(a) - 1) + vb ** 2 / (len(b) - 1), 1e-300)
    h = float(stats.t.ppf(0.975, dof) * se) if se > 0 else 0.0
    d = float(a.mean() - (0.0 if b is None else b.mean()))
    return d - h, d + h


def weigh(logs: list[Log], robot, *, base_model: dict | None = None,
          reference_per_log_kg=None) -> Weighing | None:
    """Weigh the robot on floating-base logs with foot forces (module docstring).

    Args:
        logs: floating-base recordings of ``robot`` with ``fsr`` columns (N rows each, N >= 3).
        robot: the logs' robot (``robots.RobotModel``; its root link is the torso).
        base_model: terms every replay carries (Term -> value); a ``link_mass`` of the root there sets
            the root's and the model's mass the logs are compared with.
        reference_per_log_kg: the calibration logs' weighings [kg] (``calibrate()["weight"]``): the
            reference instead of the model's mass, so that what the two sets of logs share (force
            sensor gain, a gap of the recording simulator) cancels.

    Returns:
        A :class:`Weighing`, or None when fewer than 2 logs, or a log is fixed-base or has no foot forces.
    """
    from sysid.model import Structure, replay_model

    if len(logs) < 2:
        return None
    rm = replay_model(Structure(fixed_base=False, physics_dt=logs[0].physics_dt, robot=logs[0].robot_name))
    m = rm.model
    gravity = float(np.linalg.norm(m.opt.gravity))
    masses = log_masses(logs, gravity)
    if masses is None:
        return None
    import mujoco

    root_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, robot.root)
    root_nominal = float(m.body_mass[root_id])
    scale = next((float(v) for t, v in (base_model or {}).items() if t.family == "link_mass" and t.target == robot.root),
                 1.0)
    root_kg = root_nominal * scale
    model_kg = float(m.body_mass.sum()) + root_kg - root_nominal
    if reference_per_log_kg is not None and len(reference_per_log_kg) >= 2:
        ref = np.asarray(reference_per_log_kg, dtype=float)
        reference_kg, reference = float(ref.mean()), f"the {len(ref)} calibration logs' weighing"
        lo, hi = _ci(masses, ref)
    else:
        ref = None
        reference_kg, reference = model_kg, "the model's mass"
        lo, hi = (x - model_kg for x in _ci(masses, None))
    delta = float(masses.mean()) - reference_kg
    found = bool((lo > 0 or hi < 0) and abs(delta) >= MIN_SHARE * model_kg)
    return Weighing(per_log_kg=tuple(float(x) for x in masses), mass_kg=float(masses.mean()), reference_kg=reference_kg,
                    reference=reference, model_kg=model_kg, delta_kg=delta, delta_ci95=(float(lo), float(hi)),
                    root=robot.root, root_kg=root_kg, root_nominal_kg=root_nominal, found=found)
