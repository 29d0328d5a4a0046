"""A campaign on a Ray cluster of two nodes: runs execute on both and come back as the local
executor's.

Both nodes run on this machine, each its own ``ray start --block`` process with its own temporary
directory, ports and one CPU, and are stopped by ending those processes: ``ray stop`` would stop
every Ray node on the machine, other users' too.
"""

from __future__ import annotations

import contextlib
import json
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.campaign.test_campaign import GRID, assert_same_runs
from tests.helpers import hazardhunt

RAY = Path(sys.executable).parent / "ray"

AGENT_PORTS = (
    "--node-manager-port",
    "--object-manager-port",
    "--dashboard-agent-listen-port",
    "--dashboard-agent-grpc-port",
    "--runtime-env-agent-port",
    "--metrics-export-port",
)
"""Ports each node would otherwise take at fixed defaults (two nodes on one machine collide)."""


def free_ports(count: int) -> list[int]:
    """``count`` distinct free ports (every probe stays bound until all are chosen, so the
    system cannot hand out one port twice)."""
    with contextlib.ExitStack() as stack:
        probes = [stack.enter_context(socket.socket()) for _ in range(count)]
        for probe in probes:
            probe.bind(("", 0))
        return [int(probe.getsockname()[1]) for probe in probes]


def free_port() -> int:
    return free_ports(1)[0]


def start_node(temp_dir: Path, *options: str) -> subprocess.Popen[bytes]:
    """A Ray node with one CPU, running until its process ends; returns once the node is up."""
    taken = set(options)  # the head's --port is chosen before
    chosen = [port for port in free_ports(2 * len(AGENT_PORTS)) if str(port) not in taken]
    pairs = zip(AGENT_PORTS, chosen[: len(AGENT_PORTS)], strict=True)
    ports = [value for option, port in pairs for value in (option, str(port))]
    command = [str(RAY), "start", "--block", "--num-cpus", "1", "--temp-dir", str(temp_dir)]
    with (temp_dir.parent / f"{temp_dir.name}.log").open("wb") as log:
        process = subprocess.Popen(
            [*command, "--disable-usage-stats", *ports, *options],
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    address_file = temp_dir / "ray_current_cluster"  # written once the node is up
    deadline = time.monotonic() + 120
    while not address_file.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            stop_node(process)
            tail = (temp_dir.parent / f"{temp_dir.name}.log").read_text()[-2000:]
            raise RuntimeError(f"the Ray node did not start:\n{tail}")
        time.sleep(0.2)
    return process


def stop_node(process: subprocess.Popen[bytes]) -> None:
    """End a node: its process drains it and stops the node's own processes on SIGTERM."""
    process.terminate()
    try:
        process.wait(timeout=60)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


@contextlib.contextmanager
def two_node_cluster(monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """A head and a worker node on this machine; yields the head's address."""
    # A token of its own: whatever token or setting this machine has, the three processes
    # (two nodes and the campaign) agree.
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    monkeypatch.setenv("RAY_AUTH_TOKEN", secrets.token_hex(32))
    # Short paths: Ray's sockets live under the temporary directory (at most 107 characters).
    root = Path(tempfile.mkdtemp(prefix="hh-ray-", dir="/tmp"))
    nodes: list[subprocess.Popen[bytes]] = []
    try:
        head_options = ("--head", "--port", str(free_port()), "--include-dashboard", "false")
        nodes.append(start_node(root / "head", *head_options))
        address = (root / "head" / "ray_current_cluster").read_text().strip()
        nodes.append(start_node(root / "worker", "--address", address))
        yield address
    finally:
        for node in reversed(nodes):
            stop_node(node)
        shutil.rmtree(root, ignore_errors=True)


@pytest.mark.slow
def test_a_campaign_on_two_ray_nodes_runs_on_both_and_records_what_local_records(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    file = tmp_path / "grid.toml"
    file.write_text(GRID)
    reference = tmp_path / "local"
    local = hazardhunt("campaign", file, "--out", reference, "--workers", "2")
    assert local.returncode == 0, local.stderr
    out = tmp_path / "ray"
    with two_node_cluster(monkeypatch) as address:
        result = hazardhunt(
            "campaign", file, "--out", out, "--executor", "ray", "--address", address, timeout=600
        )
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs_complete"] == summary["runs_total"] == 4
    assert len({entry["ray_node"] for entry in summary["runs"]}) == 2  # both nodes ran runs
    assert_same_runs(out, reference)
    assert not list((out / "runs").glob(".*"))
