import numpy as np

from hazardhunt.sut.tracking import HumanTracker
from hazardhunt.world.floor import FloorMap

ZONE = np.array([[4.0, 4.0], [6.0, 4.0], [6.0, 6.0], [4.0, 6.0]])
FLOOR = FloorMap("empty", 10.0, 10.0, obstacles=(), blind_zones=(ZONE,))


def test_tracking_keeps_the_last_three_sightings():
    tracker = HumanTracker(FLOOR)
    for step in range(5):
        tracked = tracker.observe(0.2 * step, np.array([1.0 + step, 1.0]), 0.0)
    assert tracked is not None
    assert tracked.recent_positions[:, 0].tolist() == [3.0, 4.0, 5.0]
    assert tracked.recent_times.tolist() == [0.4, 0.6000000000000001, 0.8]


def test_a_blind_zone_hides_the_human_and_breaks_the_history():
    tracker = HumanTracker(FLOOR)
    tracker.observe(0.0, np.array([3.0, 5.0]), 0.0)
    tracker.observe(0.2, np.array([3.5, 5.0]), 0.0)
    assert tracker.observe(0.4, np.array([5.0, 5.0]), 0.0) is None
    tracked = tracker.observe(0.6, np.array([6.5, 5.0]), 0.0)
    assert tracked is not None
    assert len(tracked.recent_positions) == 1
