"""``sgatwalk cliff``: GAT against SGAT on Cliff Walking over a noise sweep (the SGAT paper, Fig. 7)."""
