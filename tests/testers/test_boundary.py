"""The boundary arm: bisection from a failure towards a nearby episode that did not fail."""

import numpy as np
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.testers.boundary import BoundaryParams, BoundarySampler
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.mirror import failure_cell
from hazardhunt.testers.search import SearchContext
from hazardhunt.testers.spaces import DecisionSpace


@pytest.fixture(scope="module")
def sim():
    return Simulation.build("head-on", "none", controller=PursuitController())


def play(sim, plans):
    return [plan.space.play(sim, plan.decisions, False) for plan in plans]


def test_the_boundary_waits_for_a_failure_then_closes_in_on_where_failing_stops(sim):
    sampler = BoundarySampler(BoundaryParams(batch_size=1, steps=6), SearchContext(sim, seed=3))
    assert sampler.ask() == []  # nothing to start from
    attack = Plan(DecisionSpace("aim"), np.tile([1.0, 0.5, -1.0], (sim.horizon, 1)))
    [failure] = play(sim, [attack])
    assert failure.outcome == "failure"
    sampler.observe([attack], [failure])

    played = []
    while sampler.lines_done == 0:
        plans = sampler.ask()
        results = play(sim, plans)
        sampler.tell(plans, results)
        failed = [result.outcome == "failure" for result in results]
        played += [(plan.decisions, fail) for plan, fail in zip(plans, failed, strict=True)]
        assert len(played) < 30, "the line never ended"
    # Perturbations of the failure until one does not fail, then six midpoints.
    first_safe = next(i for i, (_, failed) in enumerate(played) if not failed)
    assert len(played) == first_safe + 1 + 6
    inside = np.asarray(failure.actions, dtype=np.float64)
    inside = np.concatenate([inside, np.repeat(inside[-1:], sim.horizon - len(inside), axis=0)])
    outside = played[first_safe][0]
    gap = np.abs(inside - outside).max()
    for decisions, failed in played[first_safe + 1 :]:
        np.testing.assert_allclose(decisions, 0.5 * (inside + outside))
        inside, outside = (decisions, outside) if failed else (inside, decisions)
    # The last failure and the last safe episode are 1/64 as far apart as the first pair.
    assert np.abs(inside - outside).max() == pytest.approx(gap / 2**6)


def test_the_boundary_starts_its_lines_in_the_least_explored_cell_first(sim):
    sampler = BoundarySampler(BoundaryParams(batch_size=2), SearchContext(sim, seed=0))
    left = Plan(DecisionSpace("aim"), np.tile([1.0, 0.5, -1.0], (sim.horizon, 1)))
    right = Plan(DecisionSpace("aim"), np.tile([1.0, -0.5, -1.0], (sim.horizon, 1)))
    results = play(sim, [left, left, right])
    assert all(result.outcome == "failure" for result in results)
    sampler.observe([left, left, right], results)
    assert len(sampler.ask()) == 2
    assert sorted(line.cell for line in sampler.lines) == sorted(sampler.failures)


def test_with_saved_ends_every_second_line_bisects_towards_an_episode_the_field_saved():
    sim = Simulation.build("crossing", "1.25m", controller=PursuitController())
    failing = Plan(DecisionSpace("aim"), np.tile([1.0, 0.6, -1.0], (sim.horizon, 1)))
    saved = Plan(DecisionSpace("aim"), np.tile([1.0, 0.5, -1.0], (sim.horizon, 1)))
    results = play(sim, [failing, saved])
    assert [result.outcome for result in results] == ["failure", "safe_contact"]
    assert results[1].summary.emergency_stops > 0  # the field stopped the robot in time
    params = BoundaryParams(batch_size=2, saved_ends=True)
    sampler = BoundarySampler(params, SearchContext(sim, seed=0))
    sampler.observe([failing, saved], results)

    first, second = sampler.ask()
    pad = sampler._padded
    inside, outside = pad(results[0].actions), pad(results[1].actions)
    assert not np.allclose(first.decisions, 0.5 * (inside + outside))  # a perturbation
    np.testing.assert_allclose(second.decisions, 0.5 * (inside + outside))  # a midpoint


def test_saved_ends_change_nothing_where_no_safety_layer_ever_stops_the_robot(sim):
    attack = Plan(DecisionSpace("aim"), np.tile([1.0, 0.5, -1.0], (sim.horizon, 1)))
    near = Plan(DecisionSpace("aim"), np.tile([1.0, 0.4, -1.0], (sim.horizon, 1)))
    results = play(sim, [attack, near])
    assert results[0].outcome == "failure"
    assert all(result.summary.emergency_stops == 0 for result in results)  # no field

    def lines(saved_ends):
        sampler = BoundarySampler(
            BoundaryParams(batch_size=2, saved_ends=saved_ends), SearchContext(sim, seed=5)
        )
        sampler.observe([attack, near], results)
        asked = []
        for _ in range(6):
            plans = sampler.ask()
            sampler.tell(plans, play(sim, plans))
            asked += [plan.decisions for plan in plans]
        return asked

    plain = lines(False)
    assert len(plain) >= 12
    for with_ends, without in zip(lines(True), plain, strict=True):
        np.testing.assert_array_equal(with_ends, without)


@pytest.mark.parametrize("cell_border", [False, True])
def test_with_cell_border_a_failure_of_another_cell_is_a_far_end(sim, cell_border):
    left = Plan(DecisionSpace("aim"), np.tile([1.0, 0.5, -1.0], (sim.horizon, 1)))
    right = Plan(DecisionSpace("aim"), np.tile([1.0, -0.5, -1.0], (sim.horizon, 1)))
    on_left, on_right = play(sim, [left, right])
    assert on_left.outcome == on_right.outcome == "failure"
    moving = MechanismClassifier(robot=sim.robot_params).moving_speed
    assert failure_cell(on_left.summary, moving) != failure_cell(on_right.summary, moving)
    params = BoundaryParams(batch_size=1, cell_border=cell_border)
    sampler = BoundarySampler(params, SearchContext(sim, seed=0))
    sampler.observe([left], [on_left])
    [perturbed] = sampler.ask()
    [line] = sampler.lines
    # The perturbation is told it failed as the right-hand attack did: in another cell.
    sampler.tell([perturbed], [on_right])
    [after] = sampler.ask()
    inside = sampler._padded(on_left.actions)
    midpoint = 0.5 * (inside + perturbed.decisions)
    if cell_border:  # the other mechanism's failure ended the search: bisection begins
        np.testing.assert_allclose(after.decisions, midpoint)
        assert line.outside is not None
    else:  # a failure is a failure: the line goes on looking for an episode that does not fail
        assert line.outside is None
        assert not np.allclose(after.decisions, midpoint)
