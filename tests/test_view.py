"""`physmotion view` in a real browser: the page loads offline in headless Chromium with no console
message from the page, and shows the figures on the floor, moving with time."""

import base64
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from physmotion.motion import Motion
from tests.cli_runner import invoke

BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
# SwiftShader's notes about reading back its own frames (the screenshot), not messages of the page.
DRIVER_NOTE = "GL Driver Message (OpenGL, Performance"


def chromium(url: str, profile: Path, *action: str) -> tuple[str, list[str]]:
    """Run headless Chromium on ``url`` with one action (--dump-dom, --screenshot=...); returns (stdout,
    the console messages of the page)."""
    exe = shutil.which("chromium")
    if exe is None:
        pytest.fail("chromium is not installed: `make test` installs it (apt-get install chromium)")
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={profile}", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
             "--enable-logging=stderr", "--v=0", "--window-size=900,600", "--virtual-time-budget=4000"]  # fmt: skip
    res = subprocess.run(
        [exe, *flags, *action, url], capture_output=True, text=True, timeout=120, check=False
    )
    assert res.returncode == 0, res.stderr[-2000:]
    console = [line for line in res.stderr.splitlines() if ":CONSOLE" in line and DRIVER_NOTE not in line]
    return res.stdout, console


def _figure_centre(path: Path) -> tuple[np.ndarray, int]:
    """Centroid (x, y) of the coloured (figure) pixels of the 3-D view, and their count; the legend
    (top left) and the control bar (bottom) are left out."""
    pixels = np.asarray(Image.open(path).convert("RGB")).astype(int)[90:560]
    coloured = (pixels.max(axis=-1) - pixels.min(axis=-1)) > 60  # the floor, background and text are grey
    ys, xs = np.nonzero(coloured)
    return np.array([xs.mean(), ys.mean()]), int(coloured.sum())


@pytest.fixture(scope="module")
def walk_page(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The Bandai walk imported at its true 30 fps and `physmotion view`'s page of it: (walk.npz, view.html)."""
    folder = tmp_path_factory.mktemp("view")
    walk, page = folder / "walk.npz", folder / "view.html"
    res = invoke("import", mocap_dir / BANDAI_WALK, "-o", walk, "--rig", "bandai", "--fps", "30", "--no-preview")
    assert res.returncode == 0, res.stderr
    res = invoke("view", walk, "-o", page)
    assert res.returncode == 0, res.stderr
    return walk, page


@pytest.mark.slow  # headless Chromium (installed by `make test`), three page loads
def test_view_page_plays_a_walk_in_headless_chromium(walk_page: tuple[Path, Path], tmp_path: Path) -> None:
    walk, page = walk_page
    text = page.read_text()
    # Self-contained: no external script, style or fetch.
    assert not re.search(r"<(script|link|img)[^>]+(src|href)=", text)
    data = json.loads(
        re.search(r'<script id="motion-data" type="application/json">(.*?)</script>', text, re.DOTALL)[1]
    )
    motion = Motion.load(walk)
    assert data["frames"] == motion.num_frames and data["fps"] == motion.fps
    joints = np.array(data["motions"][0]["joints"]).reshape(-1, 22, 3) / 1000
    offset = data["motions"][0]["offset"]
    assert np.abs(joints - motion.joints - [offset, 0, 0]).max() <= 0.0011  # mm, and the offset to 1 mm

    url = page.as_uri()
    dom, console = chromium(url + "?t=0.5&follow=0", tmp_path / "p0", "--dump-dom")
    assert console == []
    assert re.search(r'<div id="status" data-state="ready" data-frame="10"[ >]', dom), dom[-3000:]
    assert "0.50 / 9.05 s" in dom

    shots = []
    for t in (0.5, 1.5):
        shot = tmp_path / f"t{t}.png"
        _, console = chromium(f"{url}?t={t}&follow=0", tmp_path / f"p{t}", f"--screenshot={shot}")
        assert console == []
        assert Image.open(shot).size == (900, 600)
        shots.append(shot)
    (c1, n1), (c3, n3) = _figure_centre(shots[0]), _figure_centre(shots[1])  # 1.2 m apart
    assert n1 > 1000 and n3 > 1000, (n1, n3)  # a figure is drawn at both times
    # The walk heads for +Z, toward the fixed camera: the figure comes down the picture and grows.
    assert c3[1] - c1[1] > 30 and n3 > n1, (c1, c3, n1, n3)
    floor = np.asarray(Image.open(shots[0]).convert("RGB")).astype(int)[300:560]
    grey_lines = (np.abs(floor - 189).max(axis=-1) < 12).sum()  # the 0.5 m grid's line colour (0xbdbdb8)
    assert grey_lines > 2000, grey_lines


@pytest.mark.slow  # headless Chromium (installed by `make test`)
def test_a_broken_page_is_caught(tmp_path: Path) -> None:
    """The checks above can fail: a page whose script throws shows up in the console and the status."""
    from physmotion.render import make_tracks
    from physmotion.skeleton import rest_joints
    from physmotion.viewer import view_html

    motion = Motion(joints=np.repeat(rest_joints()[None], 10, axis=0), fps=20.0)
    tracks, fps = make_tracks([motion], ["rest"])
    text = view_html(tracks, fps).replace('"parents":[', '"parents":[[')  # JSON the viewer cannot parse
    page = tmp_path / "broken.html"
    page.write_text(text)
    dom, console = chromium(page.as_uri(), tmp_path / "profile", "--dump-dom")
    assert any("Uncaught SyntaxError" in line for line in console), console
    assert 'data-state="error"' in dom


def _colour_pixels(path: Path, colour: str) -> tuple[np.ndarray, int]:
    """Centroid (x, y) and count of the pixels of the 3-D view (legend and control bar left out) whose hue is
    ``colour``'s (#rrggbb): the figure's, shaded by the lights, not the magenta foot-contact markers."""
    hsv = np.asarray(Image.open(path).convert("HSV")).astype(int)[90:560]
    rgb = np.array([[[int(colour[i : i + 2], 16) for i in (1, 3, 5)]]], dtype=np.uint8)
    hue = int(np.asarray(Image.fromarray(rgb).convert("HSV"))[0, 0, 0])
    near = np.minimum(np.abs(hsv[..., 0] - hue), 256 - np.abs(hsv[..., 0] - hue)) <= 10
    mask = near & (hsv[..., 1] > 80) & (hsv[..., 2] > 40)
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()]) if len(xs) else np.full(2, np.nan), int(mask.sum())


@pytest.mark.slow  # headless Chromium (installed by `make test`), four page loads
def test_view_draws_the_skinned_body(walk_page: tuple[Path, Path], tmp_path: Path) -> None:
    """The page's .glb body (GLTFLoader, skinned) is drawn where the sticks are, in the motion's colour,
    many times their area; body=0 hides it and sticks=1 shows the sticks; no console message."""
    walk, page = walk_page
    text = page.read_text()
    data = json.loads(
        re.search(r'<script id="motion-data" type="application/json">(.*?)</script>', text, re.DOTALL)[1]
    )
    glb = base64.b64decode(data["motions"][0]["glb"])
    assert glb[:4] == b"glTF"
    colour = data["motions"][0]["colour"]
    found = {}
    views = {"body": "body=1&sticks=0", "sticks": "body=0&sticks=1", "none": "body=0&sticks=0"}
    for name, query in views.items():
        shot = tmp_path / f"{name}.png"
        url = f"{page.as_uri()}?t=1&follow=0&{query}"
        _, console = chromium(url, tmp_path / f"p{name}", f"--screenshot={shot}")
        assert console == [], console
        found[name] = _colour_pixels(shot, colour)
    dom, console = chromium(f"{page.as_uri()}?t=1&follow=0", tmp_path / "pdom", "--dump-dom")
    assert console == [] and 'data-state="ready"' in dom, dom[-2000:]  # ready: the body has loaded
    (c_body, n_body), (c_sticks, n_sticks), (_, n_none) = found["body"], found["sticks"], found["none"]
    assert n_none < 100, n_none  # both hidden: nothing of the colour is left, what is counted is the figure
    assert n_body > 3000 and n_body > 2 * n_sticks, (n_body, n_sticks)  # measured: 8740 and 3784
    assert n_sticks > 300, n_sticks  # the sticks are drawn, in the same colour
    assert np.linalg.norm(c_body - c_sticks) < 25, (c_body, c_sticks)  # the body is on the skeleton
