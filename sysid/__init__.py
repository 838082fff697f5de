"""Mismatch diagnosis: locate where sim and real differ, name the missing physics, fit it, prove it.

Pipeline (this project's; see README, "sgatwalk excite and sgatwalk diagnose"): calibrate the engine gap
(:func:`calibrate`) → replay
real commands in MuJoCo from the measured state (:mod:`sysid.replay`, batched through
``mujoco.rollout``; windowed for floating-base logs) → localisation statistics
(:mod:`sysid.stats`) → screening with a sensitivity dictionary and OMP/BIC, bounded nonlinear
refit, held-out selection and intervals (:mod:`sysid.identify`, :func:`diagnose`) → for
floating-base logs, terrain roughness as a fitted distribution of random surfaces
(:mod:`sysid.roughness`) → report,
plots and MJCF (:mod:`sysid.report`).

Modules: ``data`` (loading/validating logs), ``model`` (replay models), ``candidates`` (the
effect library, each effect in its common physical forms), ``equivalence`` (classes of forms that
logs can leave tied, and the held-out test that separates them), ``mjsysid`` (fits through
``mujoco.sysid``'s parameterisations, optimizer and intervals), ``roughness`` (uneven ground, fitted
by simulation), ``excitation`` (the
protocol a user runs on a robot), ``worlds`` (recording it with one robot's frozen effects),
``estimate`` (floating-base state without ground truth), ``synthetic`` (self-consistent logs for
tests).

Typical use (MuJoCo loads only when these modules are imported)::

    from sysid.data import load_logs
    from sysid.diagnose import diagnose
    from sysid.report import write_report

    logs = load_logs("excite_logs/")
    write_report(diagnose(logs), logs, "report/")
"""
