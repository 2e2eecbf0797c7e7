"""MeshCat: a localhost-only server, the robot drawn in a real browser, and the replay."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import wholebody

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def scene():
    from wholebody.viz.scene import Scene

    s = Scene(wholebody.load_robot("mobile_humanoid"))
    yield s
    s.close()


def listening_addresses(port: int) -> list[str]:
    """Local IPv4/IPv6 addresses listening on ``port`` (Linux /proc)."""
    out = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, _, state = line.split()[1:4]
            addr, p = local.split(":")
            if int(p, 16) == port and state == "0A":  # LISTEN
                out.append(addr)
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/net/tcp")
def test_server_listens_on_localhost_only(scene):
    for url in (scene.server.web_url, scene.server.zmq_url):
        port = int(url.rsplit(":", 1)[1].split("/")[0])
        addresses = listening_addresses(port)
        assert addresses, f"nothing listens on {port}"
        # 127.0.0.1 is 0100007F in /proc's little-endian hex; never 00000000 (all interfaces)
        assert set(addresses) == {"0100007F"}, addresses


@pytest.mark.skipif(
    CHROMIUM is None,
    reason="Debian's chromium is not installed (.ci/run "
    "installs it); the browser rendering test needs it",
)
@pytest.mark.slow
def test_robot_is_drawn_in_a_headless_browser(scene, tmp_path):
    robot = scene.robot
    scene.show(robot.home())
    out = tmp_path / "shot.png"
    cmd = [
        CHROMIUM,
        "--headless=new",
        "--no-sandbox",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={out}",
        "--window-size=800,600",
        "--virtual-time-budget=10000",
        scene.url,
    ]
    subprocess.run(cmd, capture_output=True, timeout=180, check=False)
    assert out.is_file(), "chromium wrote no screenshot"
    import matplotlib.image

    img = matplotlib.image.imread(out)[..., :3]
    # the page background is a smooth grey gradient; the robot adds many distinct colours
    # (shaded white links, grey joints, the dark chassis) in the middle of the image
    middle = img[150:450, 250:550].reshape(-1, 3)
    colours = np.unique((middle * 255).astype(int), axis=0)
    dark = np.mean(middle.mean(axis=1) < 0.35)
    assert len(colours) > 300, f"only {len(colours)} colours: blank canvas?"
    assert dark > 0.002, "no dark pixels: the robot's chassis is not drawn"


def test_replay_animation_and_props(scene, monkeypatch):
    robot = scene.robot
    qs = np.array([robot.neutral(), robot.home(), robot.neutral()])
    scene.marker("target", [1.7, -0.45, 0.46])
    scene.path("reference", np.array([[0, 0, 0.4], [1.0, 0, 0.5], [1.7, -0.45, 0.46]]))
    scene.cylinder("obstacle", 0.04, 0.2, np.eye(4))
    scene.box("panel", (0.1, 0.3, 0.02), np.eye(4))
    poses = np.repeat(np.eye(4)[None], 3, axis=0)
    poses[:, 0, 3] = [0.0, 1.0, 2.0]  # the panel's x at the three samples
    sent = []
    send = type(scene.viewer).set_animation

    def record(viewer, anim, **kw):
        sent.append(anim)
        return send(viewer, anim, **kw)

    monkeypatch.setattr(type(scene.viewer), "set_animation", record)
    scene.animate(np.array([0.0, 0.5, 1.0]), qs, fps=10, extra={"scene/props/panel": poses})
    time.sleep(0.1)
    assert scene.server.process.poll() is None  # the server took it all and still runs
    (anim,) = sent
    clips = {path.lower(): clip for path, clip in anim.clips.items()}
    panel = clips["/meshcat/scene/props/panel"].tracks["position"]
    assert panel.frames == list(range(11))  # 1 s at 10 fps, both ends
    # each frame shows the latest sample at or after its time (0, then 0.5 s, then 1 s)
    assert [v[0] for v in panel.values] == [0.0] + [1.0] * 5 + [2.0] * 5
    assert sum(len(c.tracks["position"].frames) == 11 for c in clips.values()) > 10  # links


def _screenshot(url: str, tmp_path: Path) -> np.ndarray:
    out = tmp_path / "shot.png"
    cmd = [
        CHROMIUM,
        "--headless=new",
        "--no-sandbox",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={out}",
        "--window-size=800,600",
        "--virtual-time-budget=15000",
        url,
    ]
    subprocess.run(cmd, capture_output=True, timeout=240, check=False)
    assert out.is_file(), "chromium wrote no screenshot"
    import matplotlib.image

    return matplotlib.image.imread(out)[..., :3]


def _robot_data_installed() -> bool:
    from wholebody.robot.urdf import example_robot_data_share

    return example_robot_data_share() is not None


@pytest.mark.slow
@pytest.mark.skipif(not _robot_data_installed(), reason="needs pip install '.[robots]'")
def test_a_shipped_robot_is_drawn_with_its_meshes(tmp_path, capsys):
    """TIAGo++'s meshes live in example-robot-data (package:// paths): found, reduced with
    the locked joints, and drawn."""
    from wholebody.viz.scene import Scene

    robot = wholebody.load_robot("tiago_dual")
    visual, note = robot.geometry("visual")
    meshes = [g for g in visual.geometryObjects if Path(g.meshPath).suffix]  # (shapes: "BOX")
    assert note == "" and len(meshes) > 20 and all(Path(g.meshPath).is_file() for g in meshes)
    scene = Scene(robot)
    try:
        scene.show(robot.home())
        assert "meshes not drawn" not in capsys.readouterr().err
        if CHROMIUM is None:
            pytest.skip("Debian's chromium is not installed (.ci/run installs it)")
        middle = _screenshot(scene.url, tmp_path)[100:500, 200:600].reshape(-1, 3)
        colours = np.unique((middle * 255).astype(int), axis=0)
        assert len(colours) > 300, f"only {len(colours)} colours: blank canvas?"
    finally:
        scene.close()


def test_missing_meshes_are_left_out_and_said_in_one_line(tmp_path, capsys):
    """A URDF whose package:// meshes cannot be found draws its other shapes and says so."""
    from wholebody.resources import robots_dir
    from wholebody.viz.scene import Scene

    dst = tmp_path / "r"
    shutil.copytree(robots_dir() / "mobile_humanoid", dst)
    urdf = dst / "robot.urdf"
    text = urdf.read_text()
    old = '<geometry><cylinder radius="0.08" length="0.05"/></geometry><material name="rubber"/>'
    assert old in text
    urdf.write_text(
        text.replace(
            old,
            '<geometry><mesh filename="package://nowhere/wheel.stl"/>'
            '</geometry><material name="rubber"/>',
            1,
        )
    )
    robot = wholebody.load_robot(dst)
    visual, note = robot.geometry("visual")
    assert "1 meshes not drawn" in note and "package_dirs" in note
    full, _ = wholebody.load_robot("mobile_humanoid").geometry("visual")
    assert visual.ngeoms == full.ngeoms - 1
    scene = Scene(robot)
    try:
        err = capsys.readouterr().err.strip().splitlines()
        assert len([line for line in err if "meshes not drawn" in line]) == 1
    finally:
        scene.close()


def test_meshcat_does_not_print_its_url(scene, capsys):
    """meshcat prints its URL on connecting; the command line prints it once itself."""
    from wholebody.viz.scene import Scene

    capsys.readouterr()
    other = Scene(scene.robot, zmq_url=scene.server.zmq_url)  # attached: no second server
    assert other.url == scene.url
    out = capsys.readouterr().out
    assert "You can open the visualizer" not in out and scene.url not in out


def _in_view(
    points: np.ndarray, eye: np.ndarray, target: np.ndarray, fov_deg: float, aspect: float
) -> np.ndarray:
    """Whether each point is inside the view of a camera at ``eye`` looking at ``target``
    (z up), vertical field of view ``fov_deg``, width / height ``aspect``."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = points - eye
    depth = rel @ forward
    tan_v = np.tan(np.radians(fov_deg) / 2)
    return (
        (depth > 0)
        & (np.abs(rel @ up) <= tan_v * depth)
        & (np.abs(rel @ right) <= tan_v * aspect * depth)
    )


def test_the_camera_frames_a_seven_metre_drive():
    """The carry drives 7 m: every corner of its extent is in the camera's view, which the
    default camera (at (3, 0, 1) looking at the origin) is not."""
    from wholebody.viz.scene import CAMERA_FOV_DEG, camera_view

    lo, hi = np.array([-2.0, -7.3, 0.0]), np.array([2.0, 0.6, 1.6])
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    target, offset = camera_view(corners)
    assert _in_view(corners, target + offset, target, CAMERA_FOV_DEG, 4 / 3).all()
    assert _in_view(corners, target + offset, target, CAMERA_FOV_DEG, 1.0).all()  # square page
    default = _in_view(corners, np.array([3.0, 0.0, 1.0]), np.zeros(3), CAMERA_FOV_DEG, 4 / 3)
    assert not default.all()
    near, _ = camera_view(np.zeros((1, 3)))
    assert np.linalg.norm(camera_view(np.zeros((1, 3)))[1]) >= 2.5 and np.allclose(near, 0)


def test_frame_moves_the_scene_under_the_camera(scene, monkeypatch):
    """meshcat 0.3's camera orbits the world origin: framing shifts the scene's roots (the
    robot and props, the grid, the axes) by minus the target and puts the camera at its
    offset (three.js's y-up axes)."""
    from wholebody.viz.scene import camera_view

    sent = []
    window = type(scene.viewer.window)
    send = window.send
    monkeypatch.setattr(
        window, "send", lambda self, cmd: sent.append(cmd.lower()) or send(self, cmd)
    )
    points = np.array([[0.0, 0.0, 0.0], [0.0, -7.0, 1.0]])
    scene.clear()
    scene.frame(points)
    target, offset = camera_view(points)
    np.testing.assert_allclose(scene.target, target)
    moved = {
        c["path"]: np.array(c["matrix"]).reshape(4, 4).T
        for c in sent
        if c["type"] == "set_transform"
    }
    for root in ("/meshcat", "/Grid", "/Axes"):
        np.testing.assert_allclose(moved[root][:3, 3], -target)
        np.testing.assert_allclose(moved[root][:3, :3], np.eye(3))
    (camera,) = [c for c in sent if c["type"] == "set_property"]
    assert camera["path"] == "/Cameras/default/rotated/<object>"
    np.testing.assert_allclose(camera["value"], [offset[0], offset[2], -offset[1]])


@pytest.mark.slow
@pytest.mark.skipif(
    CHROMIUM is None, reason="Debian's chromium is not installed (.ci/run installs it)"
)
def test_the_replay_page_opens_without_a_server_and_frames_the_run(tmp_path):
    """The page saved by save_html draws the robot from a file, the server gone; framed on
    the robot and a marker 7 m to its right, both are in view (the default camera shows no
    marker)."""
    from wholebody.viz.scene import Scene

    s = Scene(wholebody.load_robot("mobile_humanoid"))
    try:
        q = s.robot.home()
        s.show(q)
        s.marker("far", [0.0, -7.0, 0.5], color="#ff0000", radius=0.2)
        unframed = s.save_html(tmp_path / "unframed.html")
        s.frame(q=q)
        page = s.save_html(tmp_path / "replay.html")
    finally:
        s.close()
    assert s.server.process.poll() is not None  # no server from here on

    def red(img: np.ndarray) -> int:
        return int(np.sum((img[..., 0] > 0.7) & (img[..., 1] < 0.3) & (img[..., 2] < 0.3)))

    framed = _screenshot(page.as_uri(), tmp_path)
    middle = framed[100:500, 100:700].reshape(-1, 3)
    assert len(np.unique((middle * 255).astype(int), axis=0)) > 300, "robot not drawn"
    assert red(framed) > 50, "the far marker is out of view"
    assert red(_screenshot(unframed.as_uri(), tmp_path)) == 0


@pytest.mark.slow
def test_the_closest_pairs_are_drawn_live_and_in_the_replay(scene, monkeypatch, tmp_path):
    """A run with [collision]: the live view draws lines between the closest witness points
    (red at the safety distance) and the replay page holds the closest approach's line."""
    from wholebody.resources import tasks_dir
    from wholebody.scenarios import load_scenario, run_scenario
    from wholebody.scenarios.runner import collision_model
    from wholebody.scenarios.visual import LiveView, show_run

    drawn = []
    monkeypatch.setattr(
        type(scene), "closest_pairs", lambda self, pairs, **kw: drawn.append((list(pairs), kw))
    )
    spec = load_scenario(tasks_dir() / "reach_under_shelf.toml")
    live = LiveView(scene, spec.dt, realtime=False, collision=collision_model(spec, scene.robot))
    run = run_scenario(spec, on_step=live, duration_scale=1.0)
    names = {p.name for pairs, _ in drawn for p in pairs}
    assert "right_hand_1_capsule|shelf_board" in names
    drawn.clear()
    show_run(scene, run)  # the replay: the closest approach's pair, at its time
    ((pairs, kw),) = drawn
    assert [p.name for p in pairs] == [run.metrics["min_collision_pair"]]
    assert kw["safety"] == 0.01 and pairs[0].distance == pytest.approx(
        run.metrics["min_collision_distance_m"]
    )
