"""`kept_workers`: the parallel maps inside the block share their processes, and a failure costs only them."""

from __future__ import annotations

import os

import pytest

from gymnast.envs.parallel import kept_workers, parallel_map


def _pid(item: int) -> tuple[int, int]:
    return item, os.getpid()


def _square(item: int) -> int:
    return item * item


def _fail_on_three(item: int) -> int:
    if item == 3:
        raise ValueError("three")
    return item


def _pids(fn=_pid, items=range(6)) -> tuple[list[int], set[int]]:
    results = sorted(parallel_map(fn, items, workers=2))
    return [item for item, _ in results], {pid for _, pid in results}


@pytest.mark.slow  # starting spawned workers takes seconds
def test_maps_inside_the_block_share_processes_and_stop_with_it():
    with kept_workers(2):
        items, first = _pids()
        assert items == list(range(6)) and len(first) == 2 and os.getpid() not in first
        assert sorted(parallel_map(_square, range(4), workers=2)) == [0, 1, 4, 9]  # another function, same processes
        assert _pids()[1] == first
        with kept_workers(2):  # nested: still the outer block's
            assert _pids()[1] == first
    assert not first & _pids()[1]  # outside the block: processes of its own


@pytest.mark.slow
def test_a_failed_map_gives_its_error_and_the_next_one_starts_afresh():
    with kept_workers(2):
        before = _pids()[1]
        with pytest.raises(ValueError, match="three"):
            list(parallel_map(_fail_on_three, range(6), workers=2))
        items, after = _pids()
        assert items == list(range(6)) and not before & after
