"""Every node's main(): init, build the node, spin, report a refused start in one line, shut down.

The rclpy idiom (ros2/examples: `with rclpy.init(): node = ...; rclpy.spin(node)`), with what
our nodes add to it:

- a start-up refusal (a bad parameter, file or calibration) is one error line and exit status 1,
  never a traceback;
- a node that finishes on its own (bridge_publisher's campaign, virtual-daq's run) sets
  `node.done` and, when it failed, `node.failure`: main() waits on that future;
- Ctrl-C or SIGTERM is a normal stop (exit 0), also when the signal lands while spin() builds its
  wait set (it surfaces there as RCLError "context is not valid", ros2/ros2cli#854);
- the shutdown at the end tolerates a signal handler that shut the context down between
  rclpy's own `ok()` check and its `shutdown()` (RCLError "rcl_shutdown already called").
"""

from __future__ import annotations

from typing import Callable, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions


def run_node(
    name: str,
    make_node: Callable[[], Node],
    *,
    refused: tuple[type[Exception], ...] = (),
    refusal_prefix: str = '',
    args: Sequence[str] | None = None,
    signals: SignalHandlerOptions = SignalHandlerOptions.SIGINT,
    before_spin: Callable[[Node], None] | None = None,
    until_done: bool = False,
) -> int:
    """Run the node `make_node()` builds until it is done or stopped; the process's exit status.

    `refused`: the exceptions that mean "cannot start" (logged as one error line, after
    `refusal_prefix`, exit 1). With `until_done` the node's `done` future is spun until it
    completes; its `failure` text, if any, is logged and gives exit
    1. `before_spin` runs once the node exists.
    """
    rclpy.init(args=args, signal_handler_options=signals)
    node = None
    status = 0
    try:
        node = make_node()
        if before_spin is not None:
            before_spin(node)
        if not until_done:
            rclpy.spin(node)
        else:
            rclpy.spin_until_future_complete(node, node.done)  # type: ignore[attr-defined]
            failure = node.failure  # type: ignore[attr-defined]
            if failure:
                rclpy.logging.get_logger(name).error(str(failure))
                status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except refused as error:
        rclpy.logging.get_logger(name).error(f'{refusal_prefix}{error}')
        status = 1
    except RuntimeError:
        if rclpy.ok():  # not a signal during spin's wait-set setup: a real failure
            raise
    finally:
        if node is not None:
            node.destroy_node()
        shutdown()
    return status


def shutdown() -> None:
    """rclpy.try_shutdown(), but a context a signal handler shut down meanwhile is not an error."""
    try:
        rclpy.try_shutdown()
    except RuntimeError:  # RCLError: "rcl_shutdown already called on the given context"
        if rclpy.ok():
            raise
