"""The compiled hopper: MJCF loaded and parameterised through :mod:`dm_control.mjcf`.

Physical parameters are read back from the compiled model by name (``constants.py``), so the
MJCF in ``hopper_sim/models/`` (package data) is their single source. Hot loops use the raw
:class:`mujoco.MjModel` (``HopperModel.model``) and :class:`mujoco.MjData`.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np

from hopper_sim.errors import HopperSimError
from hopper_sim.physics import constants as C

# dm_control picks an OpenGL backend at import; the simulation never renders, so unless the
# caller chose a backend, import it without one (this also avoids a GLFW warning headless).
os.environ.setdefault("MUJOCO_GL", "disable")
from dm_control import mjcf


class HopperModelError(HopperSimError, ValueError):
    """A model file or an override is invalid (names the file, key or value)."""


@dataclass(frozen=True)
class SlipParams:
    """Physical parameters of the SLIP, read back from the compiled model.

    Attributes:
        mass: CoM mass m [kg] (body ``com``).
        rest_length: leg rest length l0 [m] (lower ``springlength`` of tendon ``leg``).
        stiffness: leg stiffness k [N/m] (tendon ``leg``).
        gravity: gravitational acceleration g [m/s^2] (minus ``opt.gravity[2]``).
        timestep: integrator step dt [s] (``opt.timestep``, RK4).
        thrust_limit: largest |command| of actuator ``thrust`` [N s/m] (its ``ctrlrange``).
    """

    mass: float
    rest_length: float
    stiffness: float
    gravity: float
    timestep: float
    thrust_limit: float


@dataclass(frozen=True)
class PerturbationParams:
    """Perturbation defaults, read back from the scene's custom numerics.

    Attributes:
        terrain_amplitude: standard deviation of each axis of the terrain force [N].
        terrain_lengthscale: RBF length scale of the terrain field [m].
        terrain_features: number of random Fourier features per axis.
        terrain_offset: standard deviation of each axis of the uniform part of the terrain
            force (one draw per terrain seed) [N].
        noise_sigma: standard deviation of the landing noise nu [m].
        noise_bound: nu is truncated to [-noise_bound, noise_bound] [m].
    """

    terrain_amplitude: float
    terrain_lengthscale: float
    terrain_features: int
    terrain_offset: float
    noise_sigma: float
    noise_bound: float


#: Largest sqrt(k/m) * dt accepted (the default model has 0.0158; RK4's error per stance
#: grows as its fourth power, and it turns unstable near 2.8).
MAX_OMEGA_DT = 0.1

_PHYSICAL_KEYS = ("mass", "stiffness", "rest_length", "gravity", "timestep", "thrust_limit")
_NUMERIC_KEYS = {
    "terrain_amplitude": C.NUMERIC_TERRAIN_AMPLITUDE,
    "terrain_lengthscale": C.NUMERIC_TERRAIN_LENGTHSCALE,
    "terrain_features": C.NUMERIC_TERRAIN_FEATURES,
    "terrain_offset": C.NUMERIC_TERRAIN_OFFSET,
    "noise_sigma": C.NUMERIC_NOISE_SIGMA,
    "noise_bound": C.NUMERIC_NOISE_BOUND,
}
OVERRIDE_KEYS: tuple[str, ...] = _PHYSICAL_KEYS + tuple(_NUMERIC_KEYS)


def _apply_overrides(root: mjcf.RootElement, overrides: dict[str, float]) -> None:
    for key, value in overrides.items():
        if key not in OVERRIDE_KEYS:
            raise HopperModelError(
                f"unknown model override {key!r}; known: {', '.join(OVERRIDE_KEYS)}"
            )
        value = float(value)
        if not np.isfinite(value) or (value <= 0.0 and key != "thrust_limit") or value < 0.0:
            raise HopperModelError(
                f"model override {key!r} must be a finite positive number: {value}"
            )
        if key == "mass":
            root.find("body", C.BODY_COM).inertial.mass = value
        elif key == "stiffness":
            root.find("tendon", C.TENDON_LEG).stiffness = value
        elif key == "rest_length":
            root.find("tendon", C.TENDON_LEG).springlength = [value, 1e6]
        elif key == "gravity":
            root.option.gravity = [0.0, 0.0, -value]
        elif key == "timestep":
            root.option.timestep = value
        elif key == "thrust_limit":
            root.find("actuator", C.ACTUATOR_THRUST).ctrlrange = [-value, value]
        else:
            root.find("numeric", _NUMERIC_KEYS[key]).data = [value]


@dataclass(frozen=True)
class ReplicatedModel:
    """K independent copies of the hopper in one compiled model, for batched stepping: one
    RK4 step of MuJoCo costs a fixed overhead of about 5 us of CPU whatever the model, so
    stepping K hoppers in one MjData is several times cheaper per hop than K MjData.

    The copies do not interact (no contacts, no constraints). Index arrays are per copy.

    Attributes:
        model: the compiled model. copies: K.
        qpos_adr, dof_adr: (K, 3) addresses of each copy's CoM x, y, z.
        foot_mocap: (K,) mocap ids of the feet; com_body: (K,) body ids of the CoMs;
        thrust_actuator: (K,) actuator ids.
    """

    model: mujoco.MjModel
    copies: int
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    foot_mocap: np.ndarray
    com_body: np.ndarray
    thrust_actuator: np.ndarray


class HopperModel:
    """The hopper scene compiled for simulation.

    Attributes:
        mjcf_model: the dm_control MJCF tree (for further edits, e.g. in studies).
        physics: the dm_control physics (named indexing, e.g. ``physics.named.model``).
        model: the raw :class:`mujoco.MjModel` used by the hot loops.
        params: the SLIP's physical parameters, read back by name.
        perturbation: perturbation defaults, read back by name.
    """

    def __init__(self, mjcf_model: mjcf.RootElement) -> None:
        self.mjcf_model = mjcf_model
        self.physics = mjcf.Physics.from_mjcf_model(mjcf_model)
        self.model: mujoco.MjModel = self.physics.model.ptr
        m = self.model
        self.com_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, C.BODY_COM)
        foot_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, C.BODY_FOOT)
        self.foot_mocap = int(m.body_mocapid[foot_body])
        self.leg_tendon = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, C.TENDON_LEG)
        self.thrust_actuator = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, C.ACTUATOR_THRUST)
        self.qpos_adr = np.array(
            [
                m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)]
                for j in C.COM_JOINTS
            ]
        )
        self.dof_adr = np.array(
            [m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)] for j in C.COM_JOINTS]
        )
        if min(self.com_body, foot_body, self.leg_tendon, self.thrust_actuator) < 0:
            raise HopperModelError(
                "the model lacks one of the named hopper elements (constants.py)"
            )
        if self.foot_mocap < 0:
            raise HopperModelError(f"body {C.BODY_FOOT!r} must be a mocap body")
        self.params = SlipParams(
            mass=float(m.body_mass[self.com_body]),
            rest_length=float(m.tendon_lengthspring[self.leg_tendon, 0]),
            stiffness=float(m.tendon_stiffness[self.leg_tendon]),
            gravity=float(-m.opt.gravity[2]),
            timestep=float(m.opt.timestep),
            thrust_limit=float(m.actuator_ctrlrange[self.thrust_actuator, 1]),
        )
        if self.params.gravity <= 0.0:
            raise HopperModelError(f"gravity must point down (-z): opt.gravity = {m.opt.gravity}")
        if m.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4:
            raise HopperModelError("the hopper model must use the RK4 integrator")
        omega_dt = np.sqrt(self.params.stiffness / self.params.mass) * self.params.timestep
        if omega_dt > MAX_OMEGA_DT:
            raise HopperModelError(
                f"time step {self.params.timestep} s is too coarse for the leg: "
                f"sqrt(k/m) dt = {omega_dt:.3g} > {MAX_OMEGA_DT} (RK4 would lose accuracy)"
            )

        def numeric(name: str) -> float:
            nid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, name)
            if nid < 0:
                raise HopperModelError(f"the scene lacks the custom numeric {name!r}")
            return float(m.numeric_data[m.numeric_adr[nid]])

        self.perturbation = PerturbationParams(
            terrain_amplitude=numeric(C.NUMERIC_TERRAIN_AMPLITUDE),
            terrain_lengthscale=numeric(C.NUMERIC_TERRAIN_LENGTHSCALE),
            terrain_features=int(numeric(C.NUMERIC_TERRAIN_FEATURES)),
            terrain_offset=numeric(C.NUMERIC_TERRAIN_OFFSET),
            noise_sigma=numeric(C.NUMERIC_NOISE_SIGMA),
            noise_bound=numeric(C.NUMERIC_NOISE_BOUND),
        )

    @classmethod
    def load(
        cls, overrides: dict[str, float] | None = None, path: str | Path | None = None
    ) -> HopperModel:
        """Load ``hopper_sim/models/scene.xml`` (or ``path``) and apply ``overrides``.

        Args:
            overrides: values by key, any of :data:`OVERRIDE_KEYS`: ``mass`` [kg],
                ``stiffness`` [N/m], ``rest_length`` [m], ``gravity`` [m/s^2],
                ``timestep`` [s], ``thrust_limit`` [N s/m], and the perturbation defaults.
            path: an MJCF scene with the same named elements.

        Raises:
            HopperModelError: unknown key, non-positive value, or a file without the named elements.
        """
        path = Path(path) if path is not None else C.SCENE_XML
        if not path.is_file():
            raise HopperModelError(f"model file not found: {path}")
        root = mjcf.from_path(str(path))
        _apply_overrides(root, dict(overrides or {}))
        return cls(root)

    def replicated(self, copies: int) -> ReplicatedModel:
        """This model's scene copied ``copies`` times into one model (cached per count).

        Built with :class:`mujoco.MjSpec` from this model's MJCF (with its overrides), so
        every copy has exactly these parameters; copy k > 0 has the name prefix ``h{k}/``.
        """
        copies = int(copies)
        if copies < 1:
            raise HopperModelError(f"need at least one copy of the hopper, got {copies}")
        cache = self.__dict__.setdefault("_replicated", {})
        if copies in cache:
            return cache[copies]
        xml = self.mjcf_model.to_xml_string()
        assets = self.mjcf_model.get_assets()
        spec = mujoco.MjSpec.from_string(xml, assets)
        for k in range(1, copies):
            child = mujoco.MjSpec.from_string(xml, assets)
            spec.attach(child, prefix=f"h{k}/", frame=spec.worldbody.add_frame())
        m = spec.compile()

        def ids(obj: mujoco.mjtObj, name: str) -> np.ndarray:
            out = [mujoco.mj_name2id(m, obj, (f"h{k}/" if k else "") + name) for k in range(copies)]
            if min(out) < 0:
                raise HopperModelError(f"replicated model lacks {name!r} in some copy")
            return np.array(out)

        joints = np.stack([ids(mujoco.mjtObj.mjOBJ_JOINT, j) for j in C.COM_JOINTS], axis=1)
        rep = ReplicatedModel(
            model=m,
            copies=copies,
            qpos_adr=m.jnt_qposadr[joints],
            dof_adr=m.jnt_dofadr[joints],
            foot_mocap=m.body_mocapid[ids(mujoco.mjtObj.mjOBJ_BODY, C.BODY_FOOT)],
            com_body=ids(mujoco.mjtObj.mjOBJ_BODY, C.BODY_COM),
            thrust_actuator=ids(mujoco.mjtObj.mjOBJ_ACTUATOR, C.ACTUATOR_THRUST),
        )
        cache[copies] = rep
        return rep

    def make_data(self) -> mujoco.MjData:
        """A fresh :class:`mujoco.MjData` for this model."""
        return mujoco.MjData(self.model)

    def param_hash(self) -> str:
        """Stable hex digest (sha256, 16 chars) of :attr:`params`: checkpoints store it."""
        text = json.dumps({k: float(np.float64(v)) for k, v in asdict(self.params).items()})
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def energy(self, z: np.ndarray, vel: np.ndarray) -> np.ndarray:
        """Mechanical energy of the CoM in flight, m |v|^2 / 2 + m g z [J] (spring relaxed)."""
        p = self.params
        vel = np.asarray(vel, dtype=float)
        return 0.5 * p.mass * np.sum(vel * vel, axis=-1) + p.mass * p.gravity * np.asarray(z)
