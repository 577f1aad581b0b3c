from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import MotionFormatError, ShapeError
from physmotion.motion import Motion, write_atomic
from physmotion.skeleton import REST_OFFSETS, rest_joints


def _standing(frames: int = 10) -> np.ndarray:
    return np.repeat(rest_joints()[None], frames, 0)


def test_save_load_round_trip(tmp_path: Path) -> None:
    m = Motion(_standing(), fps=20, texts=["a person stands", "stands still"], licence_tag="NC", source="x")
    m = m.with_rotations()
    m.save(tmp_path / "m.npz")
    back = Motion.load(tmp_path / "m.npz")
    np.testing.assert_array_equal(back.joints, m.joints)
    np.testing.assert_array_equal(back.rotations, m.rotations)
    assert (back.texts, back.licence_tag, back.fps, back.source) == (m.texts, "NC", 20, "x")
    assert back.humanoid is None


def test_the_simulated_body_travels_with_the_motion(tmp_path: Path) -> None:
    body = REST_OFFSETS * 1.1  # a taller body
    Motion(_standing(), humanoid=body).save(tmp_path / "p.npz")
    np.testing.assert_array_equal(Motion.load(tmp_path / "p.npz").humanoid, body)
    with pytest.raises(ShapeError, match="humanoid"):
        Motion(_standing(), humanoid=np.zeros((21, 3)))
    with pytest.raises(ShapeError, match="humanoid"):
        Motion(_standing(), humanoid=np.full((22, 3), np.nan))


def test_the_residual_travels_with_the_motion(tmp_path: Path) -> None:
    """P's root residual per frame (force x W, torque x W m) is saved and read back; a wrong shape or a
    NaN is refused."""
    residual = np.stack([np.linspace(0, 0.3, 10), np.linspace(0, 0.1, 10)], axis=-1)
    Motion(_standing(), residual=residual, resets=2).save(tmp_path / "p.npz")
    back = Motion.load(tmp_path / "p.npz")
    np.testing.assert_allclose(back.residual, residual.astype(np.float32))
    assert back.resets == 2
    assert Motion(_standing()).residual is None
    with pytest.raises(ShapeError, match="residual"):
        Motion(_standing(), residual=np.zeros((9, 2)))
    with pytest.raises(ShapeError, match="residual"):
        Motion(_standing(), residual=np.full((10, 2), np.nan))


def test_the_cap_and_torque_limit_flags_travel_with_the_motion(tmp_path: Path) -> None:
    """The force cap of the P that made a motion and its frames over the torque limit are saved and read
    back exactly; a cap that is not a number >= 0 or flags of the wrong shape or type are refused."""
    over = np.arange(10) % 3 == 0
    Motion(_standing(), residual=np.zeros((10, 2)), residual_cap=0.3, over_limit=over).save(tmp_path / "p.npz")
    back = Motion.load(tmp_path / "p.npz")
    assert back.residual_cap == 0.3 and np.array_equal(back.over_limit, over)
    plain = tmp_path / "plain.npz"
    Motion(_standing()).save(plain)
    assert Motion.load(plain).residual_cap is None and Motion.load(plain).over_limit is None
    for bad in (-0.1, float("nan")):
        with pytest.raises(ShapeError, match="residual_cap"):
            Motion(_standing(), residual_cap=bad)
    for bad in (over[:9], over.astype(np.float32)):
        with pytest.raises(ShapeError, match="over_limit"):
            Motion(_standing(), over_limit=bad)


@pytest.mark.parametrize(
    "joints, message",
    [(np.zeros((5, 21, 3)), "shape"), (np.zeros((0, 22, 3)), "zero frames"),
     (np.full((3, 22, 3), np.nan), "NaN")],
)  # fmt: skip
def test_bad_joints_are_refused(joints: np.ndarray, message: str) -> None:
    with pytest.raises(ShapeError, match=message):
        Motion(joints)


def test_load_errors_are_one_line(tmp_path: Path) -> None:
    (tmp_path / "junk.npz").write_bytes(b"not a zip at all")
    for path in (tmp_path / "missing.npz", tmp_path / "junk.npz"):
        with pytest.raises(MotionFormatError) as err:
            Motion.load(path)
        assert "\n" not in str(err.value)


def test_write_atomic_leaves_nothing_on_failure(tmp_path: Path) -> None:
    def fail(f: object) -> None:
        f.write(b"half")  # type: ignore[attr-defined]
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_atomic(tmp_path / "out.bin", fail)
    assert list(tmp_path.iterdir()) == []


def test_a_joined_licence_tag_keeps_every_restriction() -> None:
    from physmotion.motion import joined_licence_tag

    assert joined_licence_tag(["NC", "open"]) == "NC"  # Bandai (NC) and CMU (open): the mocap collection
    assert joined_licence_tag(["open", "SA", "NC"]) == "NC,SA"  # with HDM05 (CC BY-SA): both travel
    assert joined_licence_tag(["NC,SA", "SA"]) == "NC,SA" and joined_licence_tag(["open", "unknown"]) == "open"


def test_the_help_in_full_and_the_reset_frames_travel_with_the_motion(tmp_path: Path) -> None:
    """P's per-frame peaks, frames held at a cap, frames not simulated and whether the search made it are
    saved and read back; a wrong shape or dtype is refused, naming the field."""
    peak = np.stack([np.linspace(0, 0.4, 10), np.linspace(0, 0.9, 10)], axis=-1)
    at_cap, reset = np.arange(10) % 3 == 0, np.arange(10) >= 7
    Motion(_standing(), residual=peak / 2, residual_peak=peak, residual_at_cap=at_cap, reset_frames=reset,
           resets=1).save(tmp_path / "p.npz")  # fmt: skip
    back = Motion.load(tmp_path / "p.npz")
    assert back.searched is None  # not given: not recorded
    Motion(_standing(), residual=np.zeros((10, 2)), resets=0, searched=True).save(tmp_path / "s.npz")
    assert Motion.load(tmp_path / "s.npz").searched is True
    assert back.recovered is None  # not given: not recorded
    Motion(_standing(), residual=np.zeros((10, 2)), resets=0, recovered=2).save(tmp_path / "r.npz")
    assert Motion.load(tmp_path / "r.npz").recovered == 2
    np.testing.assert_array_equal(back.residual_peak, peak.astype(np.float32))
    np.testing.assert_array_equal(back.residual_at_cap, at_cap)
    np.testing.assert_array_equal(back.reset_frames, reset)
    # a file written before these fields reads them as None
    Motion(_standing(), residual=peak / 2).save(tmp_path / "old.npz")
    assert Motion.load(tmp_path / "old.npz").reset_frames is None
    with pytest.raises(ShapeError, match="reset_frames"):
        Motion(_standing(), reset_frames=np.zeros(9, dtype=bool))
    with pytest.raises(ShapeError, match="residual_at_cap"):
        Motion(_standing(), residual_at_cap=np.zeros(10))
    with pytest.raises(ShapeError, match="residual_peak"):
        Motion(_standing(), residual_peak=np.full((10, 2), np.nan))
