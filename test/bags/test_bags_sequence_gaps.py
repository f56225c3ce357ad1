"""bags/sequence_gaps.py: holes counted from a writer's publication sequence numbers."""

from balance_calib.bags.sequence_gaps import SequenceGaps


def feed(gaps, topic, numbers):
    for number in numbers:
        gaps.seen(topic, number)


def test_one_writer_skipping_numbers_counts_once_the_graph_confirms_it_alone():
    gaps = SequenceGaps()
    gaps.single_writer('/balance/raw', True)
    feed(gaps, '/balance/raw', (1, 2, 3, 7, 8))
    assert gaps.missing == {}  # tentative until the next look at the graph
    assert gaps.single_writer('/balance/raw', True) == 3
    feed(gaps, '/balance/raw', (20,))
    assert gaps.single_writer('/balance/raw', True) == 11
    assert gaps.single_writer('/balance/raw', True) == 0
    assert gaps.missing == {'/balance/raw': 14}


def test_the_first_sample_seen_is_not_a_hole_whatever_its_number():
    """A recorder started mid-run sees a writer at 5000: nothing was lost to it."""
    gaps = SequenceGaps()
    gaps.single_writer('/balance/raw', True)
    feed(gaps, '/balance/raw', (5000, 5001))
    gaps.close()
    assert gaps.missing == {}


def test_a_second_writer_already_far_ahead_is_not_taken_for_a_hole():
    """Writer B joins at 100 while A is at 5; two of B's samples come before A's next one."""
    gaps = SequenceGaps()
    gaps.single_writer('/t', True)
    feed(gaps, '/t', (4, 5, 100, 101))  # looks like 94 lost ...
    assert gaps.single_writer('/t', False) == 0  # ... but the graph shows two writers
    feed(gaps, '/t', (6, 102, 7))
    gaps.single_writer('/t', True)  # one left (B): counting again from its next sample
    feed(gaps, '/t', (103, 104, 108))
    gaps.close()
    assert gaps.missing == {'/t': 3}


def test_a_step_back_between_two_looks_drops_the_gaps_before_it():
    gaps = SequenceGaps()
    gaps.single_writer('/t', True)
    feed(gaps, '/t', (500, 600, 1))  # a jump, then a second writer (or a restart) at 1
    assert gaps.single_writer('/t', True) == 0  # not counting until a look finds one writer
    feed(gaps, '/t', (2, 4))
    assert gaps.single_writer('/t', True) == 1
    assert gaps.missing == {'/t': 1}


def test_topics_are_counted_apart_unnumbered_samples_ignored_and_the_tail_counted_at_close():
    gaps = SequenceGaps()
    gaps.single_writer('/a', True)
    gaps.single_writer('/b', True)
    feed(gaps, '/a', (1, 3))
    feed(gaps, '/b', (10, 11, None, 15))
    feed(gaps, '/c', (1, 99))  # never said to have a single writer
    gaps.close()
    assert gaps.missing == {'/a': 1, '/b': 3}
