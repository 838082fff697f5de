"""Does SGAT pull ahead of GAT as the real world's per-step randomness grows? (``sgatwalk stochasticity``)"""
