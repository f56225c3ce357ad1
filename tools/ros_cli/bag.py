"""`ros bag info|record|play`: a bag's summary read from its MCAP files (no DDS), recording with
balance_recorder, playing with bridge_publisher's replay.
"""

from __future__ import annotations

import math
from pathlib import Path
import signal
import subprocess
import time

from balance_calib.bags.errors import BagError
from balance_calib.bags.opening import open_bag
from balance_calib.launchless.processes import ros_args

from .errors import ToolError


def opened(bag: str | Path):
    """The bag's MCAP files (balance_calib.bags.opening, as every reader of bags opens them)."""
    try:
        return open_bag(bag)
    except BagError as error:
        raise ToolError(str(error)) from None


def bag_info(args) -> int:
    print(format_bag_info(Path(args.bag)))
    return 0


def _run_node(command: list[str], duration: float = 0.0) -> int:
    """A node executable in the foreground, its output ours; Ctrl-C, SIGTERM or the end of
    duration (s, 0 = none) stop it with SIGINT, as a terminal's Ctrl-C would. Its exit status.
    """

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    # its own session: a terminal's Ctrl-C reaches it once, through us
    child = subprocess.Popen(command, start_new_session=True)
    try:
        end = time.monotonic() + duration if duration > 0 else None
        while child.poll() is None and (end is None or time.monotonic() < end):
            time.sleep(0.05)
    except KeyboardInterrupt:
        pass
    finally:
        if child.poll() is None:
            child.send_signal(signal.SIGINT)
            try:
                child.wait(timeout=15.0)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
        signal.signal(signal.SIGTERM, previous)
    return child.returncode


def bag_record(args) -> int:
    parameters = {'output': args.out}
    if args.topics:
        parameters['topics'] = list(args.topics)
    if args.duration is not None and not args.duration > 0:
        raise ToolError(f'--duration {args.duration:g}: give a positive number of seconds')
    status = _run_node(['balance_recorder', *ros_args(parameters)], args.duration or 0.0)
    return 0 if status in (0, -signal.SIGINT) else status


def bag_play(args) -> int:
    if not args.rate > 0 or not math.isfinite(args.rate):
        raise ToolError(f'--rate {args.rate:g}: give a positive factor')
    for bag in args.bags:
        if ',' in bag:
            raise ToolError(
                f'{bag}: a bag path with a comma cannot be replayed '
                "(bridge_publisher's bag parameter separates paths by commas)"
            )
        opened(bag)  # ToolError now, rather than bridge_publisher's failure later
    parameters = {
        'mode': 'replay',
        'bag': ','.join(args.bags),
        'speed': args.rate,
        'loop': args.loop,
        'exit_when_done': not args.loop,
        'wait_for_subscribers': args.wait_for_subscribers,
    }
    return _run_node(['bridge_publisher', *ros_args(parameters), '-r', '__node:=bag_player'])


def format_bag_info(path: Path) -> str:
    """ros2 bag info's layout for a rosbag2 MCAP directory or a bare .mcap file (reads the MCAP
    summaries).
    """
    from mcap.reader import make_reader

    files = opened(path).files
    topics: dict[str, list] = {}
    start, end, total, size, compression = None, None, 0, 0, set()
    for file in files:
        size += file.stat().st_size
        with open(file, 'rb') as stream:
            try:
                summary = make_reader(stream).get_summary()
            except Exception as err:  # the mcap library raises its own types for damaged files
                raise ToolError(f'{file}: cannot read its MCAP summary ({err})') from None
        if summary is None or summary.statistics is None:
            raise ToolError(f'{file}: no MCAP summary (unfinished recording?)')
        stats = summary.statistics
        if stats.message_count:
            start = (
                stats.message_start_time if start is None else min(start, stats.message_start_time)
            )
            end = stats.message_end_time if end is None else max(end, stats.message_end_time)
        total += stats.message_count
        for chunk in summary.chunk_indexes:
            compression.add(chunk.compression or 'none')
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            entry = topics.setdefault(channel.topic, [schema.name if schema else '?', 0])
            entry[1] += stats.channel_message_counts.get(channel_id, 0)
    duration = (end - start) / 1e9 if start is not None else 0.0
    lines = [
        f'Files:             {", ".join(f.name for f in files)}',
        f'Bag size:          {size / 1e6:.1f} MB',
        'Storage id:        mcap',
        f'Duration:          {duration:.3f}s',
    ]
    if start is not None:
        lines += [f'Start:             {_stamp(start)}', f'End:               {_stamp(end)}']
    lines += [
        f'Messages:          {total}',
        f'Chunk compression: {", ".join(sorted(compression)) or "none"}',
        'Topic information:',
    ]
    width = max((len(t) for t in topics), default=0)
    for topic, (type_name, count) in sorted(topics.items()):
        lines.append(
            f'  Topic: {topic:{width}} | Type: {type_name} | Count: {count} | Serialization '
            'Format: cdr'
        )
    return '\n'.join(lines)


def _stamp(nanoseconds: int) -> str:
    import datetime as dt

    moment = dt.datetime.fromtimestamp(nanoseconds / 1e9, dt.timezone.utc)
    return f'{moment:%b %d %Y %H:%M:%S.%f}'[:-3] + f' ({nanoseconds / 1e9:.9f})'
