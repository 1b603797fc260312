from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from hopper_sim.controller.errors import InputShapeError
from hopper_sim.controller.hop_model import (
    AffineScaler,
    HopNet,
    InputRanges,
    heading_frame,
    rotate_xy,
)

finite = st.floats(-10, 10, allow_nan=False)


@settings(max_examples=50, deadline=None)
@given(vx=finite, vy=finite, vz=finite, angle=st.floats(-7, 7))
def test_heading_frame_is_invariant_to_rotation_about_z(vx, vy, vz, angle):
    v = np.array([vx, vy, vz])
    s, z, psi = heading_frame(v)
    s2, z2, psi2 = heading_frame(rotate_xy(v, angle))
    assert s2 == pytest.approx(s, abs=1e-9)
    assert z2 == z
    if s > 1e-6:
        assert np.cos(psi2 - psi - angle) == pytest.approx(1.0, abs=1e-9)
        # the velocity expressed in its own heading frame points along +x
        assert rotate_xy(v, -psi)[:2] == pytest.approx([s, 0.0], abs=1e-9)


def test_rotate_xy_round_trip_and_passes_z():
    v = np.random.default_rng(0).normal(size=(5, 3))
    angle = np.linspace(-3, 3, 5)
    back = rotate_xy(rotate_xy(v, angle), -angle)
    np.testing.assert_allclose(back, v, atol=1e-12)
    np.testing.assert_array_equal(rotate_xy(v, angle)[:, 2], v[:, 2])


def test_heading_frame_rejects_wrong_shape():
    with pytest.raises(InputShapeError, match="length 3"):
        heading_frame(np.zeros((4, 2)))


def test_input_ranges_validate_and_round_trip():
    r = InputRanges(speed=(2.0, 5.0))
    assert InputRanges.from_array(r.as_array()) == r
    with pytest.raises(InputShapeError, match="speed"):
        InputRanges(speed=(5.0, 2.0))
    with pytest.raises(InputShapeError, match=r"\(4, 2\)"):
        InputRanges.from_array(np.zeros((3, 2)))


def test_scaler_inverse_and_validation():
    sc = AffineScaler([1.0, -2.0], [2.0, 0.5])
    x = torch.tensor([[3.0, 4.0], [-1.0, 0.0]])
    torch.testing.assert_close(sc.inverse(sc(x)), x)
    with pytest.raises(InputShapeError, match="positive"):
        AffineScaler([0.0], [0.0])


def test_hopnet_maps_box_to_unit_cube_and_restores_units():
    ranges = InputRanges()
    net = HopNet(ranges, output_mean=np.arange(5.0), output_std=np.full(5, 2.0), hidden=(8,))
    box = torch.tensor(ranges.as_array().T, dtype=torch.float32)
    torch.testing.assert_close(net.input_scaler(box), torch.tensor([[-1.0] * 4, [1.0] * 4]))
    x = torch.tensor([[3.0, -0.5, 1.2, 0.1]])
    z, logit = net.forward_standardised(x)
    y, logit2 = net(x)
    torch.testing.assert_close(y, z * 2.0 + torch.arange(5.0))
    torch.testing.assert_close(logit, logit2)
    y_np, p = net.predict(x.numpy())
    assert y_np.shape == (1, 5) and 0.0 < p[0] < 1.0
    with pytest.raises(InputShapeError, match=r"\(N, 4\)"):
        net.predict(np.zeros((2, 3)))
    with pytest.raises(InputShapeError, match="length 5"):
        HopNet(ranges, np.zeros(4), np.ones(4))
