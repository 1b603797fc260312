"""Names of the MJCF elements the simulation reads or drives, and the model file paths.

Every physical value lives in ``hopper_sim/models/*.xml`` (package data, found with
:mod:`importlib.resources`, so an installed wheel reads its own copy); Python refers to it
only through the names below (see ``hopper_sim/models/README.md``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

MODELS_DIR: Path = Path(str(resources.files("hopper_sim") / "models"))
SCENE_XML: Path = MODELS_DIR / "scene.xml"

# Bodies.
BODY_COM = "com"
BODY_FOOT = "foot"  # mocap body: the pinned stance foot
# Joints of the CoM (slide joints along world x, y, z, in this order in qpos/qvel).
JOINT_X = "com_x"
JOINT_Y = "com_y"
JOINT_Z = "com_z"
COM_JOINTS: tuple[str, str, str] = (JOINT_X, JOINT_Y, JOINT_Z)
# Tendon: the push-only spring leg.
TENDON_LEG = "leg"
# Actuator: stance thrust, force = ctrl * ldot along the leg.
ACTUATOR_THRUST = "thrust"

# Custom numerics of the scene: perturbation defaults.
NUMERIC_TERRAIN_AMPLITUDE = "terrain_amplitude"
NUMERIC_TERRAIN_LENGTHSCALE = "terrain_lengthscale"
NUMERIC_TERRAIN_FEATURES = "terrain_features"
NUMERIC_TERRAIN_OFFSET = "terrain_offset"
NUMERIC_NOISE_SIGMA = "noise_sigma"
NUMERIC_NOISE_BOUND = "noise_bound"
