"""The ROS 2 bridge (``--controller ros2``) against real nodes in subprocesses: the example
pure-pursuit node plays exactly the in-process controller's episodes, a node that never answers
or crashes makes sut_error episodes (and is started anew), the timer-driven node drives, and no
process or shared-memory file outlives a run."""

from __future__ import annotations

import dataclasses
import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hazardhunt.campaign.config import ConfigError, load_campaign
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.pursuit import PursuitController
from tests.helpers import hazardhunt, run_tables

pytest.importorskip("rclpy", reason="the ros2 extra is not installed (pip install -e '.[ros2]')")

from hazardhunt.sut.ros2.bridge import Ros2Controller

ROOT = Path(__file__).parents[2]
PURSUIT_NODE = ROOT / "examples" / "ros2" / "pure_pursuit_node.py"
NMPC_NODE = ROOT / "examples" / "ros2" / "nmpc_node.py"
SCENARIOS = ROOT / "src" / "hazardhunt" / "scenarios"
TEST_NODES = Path(__file__).parent / "ros2_nodes"


def node_command(script: Path, *parameters: str) -> str:
    """The command line that runs ``script`` with this Python, with ROS parameters NAME:=VALUE."""
    command = [sys.executable, str(script)]
    if parameters:
        command += ["--ros-args", *(part for p in parameters for part in ("-p", p))]
    return shlex.join(command)


def random_actions(seed: int, episodes: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1, 1, size=(15, 2)).astype(np.float32) for _ in range(episodes)]


def played(controller: object, actions: list[np.ndarray]) -> list[tuple[object, ...]]:
    """Each episode's summary and trajectory (wall-clock times left out)."""
    simulation = Simulation.build("crossing", "none", controller=controller)
    episodes = []
    for episode_actions in actions:
        summary = simulation.simulate(episode_actions).summary
        trajectory = [
            dataclasses.replace(sample, solve_time_s=0.0) for sample in simulation.trajectory()
        ]
        episodes.append((summary.outcome, summary.contact_face, summary.sim_time, trajectory))
    return episodes


def node_processes(marker: str) -> list[str]:
    """Command lines of this machine's processes that contain ``marker``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if marker in command:
            found.append(command)
    return found


def shared_memory() -> set[str]:
    return set(os.listdir("/dev/shm")) if Path("/dev/shm").is_dir() else set()


def test_the_answering_node_plays_the_in_process_controllers_episodes_exactly():
    actions = [a for seed in (0, 1, 2) for a in random_actions(seed, 2)]
    bridge = Ros2Controller(command=node_command(PURSUIT_NODE))
    try:
        through_ros = played(bridge, actions)
    finally:
        bridge.close()
    in_process = played(PursuitController(), actions)
    assert [e[0] for e in in_process].count(None) < len(actions)  # episodes that ended
    assert through_ros == in_process


def test_the_scan_shows_the_true_human_also_where_the_cameras_do_not_see_it():
    from hazardhunt.world.bodies import RobotParams, RobotState

    simulation = Simulation.build("crossing", "none")  # its floor and route
    floor = dataclasses.replace(
        simulation.scenario.floor,
        blind_zones=(np.array([[9.0, 4.0], [11.0, 4.0], [11.0, 6.0], [9.0, 6.0]]),),
    )
    robot = RobotState(5.0, 4.75, 0.0, 0.0, 0.0)  # in the aisle y 4..5.5, facing east
    bridge = Ros2Controller(command=node_command(TEST_NODES / "scan_echo_node.py"))
    ahead = []
    try:
        bridge.reset(floor, simulation.route, robot, RobotParams())
        for time_s, sensed in ((0.0, True), (0.2, False)):
            if sensed:  # as the simulation does at each instant: the true human, untracked
                bridge.sense_human(time_s, np.array([10.0, 4.75]), 0.25)
            ahead.append(bridge.control(time_s, robot, None).speed)  # the middle ray's range
    finally:
        bridge.close()
    assert ahead[0] == pytest.approx(4.75, abs=1e-5)  # the human's disc, 10 - 0.25 - 5
    assert ahead[1] == pytest.approx(14.8, abs=1e-5)  # not given: the east wall at 19.8


PHYSICAL = ("time", "human_x", "human_y", "human_heading", "robot_x", "robot_y", "robot_heading",
            "robot_speed", "robot_yaw_rate", "human_visible", "emergency_stop", "human_in_field",
            "clearance")  # fmt: skip


@pytest.mark.slow
def test_the_nmpc_node_plays_the_in_process_nmpcs_episodes(tmp_path):
    from hazardhunt.sut.nmpc import NMPCController

    # The shop floor's ROS map, published at its own 0.1 m: the node's obstacles are the
    # in-process NMPC's, in the same order.
    text = (SCENARIOS / "crossing.toml").read_text()
    scenario = tmp_path / "crossing-on-map.toml"
    scenario.write_text(
        text.replace('"shopfloor.toml"', json.dumps(str(SCENARIOS / "shopfloor.yaml")))
    )
    actions = [a for seed in (0, 1) for a in random_actions(seed, 2)]

    def episodes(controller):
        simulation = Simulation.build(str(scenario), "none", controller=controller)
        played = []
        for episode_actions in actions:
            summary = simulation.simulate(episode_actions).summary
            trajectory = [[getattr(s, name) for name in PHYSICAL] for s in simulation.trajectory()]
            played.append(((summary.outcome, summary.contact_face), np.array(trajectory, float)))
        return played

    bridge = Ros2Controller(command=node_command(NMPC_NODE), map_resolution=0.1)
    try:
        through_ros = episodes(bridge)
    finally:
        bridge.close()
    in_process = episodes(NMPCController())
    assert [e[0] for e in through_ros] == [e[0] for e in in_process]
    assert {e[0][0] for e in in_process} - {None, "sut_error"}  # episodes that ended
    for (_, ros), (_, local) in zip(through_ros, in_process, strict=True):
        assert ros.shape == local.shape
        # Equal but for the last bits: the stamps' whole nanoseconds and the heading's
        # quaternion round the node's inputs (docs/ros2.md).
        np.testing.assert_allclose(ros, local, rtol=0, atol=1e-9)


def test_simulated_time_never_runs_backwards_in_a_nodes_life():
    bridge = Ros2Controller(command=node_command(TEST_NODES / "clock_checking_node.py"))
    try:
        simulation = Simulation.build("crossing", "none", controller=bridge)
        outcomes = [simulation.simulate(a).outcome for a in random_actions(7, 3)]
    finally:
        bridge.close()
    assert "sut_error" not in outcomes
    assert None not in outcomes  # each episode ended (goal, failure, ...), three in one life


@pytest.mark.slow
@pytest.mark.parametrize("reset", ["service", "restart"])
def test_a_node_reset_by_its_service_or_started_anew_per_episode_plays_the_same_episodes(reset):
    actions = random_actions(5, 3)
    bridge = Ros2Controller(command=node_command(PURSUIT_NODE), reset=reset)
    try:
        through_ros = played(bridge, actions)
    finally:
        bridge.close()
    assert through_ros == played(PursuitController(), actions)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 4])
def test_a_run_through_the_bridge_records_the_in_process_run(tmp_path, seed):
    common = ["run", "--scenario", "crossing", "--field", "none", "--tester", "random",
              "--episodes", 6, "--seed", seed, "--json"]  # fmt: skip
    command = f"command={json.dumps(node_command(PURSUIT_NODE))}"
    ros = hazardhunt(*common, "--out", tmp_path / "ros", "--controller", "ros2",
                     "--controller-param", command)  # fmt: skip
    assert ros.returncode == 0, ros.stderr
    local = hazardhunt(*common, "--out", tmp_path / "local",
                       "--controller", "hazardhunt.sut.pursuit:PursuitController")  # fmt: skip
    assert local.returncode == 0, local.stderr
    ros_episodes, ros_failures = run_tables(tmp_path / "ros")
    local_episodes, local_failures = run_tables(tmp_path / "local")
    pd.testing.assert_frame_equal(ros_episodes, local_episodes)
    pd.testing.assert_frame_equal(ros_failures, local_failures)
    assert set(ros_episodes["outcome"]) != {"sut_error"}


def test_a_node_that_never_answers_is_a_one_line_error_before_anything_is_written(tmp_path):
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", 3, "--out", out, "--controller", "ros2",
        "--controller-param", f"command={json.dumps(node_command(TEST_NODES / 'silent_node.py'))}",
        "--controller-param", "timeout=0.3",
    )  # fmt: skip
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "no /cmd_vel within 0.3 s" in lines[0]
    assert "trial episode" in lines[0]
    assert not out.exists()


def test_a_node_that_publishes_commands_of_another_type_is_a_one_line_error(tmp_path):
    out = tmp_path / "run"
    command = f"command={json.dumps(node_command(TEST_NODES / 'stamped_node.py'))}"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--episodes", 3, "--out", out,
        "--controller", "ros2", "--controller-param", command,
    )  # fmt: skip
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("error: controller 'ros2': reset() raised RuntimeError: ")
    assert lines[0].endswith(
        "publishes /cmd_vel as geometry_msgs/msg/TwistStamped, not geometry_msgs/msg/Twist (on a "
        "trial episode before the run; nothing was run)"
    )
    assert not out.exists()


def test_a_node_that_never_answers_makes_each_episode_a_sut_error():
    bridge = Ros2Controller(command=node_command(TEST_NODES / "silent_node.py"), timeout=0.2)
    try:
        simulation = Simulation.build("crossing", "none", controller=bridge)
        outcomes = [simulation.simulate(a).outcome for a in random_actions(0, 2)]
        errors = simulation.summary().controller_errors
    finally:
        bridge.close()
    assert outcomes == ["sut_error", "sut_error"]
    assert "no /cmd_vel within 0.2 s (timeout)" in errors[0]


@pytest.mark.slow
def test_a_node_that_crashes_mid_run_errs_that_episode_is_started_anew_and_the_run_goes_on(
    tmp_path,
):
    marker = tmp_path / "crashed"
    command = node_command(TEST_NODES / "crashing_node.py", "crash_after:=20", f"marker:={marker}")
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", 3, "--seed", 0, "--out", out, "--json",
        "--controller", "ros2", "--controller-param", f"command={json.dumps(command)}",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert marker.exists()
    episodes, _ = run_tables(out)
    assert episodes["outcome"].tolist()[0] == "sut_error"
    assert "sut_error" not in episodes["outcome"].tolist()[1:]
    assert node_processes(str(TEST_NODES)) == []


def test_the_timer_driven_node_drives_the_robot_to_its_goal():
    bridge = Ros2Controller(command=node_command(PURSUIT_NODE, "mode:=timer"))
    try:
        simulation = Simulation.build("crossing", "none", controller=bridge)
        standing = np.array([[-1.0, 0.0]] * 15, dtype=np.float32)  # the human stands still
        outcomes = [simulation.simulate(standing).outcome for _ in range(2)]
    finally:
        bridge.close()
    assert outcomes == ["goal", "goal"]


def test_the_bridge_needs_the_ros2_extra_and_says_what_to_install(tmp_path):
    script = (
        "import sys; sys.modules['rclpy'] = None\n"  # as if the ros2 extra were not installed
        "from hazardhunt.cli import run\n"
        "sys.argv = ['hazardhunt', *sys.argv[1:]]\n"
        "run()\n"
    )
    out = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "-c", script, "run", "--scenario", "crossing", "--episodes", "2",
         "--out", str(out), "--controller", "ros2", "--controller-param", "command=my_node"],
        capture_output=True, text=True, env=os.environ | {"COLUMNS": "1000"}, check=False,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "error: controller: ros2: ROS 2's Python packages are not installed (import of rclpy "
        "halted; None in sys.modules); install them with pip install 'hazardhunt[ros2]'"
    ]
    assert not out.exists()


def ros2_campaign(folder: Path, episodes: int) -> Path:
    """A campaign file of two runs whose controller is the example node through the bridge."""
    path = folder / "campaign.toml"
    path.write_text(
        'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [0, 1]\n'
        f'episodes = {episodes}\n\n[controller]\npath = "ros2"\n'
        f"params = {{ command = {json.dumps(node_command(PURSUIT_NODE))} }}\n"
    )
    return path


@pytest.mark.parametrize(
    ("params", "problem"),
    [
        ('{ command = "my_node", timout = 2.0 }', "ros2: does not take these parameters: got an "
         "unexpected keyword argument 'timout'"),
        ('{ command = "my_node", reset = "reboot" }', "ros2: reset must be 'messages', 'service' "
         "or 'restart', not 'reboot'"),
        ('{ command = "my_node", topics = { odometry = "/odom" } }', "ros2: topics: unknown role "
         "'odometry' (roles: clock, odom, scan, human, plan, goal, map, cmd_vel)"),
        ("{ timeout = 2.0 }", "ros2: does not take these parameters: missing a required argument: "
         "'command'"),
    ],
)  # fmt: skip
def test_a_campaign_file_naming_ros2_with_bad_parameters_is_one_line_naming_it(
    tmp_path, params, problem
):
    path = tmp_path / "campaign.toml"
    path.write_text(
        'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [0]\n'
        f'episodes = 2\n\n[controller]\npath = "ros2"\nparams = {params}\n'
    )
    with pytest.raises(ConfigError) as raised:
        load_campaign(path)
    assert str(raised.value) == f"{path}: controller: {problem}"
    assert node_processes(str(tmp_path)) == []


@pytest.mark.slow
@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGKILL])
def test_a_stopped_campaign_with_two_workers_leaves_no_node_and_no_shared_memory(tmp_path, stop):
    before = shared_memory()
    process = subprocess.Popen(
        [sys.executable, "-m", "hazardhunt.cli", "campaign", str(ros2_campaign(tmp_path, 2000)),
         "--workers", "2", "--out", str(tmp_path / "campaign")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while len(node_processes(str(PURSUIT_NODE))) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert len(node_processes(str(PURSUIT_NODE))) >= 2, "the workers' nodes did not start"
    time.sleep(1.0)
    process.send_signal(stop)
    process.wait(60)
    deadline = time.monotonic() + 30
    while node_processes(str(PURSUIT_NODE)) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert node_processes(str(PURSUIT_NODE)) == []
    assert shared_memory() - before == set()


@pytest.mark.slow
def test_a_bridge_failure_replays_and_regresses_for_a_node_command_one_names_or_trusts(tmp_path):
    out = tmp_path / "run"
    command = f"command={json.dumps(node_command(PURSUIT_NODE))}"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", 25, "--seed", 2, "--out", out, "--controller", "ros2",
        "--controller-param", command,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    episode = int(pd.read_parquet(out / "failures.parquet")["episode"].iloc[0])
    refused = hazardhunt("replay", out, "--episode", episode)
    assert refused.returncode == 2
    assert "names the plug-in 'ros2'" in refused.stderr
    # Naming ros2 again is not enough: the node command the run names is data, run only when
    # the user gives their own or trusts the file.
    named = hazardhunt("replay", out, "--episode", episode, "--controller", "ros2")
    assert named.returncode == 2
    assert "--controller-param command=..." in named.stderr
    assert "pure_pursuit_node.py" not in named.stderr
    replayed = hazardhunt(
        "replay", out, "--episode", episode, "--controller", "ros2", "--controller-param", command
    )
    assert replayed.returncode == 0, replayed.stderr
    assert "pure_pursuit_node.py" in replayed.stderr  # the command it starts is shown first
    assert "reproduced" in replayed.stdout
    cases = tmp_path / "cases"
    assert hazardhunt("export", out, "--out", cases).returncode == 0
    regressed = hazardhunt("regress", cases, "--json", "--trust-plugins")
    assert regressed.returncode == 1, regressed.stderr  # the same node fails them all again
    verdicts = {case["verdict"] for case in json.loads(regressed.stdout)["cases"]}
    assert verdicts == {"still fails"}


def test_new_sut_ros2_writes_a_node_a_map_a_scenario_and_a_campaign_that_loads(tmp_path):
    folder = tmp_path / "my_robot"
    done = hazardhunt("new-sut", folder, "--ros2")
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in folder.iterdir()) == [
        "README.md", "campaign.toml", "my_map.pgm", "my_map.yaml", "my_node.py",
        "my_scenario.toml",
    ]  # fmt: skip
    shipped = ROOT / "src" / "hazardhunt" / "scenarios" / "shopfloor.pgm"
    assert (folder / "my_map.pgm").read_bytes() == shipped.read_bytes()
    campaign = load_campaign(folder / "campaign.toml")
    assert campaign.controller.path == "ros2"
    command = shlex.split(campaign.controller.params["command"])
    assert command == [sys.executable, str(folder.resolve() / "my_node.py")]
    node = (folder / "my_node.py").read_text()
    assert "import hazardhunt" not in node
    assert "from hazardhunt" not in node  # plain rclpy and standard messages
    assert node_processes(str(folder)) == []


@pytest.mark.slow
def test_the_campaign_new_sut_ros2_writes_runs_as_written(tmp_path):
    folder = tmp_path / "my_robot"
    assert hazardhunt("new-sut", folder, "--ros2").returncode == 0
    done = hazardhunt("campaign", folder / "campaign.toml", "--out", tmp_path / "results")
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "results" / "summary.json").read_text())
    assert summary, summary
    runs = sorted((tmp_path / "results" / "runs").iterdir())
    assert len(runs) == 2  # the two field settings
    for run in runs:
        episodes, _ = run_tables(run)
        assert len(episodes) == 20
        assert "sut_error" not in set(episodes["outcome"])
    assert node_processes(str(folder)) == []
