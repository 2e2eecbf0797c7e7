"""Sweeps (wholebody.sweep): campaign files checked, cases fixed by their seed, the same
results on a local pool, one by one and on Ray, nothing lost or repeated across a kill."""

from __future__ import annotations

import ipaddress
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import wholebody as wb
from wholebody.cli import main
from wholebody.errors import ConfigError
from wholebody.sweep import executors, load_campaign, run_case, run_sweep
from wholebody.sweep.executors import run_ray, start_local_ray
from wholebody.sweep.store import flatten

CAMPAIGN = """
format = 1
[campaign]
name = "small"
scenario = "reach_generalisation"
duration_scale = 0.05
samples = 2
seed = 7

[[axes]]
key = "stack.energy"
values = [0.0, 0.5]

[[axes]]
key = "hands.right.kp"
uniform = [10.0, 30.0]
"""

TIMING = ("wall_s", "step_time_us", "median_step_rate_hz")
"""Columns that are wall times: they differ between any two runs."""


def _campaign(tmp_path: Path, text: str = CAMPAIGN, name: str = "campaign.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _deterministic(row: dict) -> str:
    """A row without its wall times, as text (so that NaN equals NaN)."""
    return json.dumps({k: v for k, v in row.items() if not k.startswith(TIMING)}, sort_keys=True)


def test_cases_are_fixed_by_the_seed_and_shared_across_the_grid(tmp_path):
    """Two loads give the same cases; each grid point gets the same random draws; the
    values are within their bounds."""
    campaign = load_campaign(_campaign(tmp_path))
    cases = campaign.cases()
    assert [c.values for c in cases] == [c.values for c in load_campaign(campaign.path).cases()]
    assert len(cases) == 4 and [c.sample for c in cases] == [0, 1, 0, 1]
    kp = [c.values["hands.right.kp"] for c in cases]
    assert kp[0] == kp[2] and kp[1] == kp[3] and kp[0] != kp[1]
    assert all(10.0 <= v <= 30.0 for v in kp)
    spec, options = campaign.case_spec(cases[3])
    assert spec.stack.energy == 0.5 and spec.hands["right"].kp == kp[3]
    assert options == {"sim": "kinematic"}


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('key = "stack.energy"', 'key = "stack.energergy"', "stack.energergy"),
        ("values = [0.0, 0.5]", 'values = [0.0, "x"]', "axes[0]"),
        ("uniform = [10.0, 30.0]", "uniform = [30.0, 10.0]", "low < high"),
        ('scenario = "reach_generalisation"', 'scenario = "nope"', "no scenario file 'nope'"),
        ("seed = 7", "seed = -1", "campaign.seed"),
        ("samples = 2", "sample = 2", "sample"),
        ('key = "stack.energy"', 'key = "phases.nope.duration"', "no entry named 'nope'"),
    ],
)
def test_a_bad_campaign_is_named(tmp_path, old, new, message):
    path = _campaign(tmp_path, CAMPAIGN.replace(old, new))
    with pytest.raises(ConfigError) as info:
        load_campaign(path)
    assert str(path) in str(info.value) and message in str(info.value), str(info.value)


@pytest.mark.parametrize("name", ["carry_weights", "panda_targets"])
def test_the_bundled_campaigns_load(name):
    from wholebody.cli import _campaign_path
    from wholebody.robot.urdf import example_robot_data_share

    if name == "panda_targets" and example_robot_data_share() is None:
        pytest.skip("example-robot-data is not installed (pip install '.[robots]')")
    campaign = load_campaign(_campaign_path(name))
    assert len(campaign.cases()) == {"carry_weights": 36, "panda_targets": 2000}[name]


def test_random_targets_are_reachable_and_shared_by_the_backends(tmp_path):
    """The built-in campaign: each draw is one target, the same for both backends, a pose
    the tool has at a configuration within the limits (reachable); each case reports how
    far the hand ended from it (a local minimum may keep it away: that is what such a
    campaign measures)."""
    text = """
format = 1
[campaign]
builtin = "random_targets"
robot = "mobile_humanoid"
samples = 2
duration = 2.0
seed = 1

[[axes]]
key = "backend"
values = ["projection", "hqp"]
"""
    campaign = load_campaign(_campaign(tmp_path, text))
    cases = campaign.cases()
    goals = [campaign.case_spec(c)[0].phases[0].hands["left"].goal for c in cases]
    assert goals[0] == goals[2] and goals[1] == goals[3] and goals[0] != goals[1]
    robot = wb.load_robot("mobile_humanoid")
    lo, hi = robot.position_limits
    rng = np.random.default_rng([1, 0, 1])  # draw 0's configuration, as the campaign draws it
    q = rng.uniform(np.clip(lo, -np.pi, np.pi), np.clip(hi, -np.pi, np.pi))
    joints = dict(zip(robot.actuated_joints[4:], q[4:], strict=True))
    pose = robot.frame_pose(robot.configuration(joints), "left_tool")
    np.testing.assert_allclose(goals[0], pose[:3, 3], atol=1e-12)
    result = run_case(campaign, cases[0])
    assert result["status"] == "ok", result["error"]
    assert np.isfinite(result["metrics"]["final_error_m"])


def test_backend_engine_and_robot_axes_are_checked(tmp_path):
    """Run options, their combinations, robots, repeated or conflicting axes and integer
    keys drawn as reals are refused before anything runs."""
    bad = [
        ('key = "backend"\nvalues = ["hqp", "qp"]', "backend 'qp'"),
        ('key = "engine"\nvalues = ["daqp", "nope"]', "engine 'nope'"),
        ('key = "engine"\nvalues = ["daqp"]', "is for the hqp backend"),
        ('key = "robot"\nvalues = ["mobile_humanoid", "no_such_robot"]', "no_such_robot"),
        ('key = "planner.n_basis"\nuniform = [10, 60]', "planner.n_basis"),
        (
            'key = "scenario.backend"\nvalues = ["hqp"]\n[[axes]]\nkey = "backend"\n'
            'values = ["hqp"]',
            "varied by two axes",
        ),
        ('key = "planner.stiffness"\nvalues = [100.0, 100.0]', "repeated"),
    ]
    for axis, message in bad:
        with pytest.raises(ConfigError, match=message):
            load_campaign(_campaign(tmp_path, CAMPAIGN + f"\n[[axes]]\n{axis}\n"))
    text = CAMPAIGN.replace(
        'key = "hands.right.kp"\nuniform = [10.0, 30.0]',
        'key = "planner.stiffness"\nvalues = [900.0]',
    )
    with pytest.raises(ConfigError, match="no random axis"):
        load_campaign(_campaign(tmp_path, text))


def test_set_key_reaches_named_and_numbered_entries():
    from wholebody.sweep.campaign import set_key

    data = {"phases": [{"name": "a", "hands": {"right": {"goal": [1.0, 2.0, 3.0]}}}]}
    set_key(data, "phases.a.hands.right.goal.2", 9.0)
    set_key(data, "phases.0.duration", 4.0)
    assert data["phases"][0]["hands"]["right"]["goal"] == [1.0, 2.0, 9.0]
    assert data["phases"][0]["duration"] == 4.0
    for key in ("phases.a.hands.right.goal.3", "phases.a.hands.right.goal.2.x", "phases.b.x"):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            set_key(data, key, 0.0)


@pytest.mark.slow
def test_local_sweep_gives_the_cases_run_one_by_one(tmp_path):
    """Two worker processes give, case for case, what :func:`run_case` gives in this process
    (wall times aside); the table, best cases and plots are written; a failing case (a
    start outside a joint's limits, found when it runs) is recorded with its error and the
    others run."""
    text = (
        CAMPAIGN + '\n[[axes]]\nkey = "scenario.start"\nvalues = ["neutral", {waist_yaw = 5.0}]\n'
    )
    campaign = load_campaign(_campaign(tmp_path, text))
    result = run_sweep(campaign, tmp_path / "out", workers=2, progress=False)
    assert (result.cases, result.found, result.ran, result.failed) == (8, 0, 8, 4)
    by_case = {r["index"]: r for r in result.rows}
    for case in campaign.cases():
        alone = flatten(run_case(campaign, case))
        assert _deterministic(by_case[case.index]) == _deterministic(alone)
        if case.values["scenario.start"] != "neutral":
            assert alone["status"] == "error" and "waist_yaw" in alone["error"]
    out = tmp_path / "out"
    assert (out / "results.csv").read_text().count("\n") == 9
    assert {"best.md", "axes.png", "results.csv", "campaign.json"} <= {
        p.name for p in out.iterdir()
    }
    assert "| case | stack.energy |" in (out / "best.md").read_text()


def test_a_directory_holds_one_campaign(tmp_path):
    campaign = load_campaign(_campaign(tmp_path))
    from wholebody.sweep.store import SweepStore

    SweepStore(tmp_path / "out", campaign)
    other = load_campaign(_campaign(tmp_path, CAMPAIGN.replace("seed = 7", "seed = 8"), "b.toml"))
    with pytest.raises(ConfigError, match="another campaign"):
        SweepStore(tmp_path / "out", other)


@pytest.mark.slow
def test_a_killed_sweep_restarted_loses_and_repeats_nothing(tmp_path):
    """The sweep is killed (SIGKILL, workers too) once some cases are written; started
    again it runs only the others: the files written before are untouched, every case has
    one file."""
    path = _campaign(tmp_path, CAMPAIGN.replace("samples = 2", "samples = 4"))
    out = tmp_path / "out"
    command = [
        sys.executable,
        "-m",
        "wholebody",
        "sweep",
        str(path),
        "--out",
        str(out),
        "--workers",
        "1",
    ]
    proc = subprocess.Popen(
        command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.time() + 240
    while len(list((out / "cases").glob("case_*.json"))) < 2 and time.time() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    before = {p.name: p.read_bytes() for p in (out / "cases").glob("case_*.json")}
    assert 2 <= len(before) < 8, len(before)
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"{len(before)} found finished" in done.stdout
    assert f"{8 - len(before)} run now" in done.stdout
    after = {p.name: p.read_bytes() for p in (out / "cases").glob("case_*.json")}
    assert len(after) == 8 and all(after[name] == data for name, data in before.items())


@pytest.mark.slow
def test_a_case_over_the_time_limit_is_stopped_and_the_sweep_goes_on(tmp_path, capsys):
    """A case that runs longer than ``--timeout`` stops there (not at its end: its wall time
    is the limit's, not the run's) and is recorded as ``"timeout"``; the others run, the
    table and report are written, and ``--retry-failed`` runs the stopped ones again."""
    campaign = load_campaign(_campaign(tmp_path, CAMPAIGN.replace("0.05", "3.0")))
    run_case(campaign, campaign.cases()[0])  # (the kernels loaded)
    full = run_case(campaign, campaign.cases()[0])
    assert full["status"] == "ok" and full["wall_s"] > 0.4, full["wall_s"]
    stopped = run_case(campaign, campaign.cases()[0], timeout=0.1)
    assert stopped["status"] == "timeout" and "0.1 s" in stopped["error"]
    assert stopped["wall_s"] < 0.5 * full["wall_s"], (stopped["wall_s"], full["wall_s"])
    out = tmp_path / "out"
    code = main(
        ["sweep", str(campaign.path), "--out", str(out), "--workers", "1", "--timeout", "0.1"]
    )
    assert code == 1, capsys.readouterr().err  # (every case failed)
    results = [json.loads(p.read_text()) for p in sorted((out / "cases").glob("case_*.json"))]
    assert [r["status"] for r in results] == ["timeout"] * 4
    assert (out / "results.csv").is_file()
    again = run_sweep(campaign, out, workers=1, retry_failed=True, progress=False)
    assert again.ran == 4 and again.failed == 0
    assert main(["sweep", str(campaign.path), "--out", str(out), "--timeout", "0"]) != 0
    assert "time limit must be > 0 s" in capsys.readouterr().err
    assert main(["sweep", str(campaign.path), "--out", str(out), "--timeout", "inf"]) != 0
    assert "and finite" in capsys.readouterr().err


def test_the_time_limit_waits_for_a_kernel_being_loaded():
    """A limit that expires while numba loads or compiles a kernel does not interrupt it (a
    half-loaded kernel broke the worker's later cases: "generator raised StopIteration"); it
    fires once the loading is done."""
    from wholebody import kernels
    from wholebody.sweep.case import CaseTimeoutError, _Limit

    if not hasattr(signal, "setitimer"):
        pytest.skip("no interval timers here")
    limit = _Limit(0.05)
    kernels._DEPTH[0] += 1  # "loading a kernel"
    limit.start()
    try:
        time.sleep(0.3)  # the limit passes, nothing is raised
        assert limit.armed and not limit.expired
        kernels._DEPTH[0] -= 1
        with pytest.raises(CaseTimeoutError):
            time.sleep(0.5)
        assert limit.expired
    finally:
        limit.stop()
        kernels._DEPTH[0] = 0


def test_a_run_that_swallowed_its_time_limit_is_still_a_timeout(tmp_path, monkeypatch):
    """Code that catches every exception can swallow the limit's; the case ran past its limit
    all the same and is recorded so, not as ``"ok"``."""
    import wholebody.scenarios.runner as runner

    if not hasattr(signal, "setitimer"):
        pytest.skip("no interval timers here")

    def swallowing(*args, **kwargs):
        try:
            time.sleep(0.5)
        except BaseException:  # (what the test is about)
            time.sleep(0.1)
        return SimpleNamespace(metrics={})

    monkeypatch.setattr(runner, "run_scenario", swallowing)
    monkeypatch.setattr("wholebody.sweep.case.headline", lambda run: {})
    campaign = load_campaign(_campaign(tmp_path))
    result = run_case(campaign, campaign.cases()[0], timeout=0.05)
    assert result["status"] == "timeout" and "0.05 s" in result["error"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_the_same_campaign_on_a_local_ray_head_gives_the_same_table(tmp_path, monkeypatch):
    """A Ray head started here on 127.0.0.1 runs the campaign (``--ray 127.0.0.1:PORT``) to
    the table the local pool gives. (``ray stop`` at the end stops every Ray instance of
    this user on the machine: Ray has no per-instance stop.)"""
    pytest.importorskip("ray")
    ray_cli = shutil.which("ray", path=str(Path(sys.executable).parent))
    assert ray_cli, "the ray command of this environment"
    campaign = load_campaign(_campaign(tmp_path))
    local = run_sweep(campaign, tmp_path / "local", workers=2, progress=False)
    port = _free_port()
    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")  # the head's and this driver's alike
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    subprocess.run(
        [
            ray_cli,
            "start",
            "--head",
            "--node-ip-address=127.0.0.1",
            f"--port={port}",
            "--num-cpus=2",
            "--include-dashboard=false",
            "--disable-usage-stats",
        ],
        check=True,
        capture_output=True,
        env=env,
        timeout=180,
    )
    try:
        remote = run_sweep(
            campaign, tmp_path / "ray", ray=True, address=f"127.0.0.1:{port}", progress=False
        )
    finally:
        subprocess.run([ray_cli, "stop", "--force"], capture_output=True, env=env, timeout=120)
    assert remote.failed == 0 and len(remote.rows) == 4
    assert [_deterministic(r) for r in remote.rows] == [_deterministic(r) for r in local.rows]
    case = json.loads((tmp_path / "ray" / "cases" / "case_00000.json").read_text())
    assert case["status"] == "ok"


def _loopback(ip: str) -> bool:
    address = ipaddress.ip_address(ip.split("%")[0])
    mapped = getattr(address, "ipv4_mapped", None)
    return address.is_loopback or (mapped is not None and mapped.is_loopback)


@pytest.mark.slow
def test_a_local_ray_sweep_listens_on_the_loopback_interface_only(tmp_path):
    """``--ray`` without an address: while the cases run, every socket this process and the
    processes it started (Ray's GCS, raylet, agents and workers) listen on is a loopback
    one; Ray 2.60 left to itself listens on every interface. The results are the pool's."""
    pytest.importorskip("ray")
    psutil = pytest.importorskip("psutil")
    campaign = load_campaign(_campaign(tmp_path))
    listening: list[str] = []
    results: list[dict] = []

    def on_result(result: dict) -> None:
        me = psutil.Process()
        for proc in [me, *me.children(recursive=True)]:
            for sock in proc.net_connections(kind="inet"):
                if sock.status == psutil.CONN_LISTEN:
                    listening.append(f"{sock.laddr.ip}:{sock.laddr.port} ({proc.name()})")
        results.append(result)

    run_ray(campaign, campaign.cases(), None, on_result, workers=2)
    assert any("raylet" in s or "gcs" in s for s in listening), listening  # Ray's were seen
    assert all(_loopback(s.split(" ")[0].rsplit(":", 1)[0]) for s in listening), listening
    local = run_sweep(campaign, tmp_path / "local", workers=2, progress=False)
    rows = {r["index"]: r for r in results}
    assert sorted(rows) == [r["index"] for r in local.rows]
    assert all(rows[r["index"]]["status"] == r["status"] == "ok" for r in local.rows)
    stopped: list[dict] = []  # a Ray worker runs the case's time limit too
    run_ray(campaign, campaign.cases()[:1], None, stopped.append, workers=1, timeout=1e-3)
    assert [r["status"] for r in stopped] == ["timeout"], stopped


@pytest.mark.slow
def test_a_local_ray_that_listens_on_the_network_is_stopped_and_refused(monkeypatch):
    """Where Ray binds a server beyond the loopback interface anyway, the instance is shut
    down and the sweep refused with what to do, ``--ray-public`` among it."""
    ray = pytest.importorskip("ray")
    pytest.importorskip("psutil")
    monkeypatch.setattr(executors, "exposed_listeners", lambda: ["192.0.2.2:6379 (gcs_server)"])
    with pytest.raises(ConfigError, match=r"192\.0\.2\.2:6379.*--ray-public"):
        start_local_ray(1)
    assert not ray.is_initialized()


def test_ray_public_is_for_a_local_instance_only(tmp_path, capsys):
    for argv in (["--ray-public"], ["--ray", "10.0.0.1:6379", "--ray-public"]):
        code = main(["sweep", str(_campaign(tmp_path)), "--out", str(tmp_path / "o"), *argv])
        assert code != 0
        assert "--ray-public is for a local Ray instance" in capsys.readouterr().err
