"""Holes in a recorded topic, counted from its writer's own numbering.

DDS reports a sample lost when a reliable writer could no longer repair it, but not a sample a
keep-last reader queue overwrote before the recorder took it. Every sample carries its writer's
publication sequence number (1, 2, 3 … per writer), so on a topic with one writer a jump from n
to n + k means k − 1 samples that never reached the bag, whatever lost them.

With several writers the numbers interleave and say nothing, and a sample does not say which
writer sent it (rclpy gives no publisher GID). So gaps are held as tentative until the recorder's
next look at the graph: still one writer, and no step back in between (a second writer, or one
restarted at 1), and they count; otherwise they are dropped and counting resumes on the next
look that finds a single writer.

Pure: the recorder node feeds it; tests drive it with made-up numbers.
"""

from __future__ import annotations


class SequenceGaps:
    """Missing publication sequence numbers per topic, while the topic has a single writer."""

    def __init__(self) -> None:
        self.missing: dict[str, int] = {}
        self._last: dict[str, int | None] = {}
        self._tentative: dict[str, int] = {}
        self._counting: set[str] = set()

    def single_writer(self, topic: str, single: bool) -> int:
        """What the graph says now. Returns the gaps this confirms (0 if none)."""
        tentative = self._tentative.pop(topic, 0)
        if not single:
            self._counting.discard(topic)
            return 0
        if topic not in self._counting:  # (again) one writer: count from its next sample on
            self._counting.add(topic)
            self._last[topic] = None
            return 0
        if tentative:
            self.missing[topic] = self.missing.get(topic, 0) + tentative
        return tentative

    def seen(self, topic: str, sequence: int | None) -> None:
        """One sample's publication sequence number (None: the middleware gave none)."""
        if topic not in self._counting or sequence is None:
            return
        last, self._last[topic] = self._last.get(topic), sequence
        if last is None:
            return
        if sequence <= last:  # another writer, or this one restarted: the numbers say nothing
            self._counting.discard(topic)
            self._tentative.pop(topic, None)
            return
        if sequence > last + 1:
            self._tentative[topic] = self._tentative.get(topic, 0) + sequence - last - 1

    def close(self) -> None:
        """The recording ends: the gaps since the last look at the graph count as they are."""
        for topic in list(self._tentative):
            if topic in self._counting:
                self.single_writer(topic, True)
        self._tentative.clear()
