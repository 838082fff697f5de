"""Rerun logging of rollouts: the robot in 3D, its terrain, time series, plan and fall, many worlds.

One :class:`envs.Recording` becomes one subtree ``/<label>`` of a Rerun recording; several
recordings (sim, real, grounded sim, trials of an optimisation run) share the ``time`` timeline and
are laid out side by side by :func:`build_blueprint`. Everything time-varying is sent with Rerun's
columnar API (``RecordingStream.send_columns``, one call per entity per rollout), so a 7.5 s
rollout (750 rows) logs in a few tens of milliseconds (``benchmarks/bench_rerun.py``).

Entity layout (``<label>`` is the world, e.g. ``sim``, or ``<world>/<name>`` when a world has
several recordings; all positions in the world frame [m], z up; every time-varying entity has one
row per recording row on the timelines ``time`` (duration, the recording's ``t`` [s]) and ``step``
(sequence, the row index), unless noted):

==========================================  ================  ===================================================
entity                                      archetype         content
==========================================  ================  ===================================================
``/<label>``                                ViewCoordinates   static: right-handed, z up
``/<label>/terrain``                        Mesh3D            static: the heightfield (MuJoCo's triangle diagonal)
                                                              or a flat 6 m x 3 m quad at z = 0
``/<label>/robot/<link>``                   Transform3D       world pose of each link (25 for the NAO; own forward
                                                              kinematics from ``q.*`` and ``gt.base``/``gt.quat``)
``/<label>/robot/<link>/geom``              Boxes3D,          static: the link's primitives (``RobotModel`` spec),
                                            Capsules3D,       in the link frame (``geom/<kind>`` when a link has
                                            Ellipsoids3D      several kinds)
``/<label>/robot/<link>/mesh/<file>``       Transform3D,      static: each visual mesh of the link (G1, Talos; the
                                            Asset3D           NAO has none): the geom's pose and scale in the link
                                                              frame, the file's bytes (STL/OBJ/glTF) embedded
``/<label>/com``                            Points3D          measured (ground-truth) CoM ``gt.com.*``
``/<label>/com_trail``                      LineStrips3D      static: the whole CoM path
``/<label>/cop``                            Points3D          measured centre of pressure on the ground: ``gt.cop``
                                                              or, without it, from ``fsr.*``/``cop.*`` and the
                                                              sole poses; an empty row when no foot touches
``/<label>/plan/com``                       Points3D          planned CoM ``plan.com.*`` (if present)
``/<label>/plan/zmp``                       Points3D          ZMP reference ``plan.zmp.*`` on the terrain (if present)
``/<label>/plan/com_trail``                 LineStrips3D      static: planned CoM path (if present)
``/<label>/plan/footsteps``                 Boxes3D           static: every planned footstep (metadata ``footsteps``)
``/<label>/plan/footsteps/active``          Boxes3D           the footsteps whose [t_start, t_end) holds t
``/<label>/fall``                           Points3D          one row at ``fall_time``: where (torso over the ground)
                                                              and why (label) the robot fell; absent if it did not
``/<label>/events``                         TextLog           start (world, seed, terrain ...) and fall messages
``/<label>/ts/joints/<joint>/{cmd,app,q}``  Scalars           commanded, applied (after grounding; absent when the
                                                              recording has no ``app.*``) and measured angle [rad]
                                                              of each of the 12 leg joints (the NAO's
                                                              ``RHipYawPitch`` command is ``LHipYawPitch``'s: one
                                                              motor)
``/<label>/ts/gyro/{x,y,z}``                Scalars           torso gyro [rad/s] (if present)
``/<label>/ts/angle/{roll,pitch}``          Scalars           torso roll/pitch estimate [rad] (if present)
``/<label>/ts/fsr/{L,R}``                   Scalars           foot normal force [N] (if present)
``/<label>/ts/balance/{x,y}/<quantity>``    Scalars           ``com``, ``cop``, ``plan_com``, ``zmp_ref`` [m]
``/legend``                                 TextDocument      static: how to read the views (markdown)
==========================================  ================  ===================================================

The robot is the one named by each recording's ``meta["robot"]`` (``nao``, ``g1``, ``talos``;
one robot per file). The default camera and the footstep boxes follow the robot's size and sole.
A G1 recording embeds its 35 STL meshes (about 9 MB in the .rrd per recording), a Talos one its 47
(25 files, about 5 MB).

Diagnostics convention (optional, shown when present): columns ``plan.com.x|y|z`` (planned CoM,
world [m]), ``plan.zmp.x|y`` (ZMP reference), metadata ``footsteps``: a list of ``{"x", "y",
"yaw", "side" ("L"/"R"), "t_start", "t_end"}`` where (x, y, yaw) is the planned sole frame
(``l_sole``/``r_sole``: the ankle projected onto the sole's bottom face, 45.11 mm down on the NAO;
world [m], [rad]).

Terrain heights are not stored in recordings; :func:`terrain_for` rebuilds them from the
generator spec in the metadata (``terrain["spec"]``, :func:`terrain.from_spec`), or for older
recordings without one regenerates them from the seed and effects, and checks the result against
the recorded shape and min/max.

Modules: :mod:`~experiments.viz.rerun_log` (logging, the default blueprint, the legend),
:mod:`~experiments.viz.kinematics` (the robot's link poses for drawing), :mod:`~experiments.viz.terrain`
(the ground of a recording and its mesh), :mod:`~experiments.viz.plan` (a walk engine's plan as
columns), :mod:`~experiments.viz.inputs` (checks, labels, finding recordings),
:mod:`~experiments.viz.screenshot` (headless PNGs), :mod:`~experiments.viz.style` (timelines, colours).
Every name is re-exported here.

Sources: rerun-sdk 0.41 (https://rerun.io/docs, https://ref.rerun.io/docs/python/), quaternion order x, y, z, w for
Rerun and w, x, y, z in recordings.
"""

from experiments.viz.inputs import _PART, _is_recording_file, check_recording, find_recordings, sanitize_label
from experiments.viz.kinematics import _measured_cop, _robot_scale, _sole_geometry, _xyzw, link_poses
from robots.kinematics import forward_kinematics, frame_positions
from experiments.viz.plan import footsteps_from_phases, plan_from_engine
from experiments.viz.rerun_log import (EYE_OFFSET, LEGEND_MD, MESH_MEDIA_TYPES, SOLE_BOX, SOLE_CENTER, _Logger,
                                       build_blueprint, log_recording, log_rollouts_to_rrd)
from experiments.viz.screenshot import _quiet_child_output, screenshot_rrd, tempfile_dir
from experiments.viz.style import PALETTE, STEP_TIMELINE, TIMELINE, WORLD_COLORS, _color, _pick_color
from experiments.viz.terrain import FLAT_SIZE, _ground_z, _terrain_matches, terrain_for, terrain_mesh

__all__ = ["EYE_OFFSET", "FLAT_SIZE", "LEGEND_MD", "MESH_MEDIA_TYPES", "PALETTE", "SOLE_BOX", "SOLE_CENTER",
           "STEP_TIMELINE", "TIMELINE", "WORLD_COLORS", "build_blueprint", "check_recording", "find_recordings",
           "footsteps_from_phases", "forward_kinematics", "frame_positions", "link_poses", "log_recording",
           "log_rollouts_to_rrd", "plan_from_engine", "sanitize_label", "screenshot_rrd", "tempfile_dir", "terrain_for",
           "terrain_mesh",
           # private helpers, re-exported for tests and benchmarks (benchmarks/bench_rerun.py: _xyzw)
           "_Logger", "_PART", "_color", "_ground_z", "_is_recording_file", "_measured_cop", "_pick_color",
           "_quiet_child_output", "_robot_scale", "_sole_geometry", "_terrain_matches", "_xyzw"]
