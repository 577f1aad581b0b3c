"""``physmotion view``: one self-contained HTML page that plays motions in 3-D (WebGL, three.js).

The page inlines everything it needs, so it opens from disk with no network: the vendored three.js
bundle (``vendor/``, see its README), the viewer script (``viewer.js``) and the motions as JSON (joints
in integer millimetres per frame, foot contacts as a 4-bit mask per frame, and each motion's skinned body
as the .glb that ``export`` writes, base64, parsed by three.js' GLTFLoader in the page). Motions are
loaded, labelled and brought to one rate and length exactly as ``physmotion render`` does
(:mod:`physmotion.render`), and placed side by side along X so that they do not overlap.

Page URL parameters (also for tests): ``?t=SECONDS`` shows that time, paused; ``follow=0`` keeps the
camera where it starts instead of following the motions; ``body=0`` hides the skinned bodies and
``sticks=1`` shows the stick figures (by default the bodies are shown and, of the sticks, only the
foot-contact markers; the page's "body" and "sticks" boxes toggle them). ``window.physmotionViewer``
exposes ``setTime(s)``, ``play()``, ``pause()`` and ``state()``.
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.motion import Motion, write_atomic
from physmotion.render import Track, load_motion, make_tracks, short_labels
from physmotion.skeleton import FOOT_JOINTS, JOINT_NAMES, PARENTS

_GAP = 1.0  # m of free floor between neighbouring motions


@dataclass(frozen=True)
class ViewSummary:
    """What :func:`view_files` wrote: frames at ``fps``, and the page's size in bytes."""

    frames: int
    fps: float
    bytes: int


def _asset(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def lateral_offsets(tracks: Sequence[Track]) -> np.ndarray:
    """(M,) X shift of each motion so that their X ranges, ``_GAP`` apart, sit side by side centred on 0."""
    lo = np.array([t.joints[..., 0].min() for t in tracks])
    hi = np.array([t.joints[..., 0].max() for t in tracks])
    width = hi - lo
    starts = np.concatenate([[0.0], np.cumsum(width + _GAP)[:-1]])
    total = starts[-1] + width[-1]
    return starts - lo - total / 2


def scene_data(tracks: Sequence[Track], fps: float) -> dict:
    """The page's JSON: skeleton, rate, and per motion its label, colour, X offset, joints (N * 22 * 3
    integers, mm, frame-major), contacts (N integers, bit i = FOOT_JOINTS[i] touching the floor) and
    not_simulated (the indices of the frames P did not simulate: ``Track.not_simulated``) and glb (base64 of
    the motion's .glb at the common rate, without the X offset: :func:`physmotion.io.gltf.glb_bytes`)."""
    from physmotion.io.gltf import glb_bytes

    offsets = lateral_offsets(tracks)
    motions = []
    for track, dx in zip(tracks, offsets):
        mm = np.rint((track.joints + np.array([dx, 0.0, 0.0])) * 1000).astype(np.int64)
        bits = (track.contacts.astype(np.int64) << np.arange(len(FOOT_JOINTS))).sum(axis=1)
        motions.append({
            "label": track.label,
            "colour": "#{:02x}{:02x}{:02x}".format(*track.colour),
            "offset": round(float(dx), 3),
            "joints": mm.reshape(-1).tolist(),
            "contacts": bits.tolist(),
            "not_simulated": [] if track.not_simulated is None else np.flatnonzero(track.not_simulated).tolist(),
            "glb": base64.b64encode(glb_bytes(Motion(joints=track.joints, fps=fps))).decode("ascii"),
        })  # fmt: skip
    return {
        "fps": fps,
        "frames": len(tracks[0].joints),
        "parents": list(PARENTS),
        "joint_names": list(JOINT_NAMES),
        "foot_joints": list(FOOT_JOINTS),
        "motions": motions,
    }


def view_html(tracks: Sequence[Track], fps: float, title: str = "physmotion view") -> str:
    """The page's HTML text: three.js, the viewer script and the data inlined."""
    data = json.dumps(scene_data(tracks, fps), separators=(",", ":"))
    # "</" would end the inline <script> early; JSON allows the escaped "<\/" form.
    data = data.replace("</", "<\\/")
    parts = {"TITLE": html.escape(title), "THREE": _asset("vendor/three-bundle.min.js"),
             "VIEWER": _asset("viewer.js"), "DATA": data}  # fmt: skip
    # One pass, so that a marker-like text inside an inserted part is left alone.
    return re.sub(r"\{\{([A-Z]+)\}\}", lambda m: parts[m.group(1)], _asset("viewer.html"))


def view_files(paths: Sequence[str | Path], out: str | Path, rig: str | None = None,
               fps: float | None = None, mapping: str | Path | None = None) -> ViewSummary:  # fmt: skip
    """Write the viewer page of motion files (.npz, or .bvh imported with ``rig`` / ``fps`` / ``mapping``) to ``out``
    (.html) atomically; nothing is written on a failure."""
    out = Path(out)
    if out.suffix.lower() not in (".html", ".htm"):
        raise PhysmotionError(f"{out}: output must be an .html file")
    motions = [load_motion(p, rig=rig, fps=fps, mapping=mapping) for p in paths]
    labels = short_labels(paths)
    tracks, rate = make_tracks(motions, labels)
    text = view_html(tracks, rate, title=" | ".join(labels))
    payload = text.encode("utf-8")
    write_atomic(out, lambda f: f.write(payload))
    return ViewSummary(len(tracks[0].joints), rate, len(payload))
