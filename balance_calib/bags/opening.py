"""Open a bag: a rosbag2 directory (metadata.yaml + *.mcap) or a bare .mcap file -> its MCAP files.

The one place that decides what a bag path is, for every reader of bags: read_bags (the
calibration and the reduction), bridge_publisher's replay (simulation/replay.py) and the
development tools' `ros bag info|play` (tools/ros_cli). A wrong path is one BagError naming it.
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
import stat

import yaml

from balance_calib.bags.errors import BagError
from balance_calib.bags.mcap_scan import check_regular_file, McapDamage

_METADATA_MAX_BYTES = 16 * 1024 * 1024


@dataclass(frozen=True)
class OpenedBag:
    """The MCAP files of one bag, in the order its metadata.yaml lists them."""

    source: Path
    files: tuple[Path, ...]
    # a directory without metadata.yaml yet: its recorder is still at work (or was killed), and
    # its .mcap files are read up to what is on disk
    unfinished: bool = False


def open_bag(source: str | os.PathLike) -> OpenedBag:
    """The MCAP files of a bag: a bare .mcap, those metadata.yaml lists in a rosbag2 directory, or
    (a bag still being recorded: no metadata.yaml yet) the directory's .mcap files. BagError
    naming the path when it is missing or not a bag.
    """
    source = Path(source)
    if not source.exists() and not source.is_symlink():
        raise BagError(f'{source}: no such bag directory or .mcap file')
    try:
        mode = source.stat().st_mode
    except OSError as error:
        raise BagError(f'{source}: cannot read ({error.strerror})') from None
    if not stat.S_ISDIR(mode):
        if source.suffix != '.mcap':
            raise BagError(f'{source}: not a bag (expected a rosbag2 directory or an .mcap file)')
        return OpenedBag(source, (source,))
    metadata = source / 'metadata.yaml'
    if not metadata.exists():
        # rosbag2 (and balance_recorder) write metadata.yaml when the recording stops: until
        # then the directory's .mcap files are the bag
        inside = tuple(sorted(source.glob('*.mcap')))
        if not inside:
            raise BagError(f'{source}: not a rosbag2 bag (no metadata.yaml and no .mcap file)')
        return OpenedBag(source, inside, unfinished=True)
    names = _listed_files(metadata) or sorted(p.name for p in source.glob('*.mcap'))
    if not names:
        raise BagError(f'{source}: its metadata.yaml lists no files')
    files = tuple(source / name for name in names)
    for path in files:
        if not path.exists():
            raise BagError(f'{path}: listed in {metadata} but missing')
    return OpenedBag(source, files)


def _listed_files(metadata: Path) -> list[str]:
    """The relative_file_paths of a rosbag2 metadata.yaml (MCAP storage only)."""
    try:
        check_regular_file(metadata)
    except McapDamage as error:
        raise BagError(str(error)) from None
    if metadata.stat().st_size > _METADATA_MAX_BYTES:
        raise BagError(f'{metadata}: {metadata.stat().st_size} bytes, too large for bag metadata')
    try:
        info = _yaml(metadata.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
        storage = info.get('storage_identifier', 'mcap')
        names = [str(p) for p in (info.get('relative_file_paths') or [])]
    except (
        yaml.YAMLError,
        UnicodeDecodeError,
        KeyError,
        TypeError,
        AttributeError,
        OSError,
    ) as error:
        raise BagError(
            f'{metadata}: not rosbag2 metadata ({type(error).__name__}: '
            f'{str(error).splitlines()[0] if str(error) else ""})'
        ) from None
    if storage != 'mcap':
        raise BagError(f'{metadata}: storage {storage!r}; only MCAP bags are read')
    return names


def _yaml(text: str):
    """The document of a YAML text, read by libyaml's safe loader when built in (~10x faster
    than the pure-Python one, same result); the pure-Python loader's yaml.YAMLError (and its
    wording) when the text does not parse.
    """
    loader = getattr(yaml, 'CSafeLoader', None)
    if loader is not None:
        try:
            return yaml.load(text, Loader=loader)
        except yaml.YAMLError:
            pass  # the error as the pure-Python loader words it
    return yaml.safe_load(text)
