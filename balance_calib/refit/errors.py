"""The refit's one error and how its messages name the campaign's files."""

from __future__ import annotations

from typing import Sequence


class RefitError(ValueError):
    """The refit cannot be done with these inputs; the message says which file and why."""


def named(text: str, sources: Sequence[str]) -> str:
    """The message with the campaign's files in front, unless it names them already."""
    if not sources or any(str(s) in text for s in sources):
        return text
    return f'{where(sources)}: {text}'


def where(sources: Sequence[str]) -> str:
    """The campaign's files, comma-separated ('campaign' when there are none)."""
    return ', '.join(str(s) for s in sources) if sources else 'campaign'
