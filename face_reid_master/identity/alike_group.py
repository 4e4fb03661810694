"""One person's posterior summed over their learned faces: a decision that a split person still reaches.

A person sometimes owns two learned faces (the second was learned while a track of theirs held the first, or
their own face was too far from one new photo). A track of that person then splits its posterior between both
faces, and neither passes the threshold although the person is plain. Faces whose stored features are closer
than the same-person distance the caller's ``alike`` applies count as one person: their posteriors are added
up, and the most likely of them that is free is given. Pure Python.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Set

__all__ = ["Alike", "alike_group"]

Alike = Callable[[int, list[int]], list[bool]]  # alike(face, others): which of others are face's person
_BATCH = 8  # candidate faces compared with the top face per batched distance computation


def alike_group(post: Mapping[int, float], top: int, free: Set[int], alike: Alike | None,
                threshold: float) -> tuple[int, float]:
    """The most likely free face of ``top``'s person and that person's summed posterior.

    ``post``: face id -> posterior, 0 = "someone else" (new person); ``top``: the most likely face. The top face
    alone when ``alike`` is None or "someone else" already holds at least ``1 - threshold``. Candidates are checked
    most likely first, in small batches, and no further once even all the rest could not lift the sum above
    ``threshold`` (the verdict is then "undecided" whatever they are)."""
    if alike is None or post.get(0, 0.0) >= 1.0 - threshold:
        return top, post[top]
    floor = (1.0 - threshold) / len(post)  # faces below this cannot change the verdict
    candidates = sorted(((q, g) for g, q in post.items() if g not in (0, top) and q > floor), reverse=True)
    group, total = [top], post[top]
    remaining = sum(q for q, _ in candidates)
    for k in range(0, len(candidates), _BATCH):
        if total + remaining <= threshold:
            break
        batch = candidates[k:k + _BATCH]
        for (q, g), same in zip(batch, alike(top, [g for _, g in batch]), strict=True):
            remaining -= q
            if same:
                group.append(g)
                total += q
    given = max((g for g in group if g in free), key=post.__getitem__, default=top)
    return given, float(total)
