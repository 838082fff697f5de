"""The blind benchmark of ``sgatwalk diagnose``, split by concern (CLI: ``benchmarks/sysid_blind.py``).

* :mod:`.families` - the effect classes, nominal values and noise levels both sides agree on;
* :mod:`.referee` - draws hidden effects and trials, records the blind logs, runs the tool;
* :mod:`.worlds` - the referee's own effect injection in MuJoCo (sim-as-real) and PyBullet (real);
* :mod:`.scorer` - compares one diagnosis report with the hidden truth;
* :mod:`.report` - the markdown summary of scored trials.

The protocol is described in the docstring of ``benchmarks/sysid_blind.py`` (its ``--help``) and
in README.md, "The blind proof".
"""
