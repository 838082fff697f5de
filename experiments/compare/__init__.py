"""``sgatwalk compare``: every training world of several fidelity runs, ranked per gait panel."""

#: Worlds drawn per panel by :func:`experiments.compare.run.plot` (the best by worst ρ).
PLOT_ROWS = 20
