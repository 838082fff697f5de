"""Fits through ``mujoco.sysid`` (MuJoCo 4.0.0, ``pip install "mujoco[sysid]"``): its parameterisations,
its optimizer and its confidence intervals, on this package's replays.

``mujoco.sysid`` declares each unknown as a :class:`mujoco.sysid.Parameter` whose modifier writes it
into an ``MjSpec``; :func:`mujoco.sysid.optimize` runs bounded Gauss-Newton (``mujoco.minimize``) on a
residual vectorised over parameter columns, and :func:`mujoco.sysid.calculate_intervals` turns the
Jacobian at the optimum into Student-t intervals (``python/mujoco/sysid/_src/optimize.py``). Here:

* the terms of :mod:`sysid.candidates` that ``mujoco.sysid`` parameterises become its Parameters
  (:func:`parameters`): a servo's kp (``pd_gain``: :func:`mujoco.sysid.apply_pgain`), its kd
  (``kd_gain``: :func:`mujoco.sysid.apply_dgain`), both together (``torque_constant``, and a joint
  block of ``pd_gain`` and ``kd_gain`` as one 2-vector: :func:`mujoco.sysid.apply_pdgain`; a torque
  constant's ceiling scaled beside it), a link's
  mass (``link_mass``) and its mass with its centre of mass (``link_mass`` with ``link_com`` terms:
  :func:`mujoco.sysid.body_inertia_param`, ``InertiaType.Mass`` / ``MassIpos``);
* each parameter column is written into a copy of the replay model's spec and compiled
  (:func:`compile_models`), the rest of the model (terms ``mujoco.sysid`` does not parameterise:
  latency, backlash, friction, ...) applied on the compiled model as :func:`sysid.candidates.apply_terms`
  does, and every column replayed in one batched ``mujoco.rollout`` call (:func:`sysid.replay.predict`);
* :func:`fit` returns the project's :class:`sysid.identify.FitResult` in the terms' own units, and
  :func:`intervals` ``mujoco.sysid``'s intervals converted to them.

What ``mujoco.sysid`` lacks (backlash, compliance, friction forms, screening, selection, the report)
stays in the package's own code.
"""

from __future__ import annotations

import io

import numpy as np

from sysid.candidates import COM_AXES, Term, apply_terms, com_target, readout, series_structure, term_bounds, term_link
from sysid.model import Structure, replay_model

#: Families :func:`parameters` maps onto ``mujoco.sysid`` parameterisations.
MJSYSID_FAMILIES = ("pd_gain", "kd_gain", "torque_constant", "link_mass", "link_com")


def _sysid():
    """``mujoco.sysid``, or a clear error when its optional dependencies are missing.

    Raises:
        ImportError: ``mujoco.sysid`` exports nothing (installed without ``mujoco[sysid]``).
    """
    import mujoco.sysid as ms

    if not hasattr(ms, "optimize"):
        raise ImportError('mujoco.sysid needs its optional dependencies: pip install "mujoco[sysid]"')
    return ms


class Parameterisation:
    """The ``mujoco.sysid`` Parameters of some terms and the map between the two.

    Attributes:
        params: the :class:`mujoco.sysid.ParameterDict` (one Parameter per servo or link).
        groups: list of (Parameter name, [Terms], to_param, from_param): ``to_param`` maps the
            terms' values (family units) to the parameter's vector, ``from_param`` back.
    """

    def __init__(self, params, groups):
        self.params, self.groups = params, groups

    def vector(self, values: dict) -> np.ndarray:
        """The parameter vector (``ParameterDict.as_vector`` order) of term values ``values``."""
        return np.concatenate([np.atleast_1d(to(values)) for _, _, to, _ in self.groups])

    def values(self, x: np.ndarray) -> dict:
        """Term -> value (family units) of the parameter vector ``x``."""
        out, i = {}, 0
        for name, terms, _, back in self.groups:
            n = self.params[name].size
            out.update(back(np.asarray(x[i:i + n], dtype=float)))
            i += n
        return out


def parameters(rm, terms: list[Term], start: dict) -> Parameterisation:
    """``mujoco.sysid`` Parameters of ``terms`` (families of :data:`MJSYSID_FAMILIES`) on the replay
    model ``rm`` (a :class:`sysid.model.ReplayModel`), starting at ``start`` (Term -> value).

    Servo terms on one joint become one Parameter: kp alone (:func:`mujoco.sysid.apply_pgain`), kd
    alone (``apply_dgain``), or [kp, kd] (``apply_pdgain``) for a ``pd_gain`` + ``kd_gain`` pair and
    for ``torque_constant`` (its one scale is kept: both gains move together through the bounds of
    the scale). Link terms on one link become :func:`mujoco.sysid.body_inertia_param` of type
    ``Mass`` (``link_mass``, rotational inertia scaled with it, as the candidate does) or ``MassIpos``
    (any ``link_com`` axis; the link's mass free only if ``link_mass`` is among ``terms``, else held).
    Bounds are the terms' own (:func:`sysid.candidates.term_bounds`) in the parameter's units.

    Raises:
        ValueError: a family ``mujoco.sysid`` does not parameterise here, or a joint with a play or
            spring hinge (its servo damping is not the actuator's).
        ImportError: ``mujoco.sysid`` without its optional dependencies.
    """
    ms = _sysid()
    robot, model = rm.robot, rm.model
    bad = [t.label() for t in terms if t.family not in MJSYSID_FAMILIES]
    if bad:
        raise ValueError(f"no mujoco.sysid parameterisation for {', '.join(bad)}; it has one for "
                         f"{', '.join(MJSYSID_FAMILIES)}")
    pd = ms.ParameterDict()
    groups = []
    jidx = {n: i for i, n in enumerate(robot.joint_names)}
    joints = sorted({t.target for t in terms if t.fam.scope == "joint"})
    for j in joints:
        if j in rm.play_jnt or j in rm.spring_jnt:
            raise ValueError(f"{j}: a servo with a series hinge keeps its damping outside the actuator; "
                             "fit it with sysid.identify.refit")
        kp0, kd0 = float(robot.kp[jidx[j]]), float(robot.kd[jidx[j]])
        fams = {t.family for t in terms if t.target == j}
        name = f"servo:{j}"
        if "torque_constant" in fams:
            t = Term("torque_constant", j)
            lo, hi = term_bounds(t, robot)
            eff = float(robot.effort[jidx[j]])

            def torque_constant(spec, prm, j=j, kp0=kp0, eff=eff):
                # kp and kd through mujoco.sysid; the servo's torque ceiling scales with them (tau = K_t i)
                ms.apply_pdgain(spec, j, np.asarray(prm.value))
                s = float(np.ravel(prm.value)[0]) / kp0
                spec.actuator(j).forcerange = [-eff * s, eff * s]
            p = ms.Parameter(name, np.array([kp0, kd0]) * start[t], np.array([kp0, kd0]) * lo,
                             np.array([kp0, kd0]) * hi, modifier=torque_constant)
            groups.append((name, [t], lambda v, t=t, a=kp0, b=kd0: np.array([a, b]) * v[t],
                           lambda x, t=t, a=kp0: {t: float(x[0]) / a}))
        elif fams == {"pd_gain", "kd_gain"}:
            tp, td = Term("pd_gain", j), Term("kd_gain", j)
            (lp, hp), (ld, hd) = term_bounds(tp, robot), term_bounds(td, robot)
            p = ms.Parameter(name, np.array([kp0 * start[tp], kd0 * start[td]]), np.array([kp0 * lp, kd0 * ld]),
                             np.array([kp0 * hp, kd0 * hd]),
                             modifier=lambda spec, prm, j=j: ms.apply_pdgain(spec, j, np.asarray(prm.value)))
            groups.append((name, [tp, td], lambda v, tp=tp, td=td, a=kp0, b=kd0: np.array([a * v[tp], b * v[td]]),
                           lambda x, tp=tp, td=td, a=kp0, b=kd0: {tp: float(x[0]) / a, td: float(x[1]) / b}))
        elif fams == {"pd_gain"}:
            t = Term("pd_gain", j)
            lo, hi = term_bounds(t, robot)
            p = ms.Parameter(name, kp0 * start[t], kp0 * lo, kp0 * hi,
                             modifier=lambda spec, prm, j=j: ms.apply_pgain(spec, j, float(np.ravel(prm.value)[0])))
            groups.append((name, [t], lambda v, t=t, a=kp0: a * v[t], lambda x, t=t, a=kp0: {t: float(x[0]) / a}))
        elif fams == {"kd_gain"}:
            t = Term("kd_gain", j)
            lo, hi = term_bounds(t, robot)
            p = ms.Parameter(name, kd0 * start[t], kd0 * lo, kd0 * hi,
                             modifier=lambda spec, prm, j=j: ms.apply_dgain(spec, j, float(np.ravel(prm.value)[0])))
            groups.append((name, [t], lambda v, t=t, b=kd0: b * v[t], lambda x, t=t, b=kd0: {t: float(x[0]) / b}))
        else:
            raise ValueError(f"{j}: servo terms {sorted(fams)} do not form one mujoco.sysid parameter")
        pd.add(p)
    links = sorted({term_link(t) for t in terms if t.fam.scope == "link"})
    for ln in links:
        b = rm.body[ln]
        m0, ipos0 = float(model.body_mass[b]), np.array(model.body_ipos[b], dtype=float)
        tm = Term("link_mass", ln)
        coms = [Term("link_com", com_target(ln, a)) for a in COM_AXES]
        has_com = any(t in terms for t in coms)
        name = f"inertia:{ln}"
        spec = rm.spec
        if not has_com:
            lo, hi = term_bounds(tm, robot)
            p = ms.body_inertia_param(spec, model, ln, ms.InertiaType.Mass, scale_rot_inertia=True,
                                      mass_bound_mult=np.array([lo, hi]), param_name=name)
            p.value = np.atleast_1d(m0 * start[tm])
            groups.append((name, [tm], lambda v, t=tm, m=m0: np.array([m * v[t]]),
                           lambda x, t=tm, m=m0: {t: float(x[0]) / m}))
        else:
            mass_free = tm in terms
            lo, hi = term_bounds(tm, robot) if mass_free else (1.0 - 1e-9, 1.0 + 1e-9)
            clo, chi = term_bounds(coms[0], robot)
            p = ms.body_inertia_param(spec, model, ln, ms.InertiaType.MassIpos, scale_rot_inertia=True,
                                      mass_bound_mult=np.array([lo, hi]), ipos_bound_off=np.array([clo, chi]),
                                      param_name=name)
            p.value = np.concatenate([[m0 * start.get(tm, 1.0)],
                                      ipos0 + np.array([start.get(t, 0.0) for t in coms])])
            ts = ([tm] if mass_free else []) + [t for t in coms if t in terms]

            def to(v, tm=tm, coms=coms, m=m0, i0=ipos0):
                return np.concatenate([[m * v.get(tm, 1.0)], i0 + np.array([v.get(t, 0.0) for t in coms])])

            def back(x, tm=tm, coms=coms, m=m0, i0=ipos0, mass_free=mass_free, picked=ts):
                out = {tm: float(x[0]) / m} if mass_free else {}
                out.update({t: float(x[1 + k] - i0[k]) for k, t in enumerate(coms) if t in picked})
                return out
            groups.append((name, ts, to, back))
        pd.add(p)
    return Parameterisation(pd, groups)


def compile_models(rm, par: Parameterisation, X: np.ndarray, rest: dict) -> list:
    """One replay model per parameter column: ``mujoco.sysid``'s modifiers on a copy of the replay
    spec, compiled, then ``rest`` (Term -> value, families :func:`parameters` does not handle) applied.

    Args:
        rm: the replay model (its structure must hold ``rest``'s series hinges).
        X: (n_params, n_columns) parameter vectors.

    Returns:
        [(rm, MjModel, (n,) log offsets [rad], (meas, servo offsets))] per column, the layout
        :func:`sysid.replay.build_models` makes and :func:`sysid.replay.predict` takes as ``models``.
    """
    ms = _sysid()
    out = []
    for x in np.atleast_2d(X.T):
        pdict = par.params.copy()
        pdict.update_from_vector(np.asarray(x, dtype=float))
        spec = rm.spec.copy()
        ms.apply_param_modifiers_spec(pdict, spec)
        m = spec.compile()
        bias = apply_terms(rm, m, rest) if rest else np.zeros(len(rm.robot.joint_names))
        out.append((rm, m, bias, readout(rm, rest)))
    return out


def fit(problem, start: dict, free: list[Term], *, max_iters: int = 20, eps: float = 1e-4, xtol: float = 1e-5):
    """Fit ``free`` (families of :data:`MJSYSID_FAMILIES`) by :func:`mujoco.sysid.optimize` with the
    ``"mujoco"`` optimizer (``mujoco.minimize.least_squares``, finite-difference Jacobian of one batched
    replay per iteration), the other terms of ``start`` held; residuals as :meth:`sysid.identify.Problem.residuals`
    (training windows, normalised by the noise floor).

    Args:
        problem: a :class:`sysid.identify.Problem`.  start: Term -> start value (every free term in it).
        max_iters: optimizer iterations.  eps: finite-difference step, relative to max(1, |x|).
        xtol: relative step size at which the optimizer stops.

    Returns:
        :class:`sysid.identify.FitResult` in the terms' units (``jac`` per unit of each free term).

    Raises:
        ValueError: an empty ``free``, a free term missing from ``start``, or what :func:`parameters` raises.
    """
    from sysid.identify import FitResult

    ms = _sysid()
    if not free:
        raise ValueError("nothing to fit: give at least one free term")
    missing = [t.label() for t in free if t not in start]
    if missing:
        raise ValueError(f"no start value for {', '.join(missing)}")
    lg0 = problem.logs[0]
    rest = {**problem.base, **{t: v for t, v in start.items() if t not in free}}
    structure = series_structure(Structure(fixed_base=lg0.fixed_base, physics_dt=lg0.physics_dt,
                                           robot=lg0.robot_name), rest)
    rm = replay_model(structure)
    par = parameters(rm, list(free), start)
    from sysid.replay import predict

    def residual_fn(x, params):
        X = np.asarray(x, dtype=float)
        cols = X if X.ndim == 2 else X[:, None]
        models = compile_models(rm, par, cols, rest)
        preds = predict(problem.logs, problem.train, [{}] * cols.shape[1], with_imu=problem.with_imu, models=models)
        problem.n_rollouts += cols.shape[1] * len(problem.train)
        R = problem.residuals(preds, "train")  # (n_columns, n_res)
        return [R.T if X.ndim == 2 else R[0]], None, None

    x0 = par.vector(start)
    par.params.update_from_vector(x0)
    opt, res = ms.optimize(par.params, residual_fn, optimizer="mujoco", verbose=False, max_iters=max_iters,
                           eps=eps, xtol=xtol, output=io.StringIO())
    x = opt.as_vector()
    fitted = par.values(x)
    vals = {**{t: v for t, v in start.items() if t not in free}, **fitted}
    r = residual_fn(x, opt)[0][0]
    J = None
    if res.jac is not None:
        # d residual / d parameter -> d residual / d term (each group's map is linear in its terms)
        J = np.asarray(res.jac, dtype=float)
        dx = np.zeros((len(x), len(free)))
        for k, t in enumerate(free):
            v1 = dict(vals)
            v1[t] = vals[t] + 1.0
            dx[:, k] = par.vector({**start, **v1}) - par.vector({**start, **vals})
        J = J @ dx
    return FitResult(vals, list(free), float(r @ r), J, r, int(max_iters))


def intervals(fit_result, alpha: float = 0.05) -> dict:
    """:func:`mujoco.sysid.calculate_intervals` at a fit's optimum: Term -> 95 % half-width in the term's
    unit (σ² from the residual, Student's t; infinite along null directions of JᵀJ). The residual's
    autocorrelation is not in it (:func:`sysid.identify.confidence` inflates by it)."""
    ms = _sysid()
    if fit_result.jac is None or not fit_result.terms:
        return {}
    _, half = ms.calculate_intervals([fit_result.resid], fit_result.jac, alpha=alpha)
    return {t: float(h) for t, h in zip(fit_result.terms, half)}
