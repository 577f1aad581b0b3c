"""Rig tables (data), the generic rig tree, Euler conversion, units."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmotion.errors import PhysmotionError
from physmotion.io.amc import read_amc
from physmotion.io.bvh import read_bvh
from physmotion.io.rigs import RIGS, RigMotion, RigTable, euler_to_matrix, parse_units, table_from_mapping
from physmotion.skeleton import JOINT_NAMES


@pytest.mark.parametrize("order", ["XYZ", "ZXY", "ZYX", "YZX", "YXZ", "XZY", "ZX", "Y"])
def test_euler_to_matrix_matches_scipy_intrinsic(order: str) -> None:
    angles = np.random.default_rng(0).uniform(-180, 180, (7, 5, len(order)))
    expected = Rotation.from_euler(order, angles.reshape(-1, len(order)), degrees=True).as_matrix()
    assert np.allclose(euler_to_matrix(angles, order).reshape(-1, 3, 3), expected, atol=1e-12)


def test_tables_cover_the_22_joints_with_valid_blends() -> None:
    for table in RIGS.values():
        assert set(table.joints) == set(JOINT_NAMES)
        w = table.weights(tuple(sorted(table.nodes())))
        assert np.allclose(w.sum(axis=1), 1.0) and (w >= 0).all()


def test_every_convention_fits_a_real_file(clip) -> None:
    files = {
        "bandai": clip("bandai1_dataset-1_bow_active_001"),
        "cmu_bvh_cgspeed_max": clip("cmubvh_131_01"),
        "cmu_bvh_cgspeed_max_scaled_m": clip("cmubvhm_131_01"),
        "cmu_iclone_cc_base": clip("cmuiclone_02_01"),
        "cmu_asf": clip("cmu_02_01"),
    }
    for name, info in files.items():
        rig = read_bvh(info.path) if info.format == "bvh" else read_amc(info.path, info.skeleton)
        assert RIGS[name].nodes() <= set(rig.names), name


def test_table_validation_and_user_mapping() -> None:
    mapping = {name: f"rig_{name}" for name in JOINT_NAMES}
    table = table_from_mapping(mapping, units=0.01)
    assert table.units == 0.01 and table.nodes() == set(mapping.values())
    with pytest.raises(PhysmotionError, match="exactly the 22"):
        table_from_mapping({k: v for k, v in mapping.items() if k != "head"})
    with pytest.raises(PhysmotionError, match="sum to 1"):
        RigTable("bad", {**mapping, "spine2": (("a", 0.5), ("b", 0.6))}, units=1.0)
    with pytest.raises(PhysmotionError, match="has no joint"):
        table.weights(("rig_pelvis",))


def test_parse_units() -> None:
    assert parse_units("cm") == 0.01 and parse_units("m") == 1.0 and parse_units(0.5) == 0.5
    cmu = 0.0254 / 0.45
    assert parse_units("CMU ASF unit (1/0.45 inch = 5.644 cm)") == pytest.approx(cmu)
    assert parse_units("ASF length 0.45 (1 unit = 1/0.45 inch), angles deg") == pytest.approx(cmu)
    with pytest.raises(PhysmotionError):
        parse_units("furlongs")


def test_forward_kinematics_and_subset() -> None:
    rot = np.broadcast_to(np.eye(3), (2, 4, 3, 3)).copy()
    rot[1, 1] = Rotation.from_euler("z", 90, degrees=True).as_matrix()  # node b turns its children
    trans = np.broadcast_to(np.array([[1.0, 2, 3], [0, 1, 0], [0, 1, 0], [1, 0, 0]]), (2, 4, 3)).copy()
    rig = RigMotion(("a", "b", "c", "d"), np.array([-1, 0, 1, 0]), rot, trans)
    pos = rig.forward_kinematics()
    assert np.allclose(pos[0], [[1, 2, 3], [1, 3, 3], [1, 4, 3], [2, 2, 3]])
    assert np.allclose(pos[1, 2], [0, 3, 3])  # c = b + Rz(90) (0, 1, 0)
    sub = rig.subset({"c"})
    assert sub.names == ("a", "b", "c") and list(sub.parents) == [-1, 0, 1]
    assert np.allclose(sub.forward_kinematics(), pos[:, :3])
