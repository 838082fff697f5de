"""Synthetic logs from the replay models themselves (self-consistency checks and tests).

These logs are made with the *candidate* augmentations, so recovering an effect from them tests
the screening and fitting machinery, not the physics; the blind benchmark
(``benchmarks/sysid_blind.py``) injects effects with independent code instead.
"""

from __future__ import annotations

import numpy as np

from common.defaults import CONTROL_DT, PHYSICS_DT
from robots import RobotModel, get_robot
from sysid.data import Log
from sysid.excitation import protocol
from sysid.replay import predict, whole_logs


def synthetic_logs(values: dict, *, n_logs: int = 3, seconds: float = 6.0, noise: float = 1e-3, seed: int = 0,
                   traj_seed: int = 100, segments=None, robot: RobotModel | str = "nao") -> list[Log]:
    """Fixed-base excitation logs replayed under ``values`` (Term -> value) plus white encoder noise.

    Args:
        values: the hidden effects as candidate terms ({} = the plain sim).
        n_logs, seconds: number and duration [s] of logs (trajectory seeds ``traj_seed + i``).
        noise: encoder noise std [rad].  seed: noise seed.
        segments: excitation segments (default: all fixed-base segments).
        robot: the robot (a ``RobotModel`` or a ``robots.get_robot`` name; default the NAO).

    Returns:
        Logs of ``robot`` (``meta["robot"]``) with ``q`` (N, n) measured (noisy), ``dq`` None, the
        protocol's commands (N, n); n = the robot's joint count.

    Raises:
        KeyError: an unknown robot name.
    """
    r = get_robot(robot) if isinstance(robot, str) else robot
    logs = []
    for i in range(n_logs):
        kw = {} if segments is None else {"segments": segments}
        cmd = r.expand_action(protocol(r, seconds, seed=traj_seed + i, **kw))
        n = len(cmd)
        lg = Log(name=f"synthetic_{i:03d}", t=np.arange(n) * 0.01, cmd=cmd, q=np.tile(r.pose("crouch"), (n, 1)),
                 dq=np.zeros((n, len(r.joint_names))), control_dt=CONTROL_DT, physics_dt=PHYSICS_DT, fixed_base=True,
                 meta={"robot": r.name, "control_dt": 0.01})
        y = predict([lg], whole_logs([lg]), [values])[0][0]
        rng = np.random.default_rng([seed, i])
        lg.q = y + rng.normal(0.0, noise, y.shape)
        lg.dq = None
        logs.append(lg)
    return logs
