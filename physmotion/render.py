"""Pictures of motions: GIF / MP4 / PNG of one or more skeletons over a floor grid.

Drawn with Pillow (already needed for images; matplotlib would add a heavy dependency and is slower
frame by frame). A fixed perspective camera looks at a motion's centre from the front-right and above and
follows its root. Every picture carries a frame / time counter, a 0.5 m floor grid with a 1 m scale bar,
and the foot joints in contact with the floor (:func:`physmotion.metrics.physical.foot_contacts`, the
rule the Skate metric counts) as magenta dots. Several motions go side by side (one panel each) or
overlaid in one panel, one colour per motion, with a legend.

The previews ``generate``, ``project``, ``refine`` and ``import`` write beside their outputs
(:func:`save_preview`, :func:`save_with_preview`) and ``physmotion render`` (:func:`render_files`) share the
drawing code; the viewer (:mod:`physmotion.viewer`) shares the loading, labels and time alignment.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Literal

import numpy as np

from physmotion.errors import MotionFormatError, PhysmotionError, ShapeError
from physmotion.motion import Motion, check_joints, write_atomic
from physmotion.skeleton import FOOT_JOINTS, KINEMATIC_CHAINS

Layout = Literal["side", "overlay"]
LAYOUTS: tuple[str, ...] = ("side", "overlay")
OUTPUT_SUFFIXES: tuple[str, ...] = (".gif", ".mp4", ".png")
MOTION_SUFFIXES: tuple[str, ...] = (".npz", ".bvh")

PANEL_SIZE = 480  # px per panel of `physmotion render`
PREVIEW_SIZE = 320  # px of generate's GIF previews
_DISTANCE = 3.5  # m from the camera to the point it looks at
_GRID = 0.5  # m between floor lines
_BACKGROUND = (248, 248, 244)
_GRID_COLOUR = (205, 205, 200)
_SHADOW = (215, 215, 210)
_INK = (30, 30, 30)
CONTACT_COLOUR = (230, 0, 200)
"""Foot joints in contact with the floor are drawn as dots of this colour (used by nothing else)."""
RESET_COLOUR = (200, 0, 0)
NOT_SIMULATED = "reset: not simulated"
"""The words, in RESET_COLOUR, on a frame P did not simulate (``Motion.reset_frames``)."""
_CHAIN_COLOURS = [(200, 60, 60), (60, 90, 200), (60, 160, 80), (230, 140, 30), (150, 70, 170)]
MOTION_COLOURS: tuple[tuple[int, int, int], ...] = (
    (200, 60, 60), (60, 90, 200), (40, 150, 70), (230, 140, 30), (130, 70, 170), (20, 150, 160),
)  # fmt: skip
"""One colour per motion (overlay layout, viewer legend), in the order given; repeats after six."""


@dataclass(frozen=True)
class Track:
    """One motion ready to draw at the common rate.

    joints: (N, 22, 3) float64 metres, Y up; contacts: (N, 4) bool in FOOT_JOINTS order; label: its name
    in legends; colour: its RGB colour in the overlay layout and the viewer; not_simulated: (N,) bool, the
    frames P did not simulate (``Motion.reset_frames``: a reset and the cross-fade before it), or None.
    """

    label: str
    joints: np.ndarray
    contacts: np.ndarray
    colour: tuple[int, int, int]
    not_simulated: np.ndarray | None = None


# ------------------------------------------------------------------------------------------------
# Loading and aligning


def load_motion(path: str | Path, *, rig: str | None = None, fps: float | None = None,
                mapping: str | Path | None = None) -> Motion:  # fmt: skip
    """A motion file as a Motion: an .npz of :meth:`Motion.save`, or a .bvh imported on the fly
    (:func:`physmotion.io.importer.import_clip`; ``rig``, ``fps`` and ``mapping`` (a mapping JSON file) as
    for ``physmotion import``, the rig guessed when None)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MOTION_SUFFIXES:
        raise MotionFormatError(f"{path}: not a motion file (expected .npz or .bvh)")
    if not path.is_file():
        raise MotionFormatError(f"{path}: no such file")
    if suffix == ".bvh":
        from physmotion.io.importer import import_clip

        return import_clip(path, rig=rig, fps=fps, mapping=mapping)
    return Motion.load(path)  # an .npz carries its own rate; rig, fps and mapping are the BVH importer's


def short_labels(paths: Sequence[str | Path]) -> list[str]:
    """The shortest path suffix that tells each file apart: ``a/walk.npz``, ``b/walk.npz``, ``run.npz``.

    Each label starts as the file name and takes one more parent folder while another file shares it.
    The same file given twice keeps its full path in both labels.
    """
    parts = [Path(p).absolute().parts for p in paths]
    depth = [1] * len(parts)
    while True:
        labels = ["/".join(p[-d:]) for p, d in zip(parts, depth)]
        clash = [i for i, lab in enumerate(labels) if labels.count(lab) > 1 and depth[i] < len(parts[i])]
        if not clash:
            return labels
        for i in clash:
            depth[i] += 1


def motion_contacts(motion: Motion) -> np.ndarray:
    """(T, 4) bool: the foot joints (FOOT_JOINTS order) touching the floor, on the humanoid's surface
    posed on the joints (P's body where the file has it, else estimated), as ``physmotion metrics``
    measures by default."""
    from physmotion.metrics.physical import foot_contacts
    from physmotion.physics.surface import HumanoidSurface

    return foot_contacts(motion.joints, HumanoidSurface(motion.humanoid))


def common_rate(motions: Sequence[Motion]) -> tuple[float, int]:
    """(fps, frames) every motion is shown at: the highest rate given, so no motion loses frames, and as
    many frames as the longest motion lasts at it."""
    if not motions:
        raise PhysmotionError("no motion given")
    fps = max(m.fps for m in motions)
    last = max((m.num_frames - 1) / m.fps for m in motions)  # time of the last frame of the longest
    return fps, int(np.floor(last * fps + 1e-6)) + 1


def align(motion: Motion, contacts: np.ndarray, fps: float, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """A motion at ``fps`` over ``frames`` frames: joints (frames, 22, 3) linearly interpolated in time,
    contacts (frames, ...) (or any per-frame flags) from the nearest source frame; past its end a motion
    holds its last frame."""
    src = np.asarray(motion.joints, dtype=np.float64)
    pos = np.minimum(np.arange(frames) * motion.fps / fps, motion.num_frames - 1)  # source frame per frame
    lo = np.floor(pos).astype(int)
    hi = np.minimum(lo + 1, motion.num_frames - 1)
    w = (pos - lo)[:, None, None]
    joints = (1 - w) * src[lo] + w * src[hi]
    return joints, np.asarray(contacts, dtype=bool)[np.rint(pos).astype(int)]


def make_tracks(motions: Sequence[Motion], labels: Sequence[str]) -> tuple[list[Track], float]:
    """Motions with their contacts, resampled to :func:`common_rate`; returns (tracks, fps)."""
    fps, frames = common_rate(motions)
    tracks = []
    for k, (motion, label) in enumerate(zip(motions, labels)):
        joints, contacts = align(motion, motion_contacts(motion), fps, frames)
        marked = None if motion.reset_frames is None else align(motion, motion.reset_frames, fps, frames)[1]
        tracks.append(Track(label, joints, contacts, MOTION_COLOURS[k % len(MOTION_COLOURS)], marked))
    return tracks, fps


# ------------------------------------------------------------------------------------------------
# Drawing


class _Camera:
    """A camera ``_DISTANCE`` from ``target``, front-right and above, drawing into a square panel of
    ``size`` px."""

    def __init__(self, target: np.ndarray, size: int) -> None:
        view = np.array([0.9, 0.5, 1.3]) / np.linalg.norm([0.9, 0.5, 1.3])
        self.eye = target + _DISTANCE * view
        fwd = -view
        right = np.cross(fwd, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        self.rot = np.stack([right, np.cross(right, fwd), fwd])
        self.size = size

    def pixels(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) world points -> (..., 2) pixel coordinates."""
        cam = (points - self.eye) @ self.rot.T
        focal = self.size * 1.2
        z = np.maximum(cam[..., 2], 1e-3)
        half = self.size / 2
        return np.stack([half + focal * cam[..., 0] / z,
                         half + self.size / 16 - focal * cam[..., 1] / z], axis=-1)  # fmt: skip

    def segment(self, a: np.ndarray, b: np.ndarray, near: float = 1.5) -> list[tuple[float, float]]:
        """Pixel end points of the world segment a-b (3,) cut at ``near`` m in front of the camera, or
        [] when it lies wholly nearer: projecting points behind the camera would throw them across the
        picture."""
        za, zb = (np.stack([a, b]) - self.eye) @ self.rot[2]
        if za < near and zb < near:
            return []
        if za < near or zb < near:
            cut = a + (b - a) * (near - za) / (zb - za)
            a, b = (cut, b) if za < near else (a, cut)
        return [tuple(self.pixels(a)), tuple(self.pixels(b))]


def _follow(root: np.ndarray) -> np.ndarray:
    """(N, 3) camera targets: the root smoothed over 21 frames so the camera does not shake, at 0.8 m."""
    out = np.empty_like(root)
    kernel = np.ones(21) / 21
    for axis in (0, 2):
        out[:, axis] = np.convolve(np.pad(root[:, axis], 10, mode="edge"), kernel, mode="valid")
    out[:, 1] = 0.8
    return out


def _font(size: int):
    from PIL import ImageFont

    return ImageFont.load_default(size=max(10, size))


def _draw_floor(draw, cam: _Camera, target: np.ndarray, font) -> None:
    """World-fixed floor lines (y = 0) within 3 m of the target, so that travel shows against them, and
    a 1 m bar on the grid line half a metre in front, left of the figure, as the scale."""
    cx, cz = np.round(target[[0, 2]] / _GRID) * _GRID
    ticks = np.arange(-6, 7) * _GRID
    lo, hi = ticks[0], ticks[-1]
    for d in ticks:
        for a, b in (
            ([cx + d, 0, cz + lo], [cx + d, 0, cz + hi]),
            ([cx + lo, 0, cz + d], [cx + hi, 0, cz + d]),
        ):
            ends = cam.segment(np.array(a, dtype=float), np.array(b, dtype=float))
            if ends:
                draw.line(ends, fill=_GRID_COLOUR)
    start, end = cam.pixels(np.array([[cx - 1.5, 0, cz + 0.5], [cx - 0.5, 0, cz + 0.5]]))
    width = max(3, cam.size // 120)
    draw.line([tuple(start), tuple(end)], fill=_INK, width=width)
    for tip in (start, end):
        draw.line(
            [(tip[0], tip[1] - 2 * width), (tip[0], tip[1] + 2 * width)], fill=_INK, width=max(1, width // 2)
        )
    draw.text(((start[0] + end[0]) / 2, (start[1] + end[1]) / 2 + 3 * width), "1 m", fill=_INK, font=font,
              anchor="mt")  # fmt: skip


def _draw_skeleton(draw, cam: _Camera, pose: np.ndarray, contacts: np.ndarray,
                   colour: tuple[int, int, int] | None) -> None:  # fmt: skip
    """One pose (22, 3): its floor shadow, bones (per-chain colours, or ``colour`` for all), and a
    CONTACT_COLOUR dot on each foot joint whose ``contacts`` (4,) entry is set."""
    width = max(3, cam.size // 80)
    shadow = cam.pixels(pose * np.array([1.0, 0.0, 1.0]))
    px = cam.pixels(pose)
    for chain, chain_colour in zip(KINEMATIC_CHAINS, _CHAIN_COLOURS):
        draw.line([tuple(shadow[j]) for j in chain], fill=_SHADOW, width=width - 1)
        draw.line([tuple(px[j]) for j in chain], fill=colour or chain_colour, width=width, joint="curve")
    r = width + 1
    for j, touching in zip(FOOT_JOINTS, contacts):
        if touching:
            x, y = px[j]
            draw.ellipse([x - r, y - r, x + r, y + r], fill=CONTACT_COLOUR)


def draw_frame(tracks: Sequence[Track], k: int, targets: Sequence[np.ndarray], fps: float,
               layout: Layout = "side", size: int = PANEL_SIZE, title: str = "", labels: bool = True):  # fmt: skip
    """Frame ``k`` of the tracks as a PIL image: (size * panels) x size px, panels = len(tracks) side by
    side or 1 overlaid. targets: per panel, (N, 3) camera targets. labels: write each motion's label
    (side) or a legend (overlay)."""
    from PIL import Image, ImageDraw

    panels = len(tracks) if layout == "side" else 1
    img = Image.new("RGB", (size * panels, size), _BACKGROUND)
    draw = ImageDraw.Draw(img)
    small, big = _font(size // 30), _font(size // 24)
    groups = [[t] for t in tracks] if layout == "side" else [list(tracks)]
    for p, group in enumerate(groups):
        panel = Image.new("RGB", (size, size), _BACKGROUND)  # its own image: lines stop at its edges
        panel_draw = ImageDraw.Draw(panel)
        cam = _Camera(targets[p][k], size)
        _draw_floor(panel_draw, cam, targets[p][k], small)
        for track in group:
            colour = None if layout == "side" else track.colour
            _draw_skeleton(panel_draw, cam, track.joints[k], track.contacts[k], colour)
        resets = [t for t in group if t.not_simulated is not None and t.not_simulated[k]]
        for i, track in enumerate(resets):  # P put the body back here: say so where it shows
            words = NOT_SIMULATED if layout == "side" else f"{track.label}: {NOT_SIMULATED}"
            panel_draw.text((size - 8, 8 + i * (small.size + 4)), words, fill=RESET_COLOUR, font=small, anchor="ra")
        img.paste(panel, (p * size, 0))
        if p > 0:
            draw.line([(p * size, 0), (p * size, size)], fill=_GRID_COLOUR, width=2)
    line = big.size + 4
    y = 6
    if title:
        caption = "\n".join(textwrap.wrap(title, max(20, size // 8))[:2])
        draw.multiline_text((8, y), caption, fill=_INK, font=big)
        y += 2 * line
    if labels and layout == "side":
        for p, track in enumerate(tracks):
            draw.text((p * size + 8, y), track.label, fill=_INK, font=big)
    elif labels:
        for i, track in enumerate(tracks):
            top = y + i * line
            draw.rectangle([8, top + 2, 8 + big.size, top + 2 + big.size], fill=track.colour)
            draw.text((14 + big.size, top), track.label, fill=_INK, font=big)
    frames = len(tracks[0].joints)
    draw.text((8, size - 8), f"frame {k + 1}/{frames}   {k / fps:5.2f} s", fill=_INK, font=small, anchor="ld")
    right = size * panels - 8
    draw.text((right, size - 8), "foot contact", fill=_INK, font=small, anchor="rd")
    dot = right - small.getlength("foot contact") - small.size // 2 - 4
    r = small.size // 3
    draw.ellipse(
        [dot - r, size - 8 - small.size // 2 - r, dot + r, size - 8 - small.size // 2 + r],
        fill=CONTACT_COLOUR,
    )
    draw.text((dot - r - 16, size - 8), "grid 0.5 m", fill=_INK, font=small, anchor="rd")
    return img


def render_frames(tracks: Sequence[Track], fps: float, layout: Layout = "side", size: int = PANEL_SIZE,
                  title: str = "", frames: Sequence[int] | None = None, labels: bool = True) -> list:  # fmt: skip
    """PIL images of the given frame indices (default: all) of tracks that share a rate and length."""
    if layout not in LAYOUTS:
        raise PhysmotionError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    if not tracks:
        raise PhysmotionError("no motion given")
    for track in tracks:
        check_joints(track.joints, f"{track.label} joints")
    n = len(tracks[0].joints)
    if any(len(t.joints) != n or t.contacts.shape != (n, len(FOOT_JOINTS)) for t in tracks):
        raise ShapeError("tracks must share their frame count, with (N, 4) contacts")
    roots = [t.joints[:, 0] for t in tracks]
    targets = [_follow(r) for r in roots] if layout == "side" else [_follow(np.mean(roots, axis=0))]
    indices = range(n) if frames is None else frames
    return [draw_frame(tracks, k, targets, fps, layout, size, title, labels) for k in indices]


# ------------------------------------------------------------------------------------------------
# Writing


def _write_images(path: Path, images: list, fps: float) -> None:
    """Write images as .gif, .mp4 or (one image) .png at ``path``, atomically."""
    suffix = path.suffix.lower()
    if suffix == ".png":
        write_atomic(path, lambda f: images[0].save(f, format="PNG", optimize=True))
    elif suffix == ".gif":
        duration = round(1000 / fps)
        from PIL import Image

        palette = _gif_palette()
        frames = [image.quantize(palette=palette, dither=Image.Dither.NONE) for image in images]
        write_atomic(path, lambda f: frames[0].save(f, format="GIF", save_all=True, append_images=frames[1:],
                                                    duration=duration, loop=0))  # fmt: skip
    else:
        av = _require_av()

        def encode(f) -> None:
            with av.open(f, mode="w", format="mp4") as container:
                stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
                stream.width, stream.height = images[0].size
                stream.pix_fmt = "yuv420p"  # what every player decodes
                stream.options = {"crf": "20"}
                for image in images:
                    for packet in stream.encode(av.VideoFrame.from_image(image)):
                        container.mux(packet)
                for packet in stream.encode():
                    container.mux(packet)

        write_atomic(path, encode)


def _gif_palette():
    """A "P" image whose palette holds every colour the drawing uses, and the text's anti-aliased edges
    (ink and reset red blended into the background, 7 steps each): frames mapped onto it keep their
    colours exactly, and the encoder need not choose a palette per frame (docs/decisions/tools.md, "one
    GIF palette for every preview")."""
    from PIL import Image

    solid = [_BACKGROUND, _GRID_COLOUR, _SHADOW, _INK, CONTACT_COLOUR, RESET_COLOUR, *_CHAIN_COLOURS, *MOTION_COLOURS]
    back = np.array(_BACKGROUND, dtype=float)
    edges = [tuple(np.rint(back + (np.array(c) - back) * w).astype(int)) for c in (_INK, RESET_COLOUR)
             for w in np.linspace(0.125, 0.875, 7)]  # fmt: skip
    colours = list(dict.fromkeys(map(tuple, solid + edges)))
    palette = Image.new("P", (1, 1))
    palette.putpalette([int(v) for c in colours for v in c] + [0, 0, 0] * (256 - len(colours)))
    return palette


def _require_av():
    try:
        import av
    except ImportError:
        raise PhysmotionError("writing .mp4 needs PyAV: pip install 'physmotion[video]'") from None
    return av


PREVIEW_SUFFIX = ".gif"
PREVIEW_LABELS: tuple[str, str] = ("input", "output")
"""The panel labels of a command's two-motion preview (``project``, ``refine``): what it read, what it wrote."""


def preview_path(out: str | Path) -> Path:
    """Where the GIF preview of the motion file ``out`` goes: beside it, ``<stem>.gif``."""
    return Path(out).with_suffix(PREVIEW_SUFFIX)


def save_preview(path: str | Path, motions: Sequence[Motion], labels: Sequence[str] = (), title: str = "") -> None:
    """Write a command's animated GIF preview atomically: the motions side by side, 320 px a panel.

    Motions at different rates or lengths are shown at :func:`common_rate`; each carries its foot contacts
    and, where it has ``reset_frames``, the frames P did not simulate, marked as such. labels: one per
    motion over its panel (e.g. :data:`PREVIEW_LABELS`), or none for a bare single-motion preview."""
    if labels and len(labels) != len(motions):
        raise PhysmotionError(f"{len(labels)} labels for {len(motions)} motions")
    tracks, fps = make_tracks(motions, list(labels) or [""] * len(motions))
    images = render_frames(tracks, fps, "side", PREVIEW_SIZE, title, labels=bool(labels))
    _write_images(Path(path), images, fps)


def save_gif(path: str | Path, joints: np.ndarray, fps: float, title: str = "",
             not_simulated: np.ndarray | None = None) -> None:  # fmt: skip
    """Write generate's animated GIF preview of one motion atomically: 320 px, the caption as title.

    joints: (T, 22, 3) metres, Y up, floor at y = 0; not_simulated: (T,) bool frames to mark as such."""
    marked = None if not_simulated is None else np.asarray(not_simulated, dtype=bool)
    save_preview(path, [Motion(joints=joints, fps=fps, reset_frames=marked)], title=title)


def save_with_preview(motion: Motion, out: str | Path, preview: bool = True, before: Motion | None = None,
                      title: str = "") -> list[Path]:  # fmt: skip
    """Write ``motion`` to ``out`` (.npz or .bvh by its suffix) and then, with ``preview``, its GIF at
    :func:`preview_path` (``before`` given: ``before`` and ``motion`` side by side as input and output),
    each atomically. A failure of the preview removes the motion file just written: a command leaves
    both or neither. Without ``preview``, an old GIF there is removed (it showed another motion), as
    ``generate`` does. Returns the files written."""
    from physmotion.io.export import save_motion

    out = Path(out)
    save_motion(motion, out)
    if not preview:
        preview_path(out).unlink(missing_ok=True)
        return [out]
    try:
        if before is None:
            save_preview(preview_path(out), [motion], title=title)
        else:
            save_preview(preview_path(out), [before, motion], PREVIEW_LABELS, title)
    except BaseException:
        out.unlink(missing_ok=True)
        raise
    return [out, preview_path(out)]


@dataclass(frozen=True)
class RenderSummary:
    """What :func:`render_files` wrote: frames, their rate, the image size (width, height) in px."""

    frames: int
    fps: float
    width: int
    height: int


def render_files(paths: Sequence[str | Path], out: str | Path, layout: Layout = "side", size: int = PANEL_SIZE,
                 frame: int | None = None, rig: str | None = None, fps: float | None = None,
                 mapping: str | Path | None = None) -> RenderSummary:  # fmt: skip
    """Render motion files (.npz, or .bvh imported with ``rig`` / ``fps`` / ``mapping``) to ``out``: a .gif or .mp4 of
    every frame, or with ``frame`` (an index at the common rate) a .png still. Checks every argument
    before drawing, and writes nothing on a failure."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise PhysmotionError(f"{out}: output must be .gif, .mp4 or .png")
    if (suffix == ".png") != (frame is not None):
        raise PhysmotionError("a .png is one still: give --frame N with it (and only with it)")
    if layout not in LAYOUTS:
        raise PhysmotionError(f"--layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    if not 64 <= size <= 2048 or size % 2:
        raise PhysmotionError(f"--size must be an even number of pixels from 64 to 2048, got {size}")
    if suffix == ".mp4":
        _require_av()
    motions = [load_motion(p, rig=rig, fps=fps, mapping=mapping) for p in paths]
    tracks, rate = make_tracks(motions, short_labels(paths))
    n = len(tracks[0].joints)
    if frame is not None and not 0 <= frame < n:
        raise PhysmotionError(f"--frame must be in 0..{n - 1} (frames at {rate:g} fps), got {frame}")
    images = render_frames(tracks, rate, layout, size, frames=None if frame is None else [frame])
    _write_images(out, images, rate)
    return RenderSummary(len(images), rate, *images[0].size)
