"""Robot descriptions: the NAO-like H25 model generated from one Python spec, and the humanoids of
``example-robot-data`` (Unitree G1, PAL Talos); each one URDF for both engines."""

from robots.model import Frame, Geom, Inertial, JointSpec, LegGeometry, RobotModel
from robots.nao import nao_h25

#: Robot names the CLI accepts (``--robot``), default first.
ROBOT_NAMES = ("nao", "g1", "talos")


def get_robot(name: str = "nao") -> RobotModel:
    """The cached :class:`RobotModel` called ``name`` (one of :data:`ROBOT_NAMES`; ``nao_h25``, the name
    recordings made before carried, is an alias of ``nao``).

    Raises:
        KeyError: unknown name.
        ModuleNotFoundError: ``g1``/``talos`` without ``example-robot-data`` installed.
    """
    if name in ("nao", "nao_h25"):
        return nao_h25()
    if name in ("g1", "talos"):
        from robots.urdf_robots import pal_talos, unitree_g1  # lazy: parses URDFs, compiles MuJoCo models

        return unitree_g1() if name == "g1" else pal_talos()
    raise KeyError(f"unknown robot {name!r}; known: {', '.join(ROBOT_NAMES)}")


__all__ = ["Frame", "Geom", "Inertial", "JointSpec", "LegGeometry", "ROBOT_NAMES", "RobotModel", "get_robot", "nao_h25"]
