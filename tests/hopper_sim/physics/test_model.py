"""hopper_sim/models/*.xml load, step without warnings, name every element; parameters read back."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from hopper_sim.physics import constants as C
from hopper_sim.physics.model import HopperModel, HopperModelError

MJCF_FILES = sorted(C.MODELS_DIR.glob("*.xml"))

# Element kinds whose every instance must carry a name (objects of the compiled model).
NAMED_OBJECTS = {
    "body": (mujoco.mjtObj.mjOBJ_BODY, "nbody"),
    "joint": (mujoco.mjtObj.mjOBJ_JOINT, "njnt"),
    "geom": (mujoco.mjtObj.mjOBJ_GEOM, "ngeom"),
    "site": (mujoco.mjtObj.mjOBJ_SITE, "nsite"),
    "tendon": (mujoco.mjtObj.mjOBJ_TENDON, "ntendon"),
    "actuator": (mujoco.mjtObj.mjOBJ_ACTUATOR, "nu"),
    "light": (mujoco.mjtObj.mjOBJ_LIGHT, "nlight"),
    "numeric": (mujoco.mjtObj.mjOBJ_NUMERIC, "nnumeric"),
    "texture": (mujoco.mjtObj.mjOBJ_TEXTURE, "ntex"),
    "material": (mujoco.mjtObj.mjOBJ_MATERIAL, "nmat"),
}


def test_models_dir_holds_hopper_and_scene():
    assert {p.name for p in MJCF_FILES} >= {"hopper.xml", "scene.xml"}


@pytest.mark.parametrize("path", MJCF_FILES, ids=lambda p: p.name)
def test_mjcf_loads_steps_one_second_without_warnings_and_names_everything(path):
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    # Start as a hop does: the CoM l0 above a foot placed below it, so the leg is loaded.
    data.qpos[2] = 0.9
    data.mocap_pos[0] = [0.0, 0.0, 0.0]
    mujoco.mj_step(model, data, nstep=round(1.0 / model.opt.timestep))
    assert data.time == pytest.approx(1.0)
    assert all(w.number == 0 for w in data.warning), [w.number for w in data.warning]
    assert np.all(np.isfinite(data.qpos))
    for kind, (obj, count) in NAMED_OBJECTS.items():
        start = 1 if kind == "body" else 0  # the world body is named by MuJoCo
        for i in range(start, getattr(model, count)):
            assert mujoco.mj_id2name(model, obj, i), f"{path.name}: unnamed {kind} #{i}"


def test_params_are_read_back_from_the_mjcf():
    p = HopperModel.load().params
    assert (p.mass, p.rest_length, p.stiffness, p.gravity) == (80.0, 1.0, 20000.0, 9.81)
    assert p.timestep == 0.001 and p.thrust_limit > 0


def test_overrides_change_the_compiled_model_and_the_hash():
    base = HopperModel.load()
    heavy = HopperModel.load({"mass": 90.0, "stiffness": 25000.0, "rest_length": 0.9})
    assert heavy.params.mass == 90.0
    assert heavy.model.body_mass[heavy.com_body] == 90.0
    assert heavy.params.stiffness == 25000.0 and heavy.params.rest_length == 0.9
    assert heavy.param_hash() != base.param_hash()
    assert HopperModel.load().param_hash() == base.param_hash()


def test_bad_overrides_raise_specific_errors():
    with pytest.raises(HopperModelError, match="unknown model override 'masss'"):
        HopperModel.load({"masss": 1.0})
    with pytest.raises(HopperModelError, match="'stiffness'"):
        HopperModel.load({"stiffness": -1.0})
    with pytest.raises(HopperModelError, match="too coarse"):
        HopperModel.load({"stiffness": 1e9})
    with pytest.raises(HopperModelError, match="not found"):
        HopperModel.load(path="/nonexistent/scene.xml")
