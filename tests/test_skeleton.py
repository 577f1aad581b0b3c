import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from physmotion import skeleton as sk


@pytest.fixture
def random_pose() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    rot = Rotation.from_rotvec(rng.normal(scale=0.5, size=(40 * 22, 3))).as_matrix().reshape(40, 22, 3, 3)
    return rot, rng.normal(size=(40, 3))


def test_tree_is_the_smpl_order() -> None:
    assert sk.NUM_JOINTS == 22 and sk.JOINT_NAMES[0] == "pelvis" and sk.JOINT_NAMES[21] == "right_wrist"
    assert all(p < j for j, p in enumerate(sk.PARENTS))  # parents come first
    assert sk.JOINT_NAMES[sk.PARENTS[sk.JOINT_INDEX["left_wrist"]]] == "left_elbow"
    assert sk.children(9) == [12, 13, 14]


def test_default_body_is_an_adult_standing_on_the_floor() -> None:
    rest = sk.rest_joints()
    assert rest[:, 1].min() == pytest.approx(0.0)
    assert 1.35 < rest[sk.JOINT_INDEX["head"], 1] < 1.6  # head joint, below the top of the skull
    assert 0.85 < rest[0, 1] < 1.0
    np.testing.assert_allclose(sk.facing_direction(rest), [0, 0, 1], atol=1e-9)
    assert rest[sk.JOINT_INDEX["left_hip"], 0] > 0  # SMPL: the body's left is +X


def test_mirror_twice_is_identity_and_swaps_sides(random_pose) -> None:
    joints = sk.forward_kinematics(*random_pose, sk.REST_OFFSETS)
    assert np.array_equal(sk.mirror_joints(sk.mirror_joints(joints)), joints)
    m = sk.mirror_joints(joints)
    np.testing.assert_array_equal(m[:, 1, 0], -joints[:, 2, 0])
    rest = sk.rest_joints()
    np.testing.assert_allclose(sk.mirror_joints(rest), rest, atol=1e-12)  # the default body is symmetric


def test_forward_kinematics_numpy_and_torch_agree(random_pose) -> None:
    rot, root = random_pose
    a = sk.forward_kinematics(rot, root, sk.REST_OFFSETS)
    b = sk.forward_kinematics(torch.tensor(rot), torch.tensor(root), torch.tensor(sk.REST_OFFSETS))
    np.testing.assert_allclose(b.numpy(), a, atol=1e-12)
    batched = sk.forward_kinematics(rot[None].repeat(3, 0), root[None].repeat(3, 0), sk.REST_OFFSETS)
    assert batched.shape == (3, 40, 22, 3) and np.allclose(batched[1], a)
    np.testing.assert_allclose(sk.bone_lengths(a)[:, 1:].std(0), 0, atol=1e-12)


def test_inverse_kinematics_reproduces_the_joints(random_pose) -> None:
    joints = sk.forward_kinematics(*random_pose, sk.REST_OFFSETS)
    offsets = sk.offsets_from_joints(joints)
    np.testing.assert_allclose(offsets, sk.REST_OFFSETS, atol=1e-9)
    local, root = sk.inverse_kinematics(joints, offsets)
    np.testing.assert_allclose(sk.forward_kinematics(local, root, offsets), joints, atol=1e-9)
    np.testing.assert_allclose(local @ np.swapaxes(local, -1, -2), np.broadcast_to(np.eye(3), local.shape),
                               atol=1e-9)  # fmt: skip
