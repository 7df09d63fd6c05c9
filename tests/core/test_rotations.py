"""Rotation conversions: round trips, known rotations and shape checks, float32 and float64."""

import math

import pytest
import torch

from torchsplice.core.rotations import (
    EULER_ORDERS, axis_angle_to_quat, euler_to_quat, euler_to_rotmat, quat_angle, quat_apply,
    quat_canonical, quat_conj, quat_mul, quat_slerp, quat_to_axis_angle, quat_to_euler, quat_to_rotmat,
    random_quat, rotmat_to_euler, rotmat_to_quat,
)

DTYPES = [(torch.float32, 1e-5), (torch.float64, 1e-12)]


def axis_rotmat(axis: str, deg: float, dtype=torch.float64) -> torch.Tensor:
    """Textbook rotation matrix about one axis (column vectors)."""
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    m = {"X": [[1, 0, 0], [0, c, -s], [0, s, c]],
         "Y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
         "Z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[axis]
    return torch.tensor(m, dtype=dtype)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_quat_rotmat_round_trip_random_batches(dtype, tol):
    g = torch.Generator().manual_seed(1)
    q = random_quat((7, 5, 3), dtype=dtype, generator=g)
    back = rotmat_to_quat(quat_to_rotmat(q))
    assert back.shape == q.shape
    assert quat_angle(q, back).max() < 10 * math.sqrt(tol)
    assert torch.allclose(back, quat_canonical(q), atol=50 * tol ** 0.5)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_rotmat_is_orthonormal_and_agrees_with_quat_apply(dtype, tol):
    q = random_quat((100,), dtype=dtype, generator=torch.Generator().manual_seed(2))
    m = quat_to_rotmat(q)
    eye = torch.eye(3, dtype=dtype).expand(100, 3, 3)
    assert torch.allclose(m @ m.transpose(-1, -2), eye, atol=100 * tol)
    assert torch.allclose(torch.linalg.det(m), torch.ones(100, dtype=dtype), atol=100 * tol)
    v = torch.randn(100, 3, dtype=dtype)
    assert torch.allclose(quat_apply(q, v), (m @ v[..., None])[..., 0], atol=100 * tol)


def test_known_rotation_90_degrees_about_y_maps_x_to_minus_z():
    q = axis_angle_to_quat(torch.tensor([0.0, math.pi / 2, 0.0], dtype=torch.float64))
    assert torch.allclose(quat_apply(q, torch.tensor([1.0, 0, 0], dtype=torch.float64)),
                          torch.tensor([0.0, 0, -1.0], dtype=torch.float64), atol=1e-12)
    assert torch.allclose(q, torch.tensor([math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0], dtype=torch.float64))


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_quat_mul_composes_like_matrix_product(dtype, tol):
    g = torch.Generator().manual_seed(3)
    p, q = random_quat((50,), dtype=dtype, generator=g), random_quat((50,), dtype=dtype, generator=g)
    assert torch.allclose(quat_to_rotmat(quat_mul(p, q)), quat_to_rotmat(p) @ quat_to_rotmat(q), atol=100 * tol)
    ident = quat_mul(q, quat_conj(q))
    assert torch.allclose(ident, torch.tensor([1.0, 0, 0, 0], dtype=dtype).expand_as(ident), atol=100 * tol)


@pytest.mark.parametrize("order", EULER_ORDERS)
@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_euler_matches_textbook_product_and_round_trips(order, dtype, tol):
    angles = torch.tensor([[30.0, -40.0, 75.0], [-170.0, 10.0, 5.0], [0.0, 0.0, 0.0]], dtype=dtype)
    for a, m in zip(angles, euler_to_rotmat(angles, order)):
        ref = axis_rotmat(order[0], a[0]) @ axis_rotmat(order[1], a[1]) @ axis_rotmat(order[2], a[2])
        assert torch.allclose(m.double(), ref, atol=100 * tol)
    back = rotmat_to_euler(euler_to_rotmat(angles, order), order)
    assert torch.allclose(back, angles, atol=1e4 * tol)


@pytest.mark.parametrize("order", EULER_ORDERS)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_euler_round_trip_random_rotations_and_gimbal_lock(order, dtype):
    q = random_quat((2000,), dtype=dtype, generator=torch.Generator().manual_seed(4))
    tol = 2e-4 if dtype == torch.float32 else 1e-9
    assert quat_angle(q, euler_to_quat(quat_to_euler(q, order), order)).max() < tol
    lock = torch.tensor([[30.0, 90.0, 20.0], [10.0, -90.0, 50.0]], dtype=dtype)
    ql = euler_to_quat(lock, order)
    assert quat_angle(ql, euler_to_quat(quat_to_euler(ql, order), order)).max() < (1e-3 if dtype == torch.float32 else 1e-7)


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_euler_angles_near_the_lock_of_float32_rotations_give_the_rotation_back(order):
    """A rotation stored as float32 within 1e-7 of gimbal lock (a constant -90 degree joint):
    its float64 matrix's first angle is noise; the three angles still give the rotation back."""
    g = torch.Generator().manual_seed(7)
    angles = torch.tensor([[12.0, -90.0, 31.0], [-40.0, 90.0, 5.0], [3.0, -89.99999, 2.0]], dtype=torch.float64)
    angles = torch.cat([angles, torch.rand(50, 3, generator=g, dtype=torch.float64) * 60 - 30
                        + torch.tensor([0.0, 90.0, 0.0], dtype=torch.float64) * torch.sign(torch.rand(50, 1) - 0.5)])
    angles[3:, 1] = angles[3:, 1].clamp(-90, 90)
    q = euler_to_quat(angles, order).float().double()  # through float32, as a database stores it
    m = quat_to_rotmat(q)
    back = euler_to_rotmat(rotmat_to_euler(m, order), order)
    assert (back - m).abs().max() < 1e-6


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_axis_angle_round_trip_including_tiny_angles(dtype, tol):
    aa = torch.randn(200, 3, dtype=dtype, generator=torch.Generator().manual_seed(5))
    aa = aa / aa.norm(dim=-1, keepdim=True) * torch.rand(200, 1, dtype=dtype) * 3.0
    aa[:3] *= 1e-9
    assert torch.allclose(quat_to_axis_angle(axis_angle_to_quat(aa)), aa, atol=1e3 * tol)


def test_slerp_endpoints_midpoint_and_shorter_arc():
    p = torch.tensor([1.0, 0, 0, 0], dtype=torch.float64)
    q = axis_angle_to_quat(torch.tensor([0, 0, math.pi / 2], dtype=torch.float64))
    assert torch.allclose(quat_slerp(p, q, 0.0), p)
    assert torch.allclose(quat_slerp(p, q, 1.0), q)
    mid = quat_slerp(p, q, 0.5)
    assert torch.allclose(quat_to_axis_angle(mid), torch.tensor([0, 0, math.pi / 4], dtype=torch.float64))
    # -q is the same rotation: slerp must take the shorter arc, giving the same midpoint rotation
    assert quat_angle(quat_slerp(p, -q, 0.5), mid) < 1e-12
    t = torch.linspace(0, 1, 11, dtype=torch.float64)
    path = quat_slerp(p.expand(11, 4), q.expand(11, 4), t)
    assert torch.allclose(quat_angle(p.expand(11, 4), path), t * math.pi / 2, atol=1e-12)


def test_shape_errors_raise_value_error():
    with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
        quat_to_rotmat(torch.zeros(3, 3))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\)"):
        rotmat_to_quat(torch.zeros(3, 4))
    with pytest.raises(ValueError, match="Euler order"):
        euler_to_quat(torch.zeros(3), "XYX")
