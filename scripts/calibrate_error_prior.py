"""Calibrate the landing-error prior of the shipped hopper and controller.

Usage: python scripts/calibrate_error_prior.py [--states 150] [--seed 0] [--out PATH]

Simulates the controller's landing error per action on the nominal hopper (no terrain, no
noise) from a chain of loop-like departure states and the largest sensitivity of a landing to
a stance force (:func:`hopper_sim.controller.error_prior.calibrate`), prints them and writes them as
JSON (default: ``hopper_sim/data/error_prior.json``, which :func:`error_prior` uses when its
fingerprints match the model and controller). Run it after retraining the controller or
changing the model.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.controller import LegAngleController, load_checkpoint
from hopper_sim.controller.error_prior import SHIPPED, calibrate, save_calibration
from hopper_sim.physics.model import HopperModel
from planner.imdp.grid import ACTIONS


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cell", type=float, default=1.0)
    ap.add_argument("--out", type=Path, default=SHIPPED)
    args = ap.parse_args()
    model = HopperModel.load()
    ckpt = load_checkpoint(expected_param_hash=model.param_hash())
    controller = LegAngleController.from_checkpoint(ckpt)
    t0 = time.perf_counter()
    cal = calibrate(model, controller, cell=args.cell, states=args.states, seed=args.seed)
    print(f"calibrated from {args.states} chain states in {time.perf_counter() - t0:.1f} s")
    print(f"largest force sensitivity J_max: {cal.sensitivity * 1e3:.3f} mm/N")
    bias, spread = np.array(cal.bias), np.array(cal.spread)
    for a, name in enumerate(ACTIONS):
        print(
            f"  {name}: mean error ({bias[a, 0]:+.3f}, {bias[a, 1]:+.3f}) m, "
            f"std ({spread[a, 0]:.3f}, {spread[a, 1]:.3f}) m"
        )
    print(f"wrote {save_calibration(cal, args.out)}")


if __name__ == "__main__":
    main()
