"""Baselines of the paper's "sequential vs. joint optimization" study (Tab. 6, §4.4) and external methods.

- :mod:`~phiscene.baselines.joint_sdf`: CAST-style joint SDF penetration resolution (all translations at once).
- :mod:`~phiscene.baselines.joint_sim`: joint rigid-body simulation of all objects, and joint SDF + simulation.
- :mod:`~phiscene.baselines.lift`: PAT3D-style single-parent top-down lifting, then joint simulation.
- :mod:`~phiscene.baselines.external`: import another method's predicted scenes as a method row.

Every baseline returns ``(Scene, log dict)``; the scene follows the shared ``scene.json`` contract.
"""

from phiscene.baselines.external import ImportParams, import_external
from phiscene.baselines.joint_sdf import JointSdfParams, joint_sdf
from phiscene.baselines.joint_sim import JointSdfSimParams, JointSimParams, joint_sdf_sim, joint_sim
from phiscene.baselines.lift import LiftParams, depth_order, lift_scene, lift_sim, single_parent

__all__ = ["ImportParams", "JointSdfParams", "JointSdfSimParams", "JointSimParams", "LiftParams", "depth_order",
           "import_external", "joint_sdf", "joint_sdf_sim", "joint_sim", "lift_scene", "lift_sim", "single_parent"]
