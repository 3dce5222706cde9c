"""The patrol through navigation: the pose goals of a coverage route and how the patrol
moves on when navigation answers."""

from __future__ import annotations

import itertools
import math

import numpy as np

from services.semantic_map.nav_patrol import NavPatrol, patrol_goals
from services.semantic_map.patrol import Route


def _route() -> Route:
    a = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    b = np.array([[2.0, 0.0], [2.0, 1.0], [2.0, 2.0]])
    return Route([a[-1], b[-1]], [a, b])


def test_each_viewpoint_is_a_walk_facing_along_the_path_then_turns_round_the_circle() -> None:
    goals = patrol_goals(_route(), start_yaw=0.3, turns=3)
    assert len(goals) == 8
    walk, *turns = goals[:4]
    assert not walk.look and (walk.x, walk.y) == (2.0, 0.0)
    assert math.isclose(walk.yaw, 0.0, abs_tol=1e-9)  # along +x, the path's last stretch
    assert all(t.look and (t.x, t.y) == (2.0, 0.0) for t in turns)
    yaws = [walk.yaw] + [t.yaw for t in turns]
    steps = [math.remainder(b - a, math.tau) for a, b in itertools.pairwise(yaws)]
    assert np.allclose(steps, [2 * math.pi / 3] * 3)  # the full circle, one way
    assert math.isclose(goals[4].yaw, math.pi / 2)  # the second leg goes along +y
    assert [g.look for g in patrol_goals(_route(), 0.0, turns=0)] == [False, False]


def test_a_refused_or_failed_walk_skips_its_viewpoint_and_a_failed_turn_is_passed_over() -> None:
    p = NavPatrol(_route(), patrol_goals(_route(), 0.0, turns=3))
    p.sent("nav_1")
    p.finished(succeeded=True)
    assert p.current is not None and p.current.look and p.goal_id == ""
    p.sent("nav_2")
    p.finished(succeeded=False, reason="failed: blocked")
    assert p.index == 2 and p.skipped == 0  # the next turn, at the same viewpoint
    p.finished(True)
    p.finished(True)
    assert p.viewpoint == 2 and not p.current.look
    p.refused("invalid_goal: off the map")
    assert p.done and p.skipped == 1
    assert any("viewpoint 2 skipped" in line for line in p.log)


def test_the_patrol_counts_the_path_it_walked() -> None:
    p = NavPatrol(_route(), patrol_goals(_route(), 0.0))
    for x, y in [(0.0, 0.0), (3.0, 0.0), (3.0, 4.0)]:
        p.moved_to(x, y)
    assert math.isclose(p.travelled_m, 7.0)
