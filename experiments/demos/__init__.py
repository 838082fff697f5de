"""The one-episode commands: ``sgatwalk walk`` (a gait of the ZMP engine in a world) and ``sgatwalk
stand`` (a pose held in the sim and the real world side by side)."""
