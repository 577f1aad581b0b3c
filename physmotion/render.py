"""Previews: an animated GIF of the skeleton over a floor grid, with the caption as the title.

Drawn with Pillow (already needed for images; matplotlib would add a heavy dependency and is slower
frame by frame). A fixed perspective camera looks at the motion's centre from the front-right and above.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from physmotion.errors import ShapeError
from physmotion.motion import write_atomic
from physmotion.skeleton import KINEMATIC_CHAINS, NUM_JOINTS

_SIZE = 320
_DISTANCE = 4.0  # m from the camera to the point it looks at
_GRID = 0.5  # m between floor lines
_CHAIN_COLOURS = [(200, 60, 60), (60, 90, 200), (60, 160, 80), (230, 140, 30), (150, 70, 170)]


def _camera(target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(eye, rotation world->camera (3, 3)) of a camera 4 m from ``target``, front-right and above."""
    view = np.array([0.9, 0.5, 1.3]) / np.linalg.norm([0.9, 0.5, 1.3])
    eye = target + _DISTANCE * view
    fwd = -view
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    return eye, np.stack([right, np.cross(right, fwd), fwd])


def _to_pixels(points: np.ndarray, eye: np.ndarray, rot: np.ndarray) -> np.ndarray:
    cam = (points - eye) @ rot.T
    focal = _SIZE * 1.2
    z = np.maximum(cam[..., 2], 1e-3)
    return np.stack([_SIZE / 2 + focal * cam[..., 0] / z, _SIZE / 2 + 20 - focal * cam[..., 1] / z], axis=-1)


def _floor_lines(target: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """World-fixed floor lines (y = 0) within 3 m of the target, so that travel shows against them."""
    cx, cz = np.round(target[[0, 2]] / _GRID) * _GRID
    ticks = np.arange(-6, 7) * _GRID
    lo, hi = ticks[0], ticks[-1]
    return [(np.array([cx + d, 0, cz + lo]), np.array([cx + d, 0, cz + hi])) for d in ticks] + [
        (np.array([cx + lo, 0, cz + d]), np.array([cx + hi, 0, cz + d])) for d in ticks]


def render_frames(joints: np.ndarray, title: str = "") -> list:
    """PIL images, one per frame. joints: (T, 22, 3) float, metres, Y up, floor at y = 0."""
    from PIL import Image, ImageDraw

    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3) or not np.all(np.isfinite(joints)):
        raise ShapeError(f"preview needs finite joints (T, 22, 3), got {joints.shape}")
    # The camera follows the root, smoothed over about a second so that it does not shake.
    root = joints[:, 0].copy()
    kernel = np.ones(21) / 21
    for axis in (0, 2):
        padded = np.pad(root[:, axis], 10, mode="edge")
        root[:, axis] = np.convolve(padded, kernel, mode="valid")
    caption = "\n".join(textwrap.wrap(title, 44)[:2])
    frames = []
    for pose, centre in zip(joints, root):
        target = np.array([centre[0], 0.8, centre[2]])
        eye, rot = _camera(target)
        img = Image.new("RGB", (_SIZE, _SIZE), (248, 248, 244))
        draw = ImageDraw.Draw(img)
        for a, b in _floor_lines(target):
            draw.line([tuple(_to_pixels(a, eye, rot)), tuple(_to_pixels(b, eye, rot))], fill=(205, 205, 200))
        shadow = _to_pixels(pose * np.array([1.0, 0.0, 1.0]), eye, rot)
        px = _to_pixels(pose, eye, rot)
        for chain, colour in zip(KINEMATIC_CHAINS, _CHAIN_COLOURS):
            draw.line([tuple(shadow[j]) for j in chain], fill=(215, 215, 210), width=3)
            draw.line([tuple(px[j]) for j in chain], fill=colour, width=4, joint="curve")
        if caption:
            draw.multiline_text((8, 6), caption, fill=(30, 30, 30))
        frames.append(img)
    return frames


def save_gif(path: str | Path, joints: np.ndarray, fps: float, title: str = "") -> None:
    """Write an animated GIF preview of a motion atomically. joints: (T, 22, 3) metres, Y up."""
    frames = render_frames(joints, title)
    duration = round(1000 / fps)
    write_atomic(path, lambda f: frames[0].save(f, format="GIF", save_all=True, append_images=frames[1:],
                                                 duration=duration, loop=0))  # fmt: skip
