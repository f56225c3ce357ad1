"""Node processes for the launchless scripts and the ROS tests: a console script with parameters
on a chosen ROS domain, its output in log files, stopped with SIGINT (then killed if it hangs).
"""

from __future__ import annotations

import os
from pathlib import Path
import random
import signal
import subprocess
import time

MAX_DOMAIN_ID = 232  # ROS 2's limit on Linux (the DDS port formula)


def story_domain_id() -> int:
    """The shell's ROS_DOMAIN_ID when it is set (a story runs where the user asked), else a random
    domain 1-99 (a lone demo keeps clear of domain 0's other nodes). ValueError, one line, for a
    ROS_DOMAIN_ID that is not a whole number 0..232.
    """
    text = os.environ.get('ROS_DOMAIN_ID', '').strip()
    if not text:
        return random.randint(1, 99)
    try:
        domain = int(text)
    except ValueError:
        domain = -1
    if not 0 <= domain <= MAX_DOMAIN_ID:
        raise ValueError(
            f'ROS_DOMAIN_ID={text!r}: not a domain id (a whole number 0..{MAX_DOMAIN_ID})'
        )
    return domain


def ros_args(parameters: dict) -> list[str]:
    args = ['--ros-args']
    for name, value in parameters.items():
        if isinstance(value, bool):
            value = 'true' if value else 'false'
        elif isinstance(value, (list, tuple)):
            value = '[' + ','.join(f"'{v}'" for v in value) + ']'
        elif value == '':
            value = "''"  # an empty string must be spelled as YAML
        args += ['-p', f'{name}:={value}']
    return args


class NodeProcess:
    """A node's console script as a subprocess with its own log files."""

    def __init__(
        self,
        executable: str,
        domain_id: int,
        log_dir: Path,
        parameters: dict | None = None,
        extra_args: list[str] | None = None,
    ):
        self.name = Path(executable).name  # an absolute path names its log files by its base name
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
        log_dir.mkdir(parents=True, exist_ok=True)
        # bridge_publisher.1.out, bridge_publisher.2.out, ... in the order the runs started
        run = 1
        while True:
            try:  # exclusive creation: two processes started at once never share a log
                self._stdout = open(log_dir / f'{self.name}.{run}.out', 'x')
                break
            except FileExistsError:
                run += 1
        self.stdout_path = log_dir / f'{self.name}.{run}.out'
        self.stderr_path = log_dir / f'{self.name}.{run}.err'
        self._stderr = open(self.stderr_path, 'w')
        self.process = subprocess.Popen(
            [executable] + ros_args(parameters or {}) + (extra_args or []),
            env=env,
            stdout=self._stdout,
            stderr=self._stderr,
            start_new_session=True,
        )

    def output(self) -> str:
        if not self._stdout.closed:
            self._stdout.flush()
            self._stderr.flush()
        return self.stdout_path.read_text() + self.stderr_path.read_text()

    def wait(self, timeout_s: float) -> int:
        return self.process.wait(timeout=timeout_s)

    def stop(self, timeout_s: float = 5.0) -> int | None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=timeout_s)
        self._stdout.close()
        self._stderr.close()
        return self.process.returncode


def wait_until(predicate, timeout: float, what: str):
    """Poll predicate every 50 ms; TimeoutError naming `what` after timeout s."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(0.05)


def close_graph(processes, executor, node, context) -> None:
    """The end of a launchless story: its node processes (last started first), then its
    in-process node.
    """
    import rclpy

    for process in reversed(processes):
        process.stop()
    executor.shutdown(timeout_sec=2.0)
    node.destroy_node()
    rclpy.try_shutdown(context=context)
