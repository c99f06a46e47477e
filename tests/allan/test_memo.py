"""The bounded memo: values remembered, forgotten together when the count or the byte budget is reached."""

import numpy as np

from companion.allan.memo import BoundedMemo, release_free_memory


def test_byte_budget_forgets_everything_when_reached():
    memo = BoundedMemo(100, read_only=True, max_bytes=3 * 800)
    for k in range(3):
        memo.get(k, lambda: np.zeros(100))
    assert len(memo) == 3
    assert memo.get(0, lambda: np.ones(100))[0] == 0.0  # remembered: not computed again
    v = memo.get(3, lambda: np.ones(100))  # a fourth value would pass the budget: the others go
    assert len(memo) == 1 and v[0] == 1.0 and not v.flags.writeable


def test_count_bound_and_release():
    memo = BoundedMemo(2)
    memo.get("a", lambda: 1)
    memo.get("b", lambda: 2)
    memo.get("c", lambda: 3)
    assert len(memo) == 1
    release_free_memory()  # a no-op where the C library has no malloc_trim; never raises
