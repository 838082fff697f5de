"""Robot descriptions: the NAO-like H25 model generated from one Python spec (URDF for both engines)."""

from robots.nao import Frame, Geom, Inertial, JointSpec, RobotModel, nao_h25

__all__ = ["Frame", "Geom", "Inertial", "JointSpec", "RobotModel", "nao_h25"]
