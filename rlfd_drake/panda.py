"""The Franka Emika Panda, loaded offline from the ``example-robot-data`` package.

The URDF of example-robot-data is used as shipped except for three edits made in
memory (nothing on disk is changed):

* its ``<collision>`` blocks are dropped: they reference .stl meshes, which Drake
  does not accept, and the arm's own collisions are not needed for insertion (the
  parts that touch are ours, see ``scene.py``);
* the two prismatic finger joints become fixed joints at a configurable opening, so
  the arm has exactly 7 degrees of freedom (the fingers hold the part; the part
  itself is welded to the hand, see ``scene.py``);
* joint 1-7 get actuators with the Panda's torque limits (87 N m joints 1-4,
  12 N m joints 5-7, the URDF's ``effort`` values and Franka's datasheet), since the
  URDF has no ``<transmission>`` tags.

Joint damping and armature: the URDF's own ``damping="0.003"`` is a placeholder.
We use the values of MuJoCo Menagerie's ``franka_emika_panda`` model (armature
0.1 kg m^2, damping 1 N m s/rad on every arm joint), which is derived from the same
Franka URDF and tuned to behave like the real arm. The armature (reflected rotor
inertia) also keeps the light distal joints (link inertia ~0.01 kg m^2) well
conditioned for a 500 Hz explicit controller; the damping is applied implicitly by
the discrete solver.
"""

from __future__ import annotations

import re
from functools import cache
from importlib import metadata
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, RevoluteJoint

PANDA_ARM_JOINTS: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, 8))
# Torque limits of the real robot, N m (Franka datasheet; also the URDF efforts).
PANDA_TORQUE_LIMITS_NM = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
# From MuJoCo Menagerie's franka_emika_panda (see the module docstring).
PANDA_ARMATURE_KGM2 = np.full(7, 0.1)
PANDA_JOINT_DAMPING_NMS = np.full(7, 1.0)
# A comfortable configuration with the hand pointing down, rad.
PANDA_HOME_Q = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, np.pi / 4])
# Body names of the frames we use.
PANDA_BASE_BODY = "panda_link0"
PANDA_HAND_BODY = "panda_hand"
# Distance from the hand frame to the point between the fingertips, m (URDF tcp joint).
PANDA_HAND_TO_TCP_M = 0.1034


@cache
def example_robot_data_share() -> Path:
    """The ``share/example-robot-data`` folder of the installed package."""
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError as error:
        raise RuntimeError(
            "example-robot-data is not installed; `pip install example-robot-data`"
        ) from error
    share = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data")))
    if not (share / "robots/panda_description/urdf/panda.urdf").exists():
        raise RuntimeError(f"no Panda URDF under {share}")
    return share


def panda_urdf_text(finger_opening_m: float = 0.0) -> str:
    """The edited Panda URDF (see module docstring) as a string.

    Args:
        finger_opening_m: distance of each finger from the closed position, m,
            in [0, 0.04] (the URDF's finger range).
    """
    if not 0.0 <= finger_opening_m <= 0.04:
        raise ValueError(f"finger_opening_m must be in [0, 0.04] m, got {finger_opening_m}")
    urdf = (example_robot_data_share() / "robots/panda_description/urdf/panda.urdf").read_text()
    urdf = re.sub(r"<collision>.*?</collision>", "", urdf, flags=re.S)
    # Drake ignores <safety_controller> with a warning per joint; drop them quietly.
    urdf = re.sub(r"<safety_controller[^>]*/>", "", urdf)
    # Fingers become fixed at the requested opening (axis +y for finger 1, -y for 2).
    for name, sign in (("panda_finger_joint1", 1.0), ("panda_finger_joint2", -1.0)):
        pattern = re.compile(rf'<joint name="{name}" type="prismatic">.*?</joint>', re.S)
        block = pattern.search(urdf)
        if block is None:
            raise RuntimeError(f"{name} not found in the Panda URDF")
        text = block.group(0)
        parent = re.search(r'<parent link="(\w+)"/>', text).group(1)
        child = re.search(r'<child link="(\w+)"/>', text).group(1)
        y = sign * finger_opening_m
        fixed = (
            f'<joint name="{name}" type="fixed"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin rpy="0 0 0" xyz="0 {y:.6f} 0.0584"/></joint>'
        )
        urdf = urdf[: block.start()] + fixed + urdf[block.end() :]
    return urdf


def AddPanda(
    plant: MultibodyPlant,
    X_WBase: RigidTransform | None = None,
    finger_opening_m: float = 0.0,
    model_name: str = "panda",
) -> ModelInstanceIndex:
    """Adds the 7-DoF Panda (arm + hand, fingers fixed) welded to the world at X_WBase.

    Adds actuators with torque limits, joint damping and armature. Must be called
    before ``plant.Finalize()``.
    """
    parser = Parser(plant, model_name)
    parser.package_map().Add("example-robot-data", str(example_robot_data_share()))
    (panda,) = parser.AddModelsFromString(panda_urdf_text(finger_opening_m), "urdf")
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetFrameByName(PANDA_BASE_BODY, panda),
        X_WBase if X_WBase is not None else RigidTransform(),
    )
    for i, name in enumerate(PANDA_ARM_JOINTS):
        joint = plant.GetJointByName(name, panda)
        assert isinstance(joint, RevoluteJoint)
        joint.set_default_damping(float(PANDA_JOINT_DAMPING_NMS[i]))
        actuator = plant.AddJointActuator(
            f"{name}_actuator", joint, effort_limit=float(PANDA_TORQUE_LIMITS_NM[i])
        )
        # Reflected inertia = rotor_inertia * gear_ratio^2; gear ratio 1 here.
        actuator.set_default_rotor_inertia(float(PANDA_ARMATURE_KGM2[i]))
        actuator.set_default_gear_ratio(1.0)
        joint.set_default_angle(float(PANDA_HOME_Q[i]))
    return panda
