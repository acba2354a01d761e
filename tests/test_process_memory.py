"""Collections between a diagnosis's candidates: only what the diagnosis made is walked, and
no garbage escapes them."""

from __future__ import annotations

import gc
import weakref

from cpas_ocp.process_memory import new_objects_only, release_freed_memory


class _Node:
    """An object that can sit in a reference cycle (freed only by a collection)."""

    def __init__(self) -> None:
        self.other: _Node | None = None


def _cycle() -> weakref.ref:
    a, b = _Node(), _Node()
    a.other, b.other = b, a
    return weakref.ref(a)


def test_garbage_made_within_is_collected_and_older_objects_come_back() -> None:
    before = _cycle()  # garbage already when the block begins
    kept = _Node()
    with new_objects_only():
        assert before() is None  # collected, not frozen with the live objects
        assert gc.get_freeze_count() > 0
        with new_objects_only():  # a nested block changes nothing
            inside = _cycle()
            release_freed_memory()
            assert inside() is None
        assert gc.get_freeze_count() > 0
        kept.other = _Node()
        kept.other.other = kept.other  # a cycle hung from an older, frozen object
    assert gc.get_freeze_count() == 0
    orphan = weakref.ref(kept.other)
    kept.other = None
    release_freed_memory()
    assert orphan() is None  # the older objects are collected again after the block
