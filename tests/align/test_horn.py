"""Horn rotations: known rotations recovered, SVD == eigen form, reflections, weights, degenerate clouds."""

import pytest
import torch

from torchsplice.align.horn import cross_covariance, horn_rotation, horn_rotation_eig, horn_rotation_matrix
from torchsplice.core.rotations import axis_angle_to_quat, quat_angle, quat_apply, quat_to_rotmat, random_quat

DTYPES = [(torch.float32, 1e-5), (torch.float64, 1e-12)]


def cost(R: torch.Tensor, source: torch.Tensor, target: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """``sum_k w_k |target_k - R source_k|^2`` for ``(..., 3, 3)`` R (batch dims broadcast)."""
    return (w * (target - source @ R.transpose(-1, -2)).square().sum(-1)).sum(-1)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_recovers_known_rotation_exactly_with_batch_dims(dtype, tol):
    g = torch.Generator().manual_seed(0)
    q = random_quat((4, 3), dtype=dtype, generator=g)
    source = torch.randn(4, 3, 9, 3, dtype=dtype, generator=g)
    target = quat_apply(q[..., None, :], source)
    w = torch.rand(4, 3, 9, dtype=dtype, generator=g) + 0.1
    for weights in (None, w, w[0, 0]):
        got = horn_rotation(source, target, weights)
        assert got.shape == (4, 3, 4) and got.dtype == dtype
        assert (got[..., 0] >= 0).all()
        assert quat_angle(got, q).max() < 100 * tol ** 0.5


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_recovers_rotation_approximately_under_small_noise(dtype):
    g = torch.Generator().manual_seed(1)
    q = random_quat((20,), dtype=dtype, generator=g)
    source = torch.randn(20, 30, 3, dtype=dtype, generator=g)
    target = quat_apply(q[:, None], source) + 1e-3 * torch.randn(20, 30, 3, dtype=dtype, generator=g)
    assert quat_angle(horn_rotation(source, target), q).max() < 5e-3


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_svd_and_eigen_forms_agree_on_arbitrary_clouds(dtype, tol):
    g = torch.Generator().manual_seed(2)
    source = torch.randn(2, 50, 6, 3, dtype=dtype, generator=g)
    target = torch.randn(2, 50, 6, 3, dtype=dtype, generator=g)  # unrelated: the fit is poor but unique
    w = torch.rand(6, dtype=dtype, generator=g)
    q_svd, q_eig = horn_rotation(source, target, w), horn_rotation_eig(source, target, w)
    assert q_eig.shape == q_svd.shape == (2, 50, 4)
    assert quat_angle(q_svd, q_eig).max() < 1e3 * tol ** 0.5
    c_svd = cost(horn_rotation_matrix(source, target, w), source, target, w)
    c_eig = cost(quat_to_rotmat(q_eig), source, target, w)
    assert torch.allclose(c_svd, c_eig, rtol=1e3 * tol, atol=1e3 * tol)


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_mirror_image_target_gives_best_proper_rotation(dtype, tol):
    g = torch.Generator().manual_seed(3)
    source = torch.randn(8, 3, dtype=dtype, generator=g)
    q = random_quat((), dtype=dtype, generator=g)
    target = quat_apply(q, source) * torch.tensor([-1.0, 1.0, 1.0], dtype=dtype)  # a reflection
    w = torch.full((8,), 1.0 / 8, dtype=dtype)
    R = horn_rotation_matrix(source, target)
    eye = torch.eye(3, dtype=dtype)
    assert torch.allclose(R @ R.T, eye, atol=100 * tol)
    assert abs(torch.linalg.det(R).item() - 1.0) < 100 * tol
    best = cost(R, source, target, w)
    others = quat_to_rotmat(random_quat((20000,), dtype=torch.float64, generator=g))
    assert (cost(others, source.double(), target.double(), w.double()) >= best.double() - 1e3 * tol).all()
    nudges = quat_to_rotmat(axis_angle_to_quat(1e-2 * torch.randn(2000, 3, dtype=torch.float64, generator=g)))
    assert (cost(nudges @ R.double(), source.double(), target.double(), w.double()) >= best.double() - 1e3 * tol).all()
    assert quat_angle(horn_rotation_eig(source, target), horn_rotation(source, target)) < 1e3 * tol ** 0.5


def test_zero_weight_point_is_ignored():
    g = torch.Generator().manual_seed(4)
    q = random_quat((), dtype=torch.float64, generator=g)
    source = torch.randn(6, 3, dtype=torch.float64, generator=g)
    target = quat_apply(q, source)
    target[2] = torch.tensor([50.0, -80.0, 20.0], dtype=torch.float64)  # an outlier
    w = torch.ones(6, dtype=torch.float64)
    w[2] = 0.0
    assert quat_angle(horn_rotation(source, target, w), q) < 1e-10
    assert quat_angle(horn_rotation_eig(source, target, w), q) < 1e-10
    assert quat_angle(horn_rotation(source, target), q) > 1e-2  # counted, it spoils the fit


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_degenerate_identical_clouds_give_identity(dtype):
    g = torch.Generator().manual_seed(5)
    generic = torch.randn(5, 3, dtype=dtype, generator=g)
    planar = generic * torch.tensor([1.0, 1.0, 0.0], dtype=dtype)
    collinear = torch.linspace(-1, 2, 5, dtype=dtype)[:, None] * torch.tensor([0.3, -0.5, 0.8], dtype=dtype)
    single = generic[:1]
    zeros = torch.zeros(5, 3, dtype=dtype)
    ident = torch.tensor([1.0, 0, 0, 0], dtype=dtype)
    for cloud in (generic, planar, collinear, single, zeros):
        q = horn_rotation(cloud, cloud)
        assert torch.isfinite(q).all()
        assert quat_angle(q, ident) < (1e-3 if dtype == torch.float32 else 1e-7)
    assert torch.equal(horn_rotation(zeros, zeros, torch.zeros(5, dtype=dtype)), ident)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_degenerate_collinear_clouds_give_a_valid_minimiser(dtype):
    u = torch.tensor([1.0, 2.0, -2.0], dtype=dtype) / 3
    v = torch.tensor([0.0, -0.6, 0.8], dtype=dtype)
    lam = torch.tensor([-1.0, 0.5, 2.0, 3.0], dtype=dtype)
    source, target = lam[:, None] * u, 0.7 * lam[:, None] * v
    for tgt, want in ((target, v), (-target, -v), (lam[:, None] * -u, -u)):
        R = horn_rotation_matrix(source, tgt)
        assert torch.isfinite(R).all()
        assert abs(torch.linalg.det(R).item() - 1.0) < 1e-4
        assert torch.allclose(R @ u, want, atol=1e-4 if dtype == torch.float32 else 1e-9)


def test_broadcasting_and_weight_shapes():
    g = torch.Generator().manual_seed(6)
    source = torch.randn(5, 4, 3, generator=g)
    target = torch.randn(2, 5, 4, 3, generator=g)
    assert horn_rotation(source, target).shape == (2, 5, 4)
    assert horn_rotation_matrix(source, target, torch.rand(4)).shape == (2, 5, 3, 3)
    assert horn_rotation_eig(source, target, torch.rand(5, 4)).shape == (2, 5, 4)
    assert cross_covariance(source, target).shape == (2, 5, 3, 3)


@pytest.mark.parametrize("fn", [horn_rotation, horn_rotation_matrix, horn_rotation_eig])
def test_bad_shapes_raise(fn):
    with pytest.raises(ValueError):
        fn(torch.zeros(4, 2), torch.zeros(4, 2))
    with pytest.raises(ValueError):
        fn(torch.zeros(4, 3), torch.zeros(5, 3))
    with pytest.raises(ValueError):
        fn(torch.zeros(3), torch.zeros(3))
    with pytest.raises(ValueError):
        fn(torch.zeros(4, 3), torch.zeros(4, 3), torch.ones(5))


@pytest.mark.gpu
def test_cuda_matches_cpu():
    g = torch.Generator().manual_seed(7)
    q = random_quat((64,), dtype=torch.float64, generator=g)
    source = torch.randn(64, 7, 3, dtype=torch.float64, generator=g)
    target = quat_apply(q[:, None], source)
    for fn in (horn_rotation, horn_rotation_eig):
        got = fn(source.cuda(), target.cuda())
        assert got.is_cuda
        assert quat_angle(got.cpu(), q).max() < 1e-6
