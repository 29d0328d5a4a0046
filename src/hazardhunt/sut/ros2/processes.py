"""The user's ROS 2 nodes as processes of the bridge's own: a ROS domain of their own, Fast DDS
over UDP on 127.0.0.1 only (discovery included; no shared memory), and nothing left behind when
they stop.

A domain is leased with an exclusive ``flock`` on a lock file per domain id in the temporary
directory, so that two bridges on one machine (two workers, two users' runs) never share one:
nodes of one domain see each other's topics.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shlex
import signal
import subprocess
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from hazardhunt.errors import HazardhuntError
from hazardhunt.processes import die_with_parent

DOMAIN_IDS = (*range(1, 102), *range(215, 233))
"""The ROS domain ids whose DDS ports do not collide with the ephemeral ports on Linux (the
ROS 2 documentation's safe ranges, 0-101 and 215-232; 0, the default every ROS install uses,
is left out)."""

FAST_DDS_PROFILE = """\
<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>hazardhunt_udp_localhost</transport_id>
        <type>UDPv4</type>
        <interfaceWhiteList>
          <address>127.0.0.1</address>
        </interfaceWhiteList>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="hazardhunt_udp_localhost" is_default_profile="true">
      <rtps>
        <userTransports>
          <transport_id>hazardhunt_udp_localhost</transport_id>
        </userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
        <builtin>
          <discovery_config>
            <leaseDuration><sec>5</sec></leaseDuration>
            <leaseAnnouncement><sec>1</sec></leaseAnnouncement>
          </discovery_config>
        </builtin>
      </rtps>
    </participant>
  </profiles>
</dds>
"""
"""Fast DDS's default participant profile for the bridge and its nodes: UDP on the loopback
interface only. Shared-memory transport stays off: a node killed with SIGKILL would leave its
segments in /dev/shm. A participant that vanishes without saying so (a killed node) is dropped
by its peers after 5 s, instead of Fast DDS's 20."""


class NodeStartError(HazardhuntError):
    """A node's command does not start."""


def state_directory() -> Path:
    """Where the domain locks and the Fast DDS profile live (made if missing)."""
    directory = Path(tempfile.gettempdir()) / f"hazardhunt-ros2-{os.getuid()}"
    directory.mkdir(mode=0o700, exist_ok=True)
    return directory


def profile_file() -> Path:
    """The Fast DDS profile file (:data:`FAST_DDS_PROFILE`), written once per machine user."""
    path = state_directory() / "fastdds-udp-localhost.xml"
    if not path.exists() or path.read_text(encoding="utf-8") != FAST_DDS_PROFILE:
        partial = path.with_name(f"{path.name}.{os.getpid()}.partial")
        partial.write_text(FAST_DDS_PROFILE, encoding="utf-8")
        partial.replace(path)
    return path


DOMAIN_COOLDOWN = 15.0
"""Time after its last use before a domain id is leased again, when another is free, in s:
longer than a killed participant lingers in its peers' discovery (the profile's lease
duration), so that a new node never sees the endpoints of the last one."""


class DomainLease:
    """One ROS domain id held for this process until :meth:`release`."""

    def __init__(self) -> None:
        """Lease the first free id that has rested :data:`DOMAIN_COOLDOWN` (any free one if
        none has), starting from one derived from the process id.

        Raises:
            HazardhuntError: Every id is in use on this machine.
        """
        self.directory = directory = state_directory()
        start = os.getpid() % len(DOMAIN_IDS)
        order = [
            DOMAIN_IDS[(start + offset) % len(DOMAIN_IDS)] for offset in range(len(DOMAIN_IDS))
        ]
        for rested in (True, False):
            for domain in order:
                descriptor = self._lock(domain, rested)
                if descriptor is not None:
                    self.domain_id = domain
                    self._descriptor: int | None = descriptor
                    self.touch()
                    return
        raise HazardhuntError(f"every ROS domain id is in use on this machine ({directory})")

    def _lock(self, domain: int, rested: bool) -> int | None:
        path = self.directory / f"domain-{domain}.lock"
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(descriptor)
            return None
        if rested and time.time() - os.fstat(descriptor).st_mtime < DOMAIN_COOLDOWN:
            os.close(descriptor)  # used a moment ago: its last nodes may linger in discovery
            return None
        return descriptor

    def touch(self) -> None:
        """Mark the id as in use now (its cool-down counts from its last use)."""
        if self._descriptor is not None:
            os.utime(self._descriptor)

    def release(self) -> None:
        """Give the id back (idempotent)."""
        if self._descriptor is not None:
            self.touch()
            os.close(self._descriptor)
            self._descriptor = None


def ros_environment(domain_id: int) -> dict[str, str]:
    """The variables that confine ROS 2 to ``domain_id`` on this machine, over UDP.

    Discovery is kept on this machine by the Fast DDS profile (UDP on 127.0.0.1), not by
    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``: with that, rmw_fastrtps adds shared-memory
    transport of its own, whose segments a killed node leaves in /dev/shm.
    """
    return {
        "ROS_DOMAIN_ID": str(domain_id),
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "FASTDDS_DEFAULT_PROFILES_FILE": str(profile_file()),
    }


OVERRIDDEN = (
    "ROS_AUTOMATIC_DISCOVERY_RANGE",
    "ROS_STATIC_PEERS",
    "ROS_LOCALHOST_ONLY",
    "FASTRTPS_DEFAULT_PROFILES_FILE",
    "FASTDDS_BUILTIN_TRANSPORTS",
)
"""Variables of the caller's environment that would change the transports or discovery the
profile sets: the bridge and its nodes run without them."""


def confined(environment: Mapping[str, str], domain_id: int) -> dict[str, str]:
    """``environment`` with :func:`ros_environment` in force and :data:`OVERRIDDEN` removed."""
    kept = {key: value for key, value in environment.items() if key not in OVERRIDDEN}
    return {**kept, **ros_environment(domain_id)}


class NodeProcess:
    """One of the user's nodes, running in a process group of its own."""

    def __init__(self, command: str, domain_id: int, grace: float) -> None:
        """Start ``command`` (a command line, split as a shell would, run without one) with
        ``--ros-args -p use_sim_time:=true`` appended.

        Args:
            command: The node's command line.
            domain_id: Its ROS domain.
            grace: Time it is given to exit on SIGINT before SIGKILL, in s.

        Raises:
            NodeStartError: The command does not start (no such program, not executable).
        """
        self.command = command
        self.grace = grace
        argv = [*shlex.split(command), "--ros-args", "-p", "use_sim_time:=true"]
        environment = confined(os.environ, domain_id)
        parent = os.getpid()
        try:
            self._process = subprocess.Popen(
                argv,
                env=environment,
                stdin=subprocess.DEVNULL,
                start_new_session=True,  # its own process group, away from the terminal's Ctrl-C
                preexec_fn=lambda: die_with_parent(parent),
            )
        except (OSError, ValueError, subprocess.SubprocessError) as error:
            raise NodeStartError(f"node command {command!r} does not start: {error}") from None

    def interrupt(self) -> None:
        """SIGINT to the node's process group, if it runs."""
        if self._process.poll() is None:
            _signal_group(self._process.pid, signal.SIGINT)

    def wait(self, seconds: float) -> None:
        """Wait up to ``seconds`` for the node to exit."""
        with contextlib.suppress(subprocess.TimeoutExpired):
            self._process.wait(max(seconds, 0.0))

    @property
    def exit_code(self) -> int | None:
        """The node's exit code, None while it runs."""
        return self._process.poll()

    def stop(self) -> None:
        """SIGINT to the node's process group, SIGKILL after the grace (idempotent)."""
        process = self._process
        if process.poll() is None:
            self.interrupt()
            self.wait(self.grace)
        # What the node started may outlive it in its group: kill the group in any case.
        _signal_group(process.pid, signal.SIGKILL)
        process.wait()


def _signal_group(group: int, signal_number: int) -> None:
    with contextlib.suppress(ProcessLookupError):  # the group is gone
        os.killpg(group, signal_number)


def stop_all(nodes: Sequence[NodeProcess]) -> None:
    """Stop ``nodes``, all at once: each gets SIGINT, then the grace, then SIGKILL."""
    for node in nodes:
        node.interrupt()
    deadline = time.monotonic() + max((node.grace for node in nodes), default=0.0)
    for node in nodes:
        node.wait(deadline - time.monotonic())
    for node in nodes:
        node.stop()
