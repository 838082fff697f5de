"""The project's defaults, in one place (SI units).

Every module that needs one of these imports it from here; the CLI's ``--help`` texts quote them.
"""

#: Control period [s]: the walk engine and the joint targets run at 100 Hz, like the NAO's DCM loop
#: (Gouaillier et al., "Mechatronic design of NAO humanoid", ICRA 2009).
CONTROL_DT = 0.01

#: Physics step [s] of both worlds (MuJoCo ``opt.timestep``, PyBullet ``fixedTimeStep``): 10
#: substeps per control step, PD torques recomputed at every substep.
PHYSICS_DT = 0.001

#: Episode length [s] of one walk, as in the SGAT paper's NAO experiments (Desai et al., IROS 2020,
#: Sec. IV-C: "Each trajectory lasts for 7.5 seconds ... or terminates when the robot falls down").
EPISODE_SECONDS = 7.5

#: Fitness penalty per fall [cm/s]: the paper's reward is the forward speed [cm/s] plus "an early
#: termination penalty of -15 if the robot falls down" (Desai et al., IROS 2020, Sec. IV-C).
FALL_PENALTY = 15.0
