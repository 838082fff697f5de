"""SGAT grounding: forward/inverse models, the action transformer, the grounded env, and the
tabular case (``sgat.tabular``). Import submodules directly; this package stays light."""
