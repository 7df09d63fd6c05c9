"""Forward kinematics: known answers on a hand-made chain, and a per-joint reference on every real clip."""

import math

import pytest
import torch

from torchsplice.core.rotations import axis_angle_to_quat, quat_to_rotmat, random_quat
from torchsplice.core.skeleton import Skeleton
from torchsplice.core.fk import end_site_positions, forward_kinematics


def reference_fk(rotations, root_translation, offsets, parents, translations=None):
    """Straightforward per-frame, per-joint FK with rotation matrices (float64), for comparison."""
    T, J = rotations.shape[:2]
    R = quat_to_rotmat(rotations.double())
    t = offsets.double().expand(T, J, 3) if translations is None else translations.double()
    pos = torch.zeros(T, J, 3, dtype=torch.float64)
    glob = torch.zeros(T, J, 3, 3, dtype=torch.float64)
    for f in range(T):
        for j, p in enumerate(parents):
            if p < 0:
                glob[f, j] = R[f, j]
                pos[f, j] = root_translation[f].double()
            else:
                glob[f, j] = glob[f, p] @ R[f, j]
                pos[f, j] = pos[f, p] + glob[f, p] @ t[f, j]
    return pos, glob


def chain():
    """Root -> A (10 along x) -> B (5 along x), plus C under root (3 along y)."""
    return Skeleton(["root", "A", "B", "C"], [-1, 0, 1, 0],
                    torch.tensor([[0.0, 0, 0], [10, 0, 0], [5, 0, 0], [0, 3, 0]]),
                    [["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"]] + [["Zrotation", "Xrotation", "Yrotation"]] * 3,
                    end_site_parents=[2], end_site_offsets=torch.tensor([[1.0, 0, 0]]))


def test_hand_made_chain_known_answers():
    sk = chain()
    rot = torch.zeros(1, 4, 4, dtype=torch.float64)
    rot[..., 0] = 1.0
    rot[0, 0] = axis_angle_to_quat(torch.tensor([0, 0, math.pi / 2], dtype=torch.float64))  # root: 90 deg about z
    rot[0, 1] = axis_angle_to_quat(torch.tensor([0, 0, -math.pi / 2], dtype=torch.float64))  # A: -90 about z
    root = torch.tensor([[1.0, 2.0, 3.0]], dtype=torch.float64)
    pos, grot = forward_kinematics(rot, root, sk.offsets, sk.parents)
    expect = torch.tensor([[1.0, 2, 3], [1, 12, 3], [6, 12, 3], [-2, 2, 3]], dtype=torch.float64)
    assert torch.allclose(pos[0], expect, atol=1e-12)
    # A's global rotation is identity (90 - 90), root's is 90 about z
    assert torch.allclose(quat_to_rotmat(grot[0, 1]), torch.eye(3, dtype=torch.float64), atol=1e-12)
    ends = end_site_positions(pos, grot, sk.end_site_parents, sk.end_site_offsets)
    assert torch.allclose(ends[0, 0], torch.tensor([7.0, 12, 3], dtype=torch.float64), atol=1e-12)


def test_animated_translations_replace_offsets():
    sk = chain()
    rot = torch.zeros(2, 4, 4)
    rot[..., 0] = 1.0
    trans = sk.offsets.float().expand(2, 4, 3).clone()
    trans[1, 2] = torch.tensor([0.0, 7.0, 0.0])  # B moves in frame 1
    pos, _ = forward_kinematics(rot, torch.zeros(2, 3), sk.offsets.float(), sk.parents, trans)
    assert torch.allclose(pos[0, 2], torch.tensor([15.0, 0, 0]))
    assert torch.allclose(pos[1, 2], torch.tensor([10.0, 7, 0]))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_batched_random_poses_match_reference(dtype):
    sk = chain()
    g = torch.Generator().manual_seed(0)
    rot = random_quat((3, 6, 4), dtype=dtype, generator=g)
    root = torch.randn(3, 6, 3, dtype=dtype, generator=g)
    pos, grot = forward_kinematics(rot, root, sk.offsets.to(dtype), sk.parents)
    assert pos.dtype == dtype and pos.shape == (3, 6, 4, 3) and grot.shape == (3, 6, 4, 4)
    for b in range(3):
        ref_pos, ref_rot = reference_fk(rot[b], root[b], sk.offsets, sk.parents)
        tol = 1e-4 if dtype == torch.float32 else 1e-12
        assert torch.allclose(pos[b].double(), ref_pos, atol=tol)
        assert torch.allclose(quat_to_rotmat(grot[b]).double(), ref_rot, atol=tol)


def test_gradients_flow_to_rotations_and_root():
    sk = chain()
    rot = random_quat((5, 4), dtype=torch.float64, generator=torch.Generator().manual_seed(1)).requires_grad_()
    root = torch.zeros(5, 3, dtype=torch.float64, requires_grad=True)
    pos, _ = forward_kinematics(rot, root, sk.offsets, sk.parents)
    pos[:, 2].sum().backward()
    assert rot.grad is not None and rot.grad[:, 1].abs().sum() > 0
    assert torch.allclose(root.grad, torch.ones(5, 3, dtype=torch.float64))


def test_shape_errors():
    sk = chain()
    with pytest.raises(ValueError, match="rotations"):
        forward_kinematics(torch.zeros(5, 3, 4), torch.zeros(5, 3), sk.offsets, sk.parents)
    with pytest.raises(ValueError, match="root_translation"):
        forward_kinematics(torch.zeros(5, 4, 4), torch.zeros(4, 3), sk.offsets, sk.parents)


@pytest.mark.gpu
def test_cuda_matches_cpu():
    sk = chain()
    rot = random_quat((2, 9, 4), generator=torch.Generator().manual_seed(2))
    root = torch.randn(2, 9, 3)
    cpu, _ = forward_kinematics(rot, root, sk.offsets.float(), sk.parents)
    gpu, _ = forward_kinematics(rot.cuda(), root.cuda(), sk.offsets.float().cuda(), sk.parents)
    assert gpu.device.type == "cuda" and torch.allclose(gpu.cpu(), cpu, atol=1e-5)


def check_every_real_clip_matches_per_joint_reference(m):
    """``m``: a real file read in float64 (tests/formats/test_real_files.py)."""
    frames = torch.linspace(0, m.num_frames - 1, min(m.num_frames, 40)).long()  # the reference is slow
    pos, _ = forward_kinematics(m.rotations[frames], m.root_translation[frames], m.skeleton.offsets,
                                m.skeleton.parents, None if m.translations is None else m.translations[frames])
    ref, _ = reference_fk(m.rotations[frames], m.root_translation[frames], m.skeleton.offsets,
                          m.skeleton.parents, None if m.translations is None else m.translations[frames])
    assert torch.allclose(pos, ref, atol=1e-9 * m.skeleton.size())
    # the whole clip in float32, batched with itself and padded, agrees too
    p32, _ = forward_kinematics(m.rotations.float()[None].expand(2, -1, -1, -1), m.root_translation.float()[None].expand(2, -1, -1),
                                m.skeleton.offsets.float(), m.skeleton.parents,
                                None if m.translations is None else m.translations.float()[None].expand(2, -1, -1, -1))
    assert torch.allclose(p32[1, frames].double(), ref, atol=2e-5 * max(m.skeleton.size(), ref.abs().max().item()))
