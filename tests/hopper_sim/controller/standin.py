"""An analytic stand-in hop map for testing the controller without MuJoCo.

Not a SLIP: a smooth map with the same interface and the same symmetry (it works in the
heading frame of the incoming velocity), a known inverse, a known fixed point and a failure
region, so the tests can check the learned pieces against ground truth.

Heading frame: reach R = 0.6 s cos(alpha) / cos(pi/4), direction phi = 0.8 beta,
displacement R (cos phi, sin phi); next horizontal speed s' = S0 + 0.5 (s - S0) along phi;
next v_z' = -0.7 + 0.3 (v_z + 0.7) - 0.5 (alpha - 1.2). The hop fails where
alpha < 0.95 and |beta| > 1.0.
"""

from __future__ import annotations

import numpy as np

from hopper_sim.controller.dataset import HopSamples
from hopper_sim.controller.hop_model import heading_frame, rotate_xy

S0 = 3.5


def failed(alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    return (np.asarray(alpha) < 0.95) & (np.abs(np.asarray(beta)) > 1.0)


def standin_hop(velocity: np.ndarray, alpha: np.ndarray, beta: np.ndarray) -> HopSamples:
    s, vz, psi = heading_frame(np.asarray(velocity, dtype=np.float64))
    alpha = np.asarray(alpha, dtype=np.float64)
    beta = np.asarray(beta, dtype=np.float64)
    reach = 0.6 * s * np.cos(alpha) / np.cos(np.pi / 4)
    phi = 0.8 * beta
    disp = reach[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    s_next = S0 + 0.5 * (s - S0)
    vz_next = -0.7 + 0.3 * (vz + 0.7) - 0.5 * (alpha - 1.2)
    vel = np.stack([s_next * np.cos(phi), s_next * np.sin(phi), vz_next], axis=1)
    ok = ~failed(alpha, beta)
    disp = rotate_xy(disp, psi)
    vel = rotate_xy(vel, psi)
    disp[~ok] = np.nan
    vel[~ok] = np.nan
    status = np.where(ok, "ok", "no_touchdown")
    return HopSamples(ok, disp, vel, status)


def steady_alpha(hop_length: float) -> float:
    return float(np.arccos(hop_length * np.cos(np.pi / 4) / (0.6 * S0)))


def steady_vz(alpha: float) -> float:
    return -0.7 - 0.5 * (alpha - 1.2) / 0.7
