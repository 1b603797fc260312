"""The landing-error model's prior, from the hopper model, its controller and the scene.

What the robot's designer knows before the first hop, and how it enters the prior of
:class:`planner.gp.LandingErrorGP` (:func:`error_prior`):

* **The controller's own error** (no terrain, no noise), per action: simulated on the nominal
  hopper from departure states like those of the navigation loop (:func:`calibrate`): a
  chain of hops with random requests, the controller's backup switch among all actions, and
  departure points uniform in a cell; from each chain state every action the controller
  executes as requested is hopped. Its mean per action and axis is the prior mean
  ``bias_mean`` (measured with the shipped controller: one-cell hops undershoot by 0.07 m,
  two-cell hops by 0.18-0.20 m, the same as from 600 loop-like states of case (a) to within
  0.012 m); its std is the prior guess of the residual (``residual_std``: 0.035-0.04 m for
  one-cell hops, up to 0.1 m along two-cell hops). ``bias_std`` (0.05 m) is what the mean of
  a run's hops may differ by (the mean along-hop error of hops that continue forward and of
  hops that reverse differs by 0.07 m).
* **The terrain**, a draw per horizontal axis of ``GP(0, A^2 exp(-|x - x'|^2 / (2 ell^2)))``
  (the scene's ``terrain_amplitude`` ``A`` [N] and ``terrain_lengthscale`` ``ell`` [m]),
  acting as a constant stance force: a landing moves by about ``J F`` under a stance force
  ``F``, ``J`` [m/N] the sensitivity (measured: 2.7-3.1 mm/N for one-cell hops and across
  two-cell hops, 0.7-1.0 mm/N along two-cell hops, cross terms below 0.05 mm/N). The prior
  takes ``field_std = A J_max`` (``J_max`` measured from the steady gait for every action),
  ``offset_std = A_0 J_max`` for the uniform part of the force (``terrain_offset`` ``A_0``)
  and ``lengthscale = ell``.
* **The landing noise** nu of the scene (``noise_sigma``, ``noise_bound``).

The calibration depends only on the hopper model and the controller (not on a world or a
run seed; the chain's generator is seeded with ``seed``). The one for the shipped model and
controller is stored in ``hopper_sim/data/error_prior.json`` (written by
``scripts/calibrate_error_prior.py``) and used when its fingerprints match; otherwise
:func:`load_calibration` computes it (seconds) and caches it for the process.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from hopper_sim.controller import LegAngleController
from hopper_sim.controller.simulator import nominal_energy
from hopper_sim.navigation.environment import EnvConfig
from hopper_sim.physics.batch import simulate_hops
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel
from planner._util.atomic import atomic_write
from planner.gp import GPConfig, TruncatedGaussianNoise
from planner.imdp.grid import ACTION_OFFSETS

SHIPPED = Path(__file__).resolve().parents[1] / "data" / "error_prior.json"
"""The calibration of the shipped model and controller."""

BIAS_STD = 0.05
"""Prior std [m] of a run's mean error per action about the calibrated mean."""

_CACHE: dict[tuple[str, str, float], ErrorCalibration] = {}


@dataclass(frozen=True)
class ErrorCalibration:
    """What :func:`calibrate` measured: ``sensitivity`` ``J_max`` [m/N];
    ``sensitivity_table`` ``(8, 2)`` [m/N], per action and axis the largest sensitivity of
    the landing to a uniform stance force along that axis over the chain states; ``bias`` and
    ``spread`` ``(8, 2)`` [m], mean and std of the controller's landing error per action and
    axis, for cells of side ``cell`` [m]; the fingerprints of the model and controller; the
    chain length and seed."""

    sensitivity: float
    sensitivity_table: tuple[tuple[float, float], ...]
    bias: tuple[tuple[float, float], ...]
    spread: tuple[tuple[float, float], ...]
    cell: float
    model_hash: str
    controller_hash: str
    states: int
    seed: int

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1) + "\n"

    @classmethod
    def from_json(cls, text: str) -> ErrorCalibration:
        raw = json.loads(text)
        raw["bias"] = tuple(tuple(float(v) for v in row) for row in raw["bias"])
        for key in ("spread", "sensitivity_table"):
            raw[key] = tuple(tuple(float(v) for v in row) for row in raw[key])
        return cls(**raw)


class _Uniform:
    """A spatially constant horizontal force field [N]
    (:class:`hopper_sim.physics.terrain.ForceField`)."""

    def __init__(self, force: tuple[float, float]) -> None:
        self.value = np.asarray(force, dtype=float)

    def force(self, xy: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.value, (np.atleast_2d(xy).shape[0], 2)).copy()


def controller_hash(controller: LegAngleController) -> str:
    """SHA-1 of the controller's network weights and steady gait."""
    h = hashlib.sha1()
    for p in controller.optimizer.net.state_dict().values():
        h.update(p.detach().cpu().numpy().tobytes())
    s = controller.steady
    h.update(np.array([s.speed, s.vz, controller.backup_threshold]).tobytes())
    return h.hexdigest()


def _sensitivities(
    model: HopperModel,
    controller: LegAngleController,
    vel: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    force: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``|d landing_d / d F_d|`` [m/N], ``(S, A, 2)``, of the hops with touchdown angles
    ``alpha``, ``beta`` ``(S, A)`` from departure velocities ``vel`` ``(S, 3)`` (central
    differences under a uniform stance force of ``+-force`` newtons along each axis), and
    ``(S, A)`` whether all four hops of an entry succeeded."""
    n_states, n_act = alpha.shape
    energy = nominal_energy(model, controller.steady.speed)
    land = []
    ok = np.ones((n_states, n_act), dtype=bool)
    for f in ((force, 0.0), (-force, 0.0), (0.0, force), (0.0, -force)):
        res = simulate_hops(
            model, np.repeat(vel, n_act, 0), alpha.ravel(), beta.ravel(),
            terrain=_Uniform(f), thrust=True, nominal_energy=energy,
        )  # fmt: skip
        ok &= res.ok.reshape(n_states, n_act)
        land.append(res.next_pos.reshape(n_states, n_act, 2))
    jx = np.abs(land[0][..., 0] - land[1][..., 0]) / (2.0 * force)
    jy = np.abs(land[2][..., 1] - land[3][..., 1]) / (2.0 * force)
    return np.stack([jx, jy], axis=-1), ok


def _max_sensitivity(
    model: HopperModel, controller: LegAngleController, force: float, cell: float
) -> float:
    steady = controller.steady.velocity
    sol, _, _ = controller.solve_all(np.zeros(2), steady, ACTION_OFFSETS * cell)
    j, ok = _sensitivities(model, controller, steady[None], sol.alpha[None], sol.beta[None], force)
    if not ok.all():
        raise RuntimeError(f"calibration: a hop from the steady gait failed under +-{force} N")
    return float(j.max())


def _sensitivity_table(
    model: HopperModel,
    controller: LegAngleController,
    vel: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    ok: np.ndarray,
    force: float,
) -> np.ndarray:
    """``(n_actions, 2)`` [m/N]: per action and axis the largest ``|d landing_d / d F_d|``
    over the chain states where the action is executed as requested (``ok``) and its four
    hops succeed (:func:`_sensitivities`)."""
    j, hopped = _sensitivities(model, controller, vel, alpha, beta, force)
    j[~(ok & hopped)] = 0.0
    return j.max(axis=0)


def _chain_states(
    model: HopperModel,
    controller: LegAngleController,
    cell: float,
    states: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Departure velocities (S, 3) and offsets from the cell centre (S, 2), metres."""
    offsets = ACTION_OFFSETS * cell
    energy = nominal_energy(model, controller.steady.speed)
    data = model.make_data()
    vel = controller.steady.velocity.copy()
    all_actions = list(range(len(offsets)))
    vs, offs = [], []
    while len(vs) < states:
        off = rng.uniform(-0.5, 0.5, size=2) * cell
        req = int(rng.integers(len(offsets)))
        d = controller.decide(np.zeros(2), vel, all_actions, offsets - off, req)
        vs.append(vel.copy())
        offs.append(off)
        hop = simulate_hop(
            model, np.zeros(2), vel, d.alpha, d.beta, thrust=True, nominal_energy=energy,
            record_path=False, data=data,
        )  # fmt: skip
        vel = np.asarray(hop.next_vel, dtype=float) if hop.ok else controller.steady.velocity
    return np.array(vs), np.array(offs)


def calibrate(
    model: HopperModel,
    controller: LegAngleController,
    *,
    cell: float = 1.0,
    states: int = 150,
    seed: int = 0,
    force: float = 10.0,
) -> ErrorCalibration:
    """Measure the controller's landing error per action for cells of side ``cell`` [m] and
    the largest force sensitivity (module docstring)."""
    rng = np.random.default_rng(seed)
    offsets = ACTION_OFFSETS * float(cell)
    vel, off = _chain_states(model, controller, float(cell), int(states), rng)
    n_act = len(offsets)
    targets = offsets[None, :, :] - off[:, None, :]  # relative to the departure
    alpha = np.empty((len(vel), n_act))
    beta = np.empty((len(vel), n_act))
    cost = np.empty((len(vel), n_act))
    for k in range(len(vel)):
        sol, _, _ = controller.solve_all(np.zeros(2), vel[k], targets[k])
        alpha[k], beta[k], cost[k] = sol.alpha, sol.beta, sol.cost
    res = simulate_hops(
        model, np.repeat(vel, n_act, 0), alpha.ravel(), beta.ravel(), thrust=True,
        nominal_energy=nominal_energy(model, controller.steady.speed),
    )  # fmt: skip
    err = res.next_pos.reshape(len(vel), n_act, 2) - targets
    ok = (cost <= controller.backup_threshold) & res.ok.reshape(len(vel), n_act)
    if (ok.sum(axis=0) < 2).any():
        raise RuntimeError(
            f"calibration: actions {np.flatnonzero(ok.sum(axis=0) < 2).tolist()} were executed "
            "as requested from fewer than 2 chain states"
        )
    table_j = _sensitivity_table(model, controller, vel, alpha, beta, ok, force)
    w = ok[..., None].astype(float)
    mean = (err * w).sum(0) / w.sum(0)
    spread = np.sqrt((((err - mean) ** 2) * w).sum(0) / (w.sum(0) - 1.0))

    def table(a: np.ndarray) -> tuple[tuple[float, float], ...]:
        return tuple((float(x), float(y)) for x, y in np.round(a, 6))

    steady_max = _max_sensitivity(model, controller, force, float(cell))
    return ErrorCalibration(
        sensitivity=round(max(steady_max, float(table_j.max())), 9),
        sensitivity_table=tuple((float(x), float(y)) for x, y in np.round(table_j, 9)),
        bias=table(mean),
        spread=table(spread),
        cell=float(cell),
        model_hash=model.param_hash(),
        controller_hash=controller_hash(controller),
        states=int(states),
        seed=int(seed),
    )


def save_calibration(calibration: ErrorCalibration, path: Path = SHIPPED) -> Path:
    """Write ``calibration`` as JSON, atomically."""
    with atomic_write(path, "w") as fh:
        fh.write(calibration.to_json())
    return Path(path)


def load_calibration(
    model: HopperModel, controller: LegAngleController, cell: float = 1.0
) -> ErrorCalibration:
    """The shipped calibration if it was made for this model, controller and cell size, else
    a fresh one (:func:`calibrate`, cached for the process)."""
    key = (model.param_hash(), controller_hash(controller), float(cell))
    if key not in _CACHE:
        cal = None
        if SHIPPED.is_file():
            shipped = ErrorCalibration.from_json(SHIPPED.read_text(encoding="utf-8"))
            if (shipped.model_hash, shipped.controller_hash, shipped.cell) == key:
                cal = shipped
        _CACHE[key] = cal or calibrate(model, controller, cell=cell)
    return _CACHE[key]


def _scale(cal: ErrorCalibration) -> tuple[tuple[float, float], ...]:
    """Each action's sensitivity relative to ``J_max``, at least 0.05 (never 0)."""
    ratio = np.asarray(cal.sensitivity_table, dtype=np.float64) / cal.sensitivity
    return tuple((float(x), float(y)) for x, y in np.clip(ratio, 0.05, 1.0))


def error_prior(
    model: HopperModel,
    controller: LegAngleController,
    *,
    terrain: bool = EnvConfig.terrain,
    cell: float = 1.0,
    **overrides: object,
) -> GPConfig:
    """The prior of the landing-error model for this hopper and scene (module docstring):
    ``bias_mean`` and ``residual_std`` from the calibration, ``bias_std`` =
    :data:`BIAS_STD`, ``field_std = A J_max`` and ``offset_std = A_0 J_max`` (0 without
    terrain), ``lengthscale = ell`` and
    the scene's landing noise; other :class:`~planner.gp.GPConfig` fields by name."""
    cal = load_calibration(model, controller, cell)
    pp = model.perturbation
    values: dict[str, object] = {
        "lengthscale": pp.terrain_lengthscale,
        "field_std": pp.terrain_amplitude * cal.sensitivity if terrain else 0.0,
        "offset_std": pp.terrain_offset * cal.sensitivity if terrain else 0.0,
        "scale": _scale(cal),
        "bias_mean": cal.bias,
        "bias_std": BIAS_STD,
        "residual_std": cal.spread,
        "noise": TruncatedGaussianNoise(pp.noise_sigma, pp.noise_bound),
    }
    values.update(overrides)
    return GPConfig(**values)  # type: ignore[arg-type]
