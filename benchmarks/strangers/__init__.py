"""The strangers' world: effect models written apart from the diagnosis's candidate library.

A second world for the blind benchmark of ``sgatwalk diagnose``. Its hidden effects are written in
physical forms of their own (a semi-closed-loop servo with gear play, an elasto-plastic Stribeck
friction, a transport delay behind a first-order lag, a DC-motor torque-speed envelope, inertial
parameters beyond mass, a Perlin-noise ground, ...), by a code path of their own: the PD loop at the
physics step of :class:`.world.StrangerWorld` on the project's PyBullet world with its effect profile
``"none"``.

* :mod:`.effects` - the table of effect kinds (:data:`.effects.KINDS`): physical description,
  literature source, parameters with units and draw ranges, targets; :func:`.effects.draw_effect`,
  :func:`.effects.validate_hidden`;
* :mod:`.world` - :class:`.world.StrangerWorld` (a gymnasium env) and :func:`.world.make_world`;
* :mod:`.ground` - the uneven ground: fractal Perlin noise of a given RMS height.
"""

from .effects import KINDS, draw_effect, eligible_targets, validate_hidden
from .world import StrangerWorld, make_world

__all__ = ["KINDS", "StrangerWorld", "draw_effect", "eligible_targets", "make_world", "validate_hidden"]
