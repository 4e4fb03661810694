"""alike_group: one person's posterior summed over their learned faces."""

from __future__ import annotations

from face_reid_master.identity.alike_group import alike_group

SAME = {1: {2}, 2: {1}}  # faces 1 and 2 are one person; 3 is someone else


def alike(face: int, others: list[int]) -> list[bool]:
    return [g in SAME.get(face, set()) for g in others]


def test_a_split_person_is_decided_on_the_sum_and_given_the_likelier_free_face() -> None:
    post = {0: 0.02, 1: 0.50, 2: 0.46, 3: 0.02}
    assert alike_group(post, 1, {1, 2, 3}, alike, 0.95) == (1, 0.96)
    assert alike_group(post, 1, {2, 3}, alike, 0.95) == (2, 0.96)  # face 1 is held: her other face is given


def test_someone_else_is_not_added_and_no_alike_test_means_the_top_face_alone() -> None:
    post = {0: 0.02, 1: 0.50, 3: 0.48}
    assert alike_group(post, 1, {1, 3}, alike, 0.95) == (1, 0.50)
    assert alike_group({0: 0.02, 1: 0.50, 2: 0.48}, 1, {1, 2}, None, 0.95) == (1, 0.50)


def test_no_sum_when_new_person_already_holds_too_much_or_the_rest_cannot_pass() -> None:
    calls: list[list[int]] = []

    def counting(face: int, others: list[int]) -> list[bool]:
        calls.append(others)
        return alike(face, others)

    assert alike_group({0: 0.06, 1: 0.50, 2: 0.44}, 1, {1, 2}, counting, 0.95) == (1, 0.50)
    assert alike_group({0: 0.04, 1: 0.50, 2: 0.30, 3: 0.16}, 1, {1, 2, 3}, counting, 0.95)[0] == 1
    assert calls == [[2, 3]]  # one batched comparison, and none for the first call
