"""Diversity beyond the taxonomy: trajectory features, clusters against classes, and the
classes found against episodes, on hand-made failures whose structure is known."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hazardhunt.analysis import diversity, tables
from hazardhunt.analysis.results import Results
from hazardhunt.spec.episode import TrajectorySample

SAMPLE_PERIOD = 0.2


def side_contact(
    side: int, robot_speed: float, contact_time: float, along: float
) -> list[TrajectorySample]:
    """The robot drives east along y = 0; the human walks straight at its side (north of it:
    ``side`` 1, left; south: -1, right) at 1 m/s and touches it at ``contact_time``, ``along``
    m ahead of its centre."""
    times = [*np.arange(0.0, contact_time, SAMPLE_PERIOD), contact_time]
    contact_x = robot_speed * contact_time + along
    return [
        TrajectorySample(
            time=float(t),
            human_x=contact_x,
            human_y=side * (0.5 + (contact_time - t)),
            human_heading=-side * math.pi / 2,
            robot_x=robot_speed * t,
            robot_y=0.0,
            robot_heading=0.0,
            robot_speed=robot_speed,
        )
        for t in times
    ]


def results_of(tmp_path: Path, failures: list[tuple[str, str, list[TrajectorySample]]]) -> Results:
    """A one-run result whose failures are ``(class, contact face, trajectory)``."""
    run = tmp_path / "run"
    (run / "trajectories").mkdir(parents=True)
    keys = {
        "run_id": "r",
        "scenario": "crossing",
        "field": "none",
        "tester": "random",
        "seed": 0,
    }
    rows = [
        {"episode": e} | s.as_row()
        for e, (_, _, trajectory) in enumerate(failures)
        for s in trajectory
    ]
    pd.DataFrame(rows).to_parquet(run / "trajectories" / "part-00000.parquet")
    table = pd.DataFrame(
        [
            keys | {"episode": e, "class": name, "contact_face": face}
            for e, (name, face, _) in enumerate(failures)
        ]
    )
    runs = pd.DataFrame([keys | {"directory": str(run), "episodes": len(failures)}])
    empty = pd.DataFrame()
    return Results(tmp_path, runs, episodes=empty, failures=table, loitering=empty)


def two_groups(tmp_path: Path, size: int = 8) -> Results:
    """``size`` fast contacts on the left, as many slow ones on the right, a little scatter."""
    random = np.random.default_rng(3)
    failures = []
    for side, speed, name, face in (
        (1, 1.0, "left/moving", "left"),
        (-1, 0.3, "right/moving", "right"),
    ):
        for _ in range(size):
            trajectory = side_contact(
                side, speed, 3.0 + random.uniform(0.0, 0.15), random.uniform(-0.1, 0.1)
            )
            failures.append((name, face, trajectory))
    return results_of(tmp_path, failures)


@pytest.mark.parametrize("method", ["hdbscan", "kmeans"])
def test_two_groups_of_side_contacts_are_two_clusters_matching_the_classes(tmp_path, method):
    features = diversity.failure_features(two_groups(tmp_path))
    clustered = diversity.cluster_failures(features, method=method)
    counts = diversity.clusters_against_classes(features, method=method)
    assert counts[["failures", "classes", "clusters", "unclustered"]].values.tolist() == [
        [16, 2, 2, 0]
    ]
    assert counts.loc[0, "adjusted Rand index"] == pytest.approx(1.0)
    contingency = diversity.contingency_table(clustered).set_index("class")
    cells = contingency[["cluster 0", "cluster 1"]].astype(int)
    assert sorted(cells.values.tolist()) == [[0, 8], [8, 0]]
    assert (
        clustered["cluster"].tolist()
        == diversity.cluster_failures(features, method=method)["cluster"].tolist()
    )


def test_a_class_the_data_splits_shows_in_two_clusters(tmp_path):
    results = two_groups(tmp_path)
    results.failures["class"] = "side"  # a taxonomy that does not tell the sides apart
    features = diversity.failure_features(results)
    counts = diversity.clusters_against_classes(features)
    assert counts.loc[0, ["classes", "clusters"]].tolist() == [1, 2]
    contingency = diversity.contingency_table(diversity.cluster_failures(features))
    assert contingency[["cluster 0", "cluster 1"]].values.tolist() == [[8, 8]]


def test_bearings_either_side_of_behind_are_close(tmp_path):
    behind = side_contact(1, 1.0, 3.0, along=-0.55)  # the human level with the rear face
    mirrored = side_contact(-1, 1.0, 3.0, along=-0.55)
    for trajectory in (behind, mirrored):  # nudge the human round to just behind the robot
        last = trajectory[-1]
        trajectory[-1] = dataclasses.replace(last, human_y=math.copysign(0.02, last.human_y))
    one, other = (
        diversity.contact_features(pd.DataFrame([s.as_row() for s in t]), "rear")
        for t in (behind, mirrored)
    )
    bearings = [math.atan2(f["bearing_sin"], f["bearing_cos"]) for f in (one, other)]
    assert bearings[0] == pytest.approx(math.pi - math.atan2(0.02, 0.55), abs=1e-9)
    assert bearings[1] == pytest.approx(-bearings[0], abs=1e-9)
    gap = math.dist(
        (one["bearing_cos"], one["bearing_sin"]), (other["bearing_cos"], other["bearing_sin"])
    )
    assert gap < 0.1  # as near as the angle between them, not 2 pi apart


def test_velocity_and_bearing_are_in_the_robots_frame():
    # The robot drives north at 1 m/s; the human, east of it, walks west at 1 m/s.
    samples = pd.DataFrame(
        [
            TrajectorySample(t, 1.0 - t, 2.0, math.pi, 0.0, 1.5 + t, math.pi / 2, 1.0).as_row()
            for t in (0.0, 0.2, 0.5)
        ]
    )
    features = diversity.contact_features(samples, "right")
    assert features["bearing_cos"] == pytest.approx(0.0, abs=1e-9)
    assert features["bearing_sin"] == pytest.approx(-1.0)  # on the robot's right
    assert features["relative_forward_velocity"] == pytest.approx(-1.0)
    assert features["relative_left_velocity"] == pytest.approx(1.0)
    assert features["face_right"] == 1.0
    assert features["face_left"] == features["face_front"] == features["face_rear"] == 0.0


@pytest.mark.parametrize(
    ("stops", "expected"),
    [
        ([False] * 6, (0.0, 0.0, 0.0)),
        ([False, True, True, False, False, False], (1.0, 0.0, 0.5)),
        ([False, True, False, True, True, True], (2.0, 1.0, 0.0)),
    ],
)
def test_the_safety_layers_history_at_contact(stops, expected):
    times = [0.0, 0.2, 0.4, 0.6, 0.8, 1.1]
    samples = pd.DataFrame(
        [
            TrajectorySample(t, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5, emergency_stop=stop).as_row()
            for t, stop in zip(times, stops, strict=True)
        ]
    )
    features = diversity.contact_features(samples, "front")
    found = (
        features["stops_before_contact"],
        features["stop_holding"],
        features["time_since_release"],
    )
    assert found == pytest.approx(expected)
    assert features["time_to_contact"] == pytest.approx(1.1)


def test_the_smallest_cluster_grows_with_the_failures():
    sizes = [diversity.default_min_cluster_size(n) for n in (6, 20, 100, 1000, 10_000)]
    assert sizes == [3, 5, 5, 16, 50]


@pytest.mark.parametrize("method", ["pca", "tsne"])
def test_the_embedding_is_two_dimensional_and_the_same_every_time(tmp_path, method):
    features = diversity.failure_features(two_groups(tmp_path))
    first = diversity.embed(features, method=method)
    again = diversity.embed(features, method=method)
    assert first[["x", "y"]].notna().all().all()
    assert first["x"].std() > 0
    assert first[["x", "y"]].equals(again[["x", "y"]])


FAILURES = pd.DataFrame(
    [
        ("random", 0, 3, "c1"),
        ("random", 0, 5, "c1"),
        ("random", 0, 9, "c2"),
        ("random", 1, 2, "c2"),
        ("random", 1, 7, "other"),
        ("random", 1, 12, "c3"),
        ("ppo-max", 0, 0, "c1"),
    ],
    columns=["tester", "seed", "episode", "class"],
).assign(scenario="crossing", field="2m")
RUNS = pd.DataFrame(
    [(tester, seed, 20) for tester in ("random", "ppo-max") for seed in (0, 1)],
    columns=["tester", "seed", "episodes"],
).assign(scenario="crossing", field="2m")


def test_the_classes_found_against_episodes_step_up_at_each_first_find():
    curves = tables.class_discovery_curves(tables.class_discovery(FAILURES), RUNS)
    steps = {
        tester: list(zip(group["episodes"], group["classes found"], strict=True))
        for tester, group in curves.groupby("tester")
    }
    # c2 first in episode 2 (seed 1), c1 in 3 (seed 0), c3 in 12; other is not counted.
    assert steps["random"] == [(0, 0), (3, 1), (4, 2), (13, 3), (20, 3)]
    assert steps["ppo-max"] == [(0, 0), (1, 1), (20, 1)]


def test_the_first_found_table_gives_each_testers_earliest_episode():
    table = tables.class_first_found(tables.class_discovery(FAILURES))
    assert table["class"].tolist() == ["c1", "c2", "other", "c3"]
    assert table["random"].tolist() == [3, 2, 7, 12]
    assert table["ppo-max"].tolist() == [0, "", "", ""]


def test_the_cluster_counts_have_a_row_per_case_and_tester_and_one_for_all(tmp_path):
    features = diversity.failure_features(two_groups(tmp_path))
    features.loc[8:, "scenario"] = "head-on"  # the right-side group is another case
    features.loc[features["episode"] % 2 == 1, "tester"] = "ppo-max"
    counts = diversity.clusters_against_classes(features)
    rows = counts[["scenario", "tester", "failures", "classes", "clusters"]].values.tolist()
    assert rows[:3] == [
        ["all", "all", 16, 2, 2],
        ["all", "random", 8, 2, 2],  # registered testers in the registry's order
        ["all", "ppo-max", 8, 2, 2],
    ]
    assert [row[:3] for row in rows[3:]] == [
        ["crossing", "all", 8],
        ["crossing", "random", 4],
        ["crossing", "ppo-max", 4],
        ["head-on", "all", 8],
        ["head-on", "random", 4],
        ["head-on", "ppo-max", 4],
    ]


@pytest.mark.parametrize("method", ["hdbscan", "kmeans"])
def test_one_failure_found_again_and_again_is_one_cluster(tmp_path, method):
    trajectory = side_contact(1, 1.0, 3.0, 0.0)
    features = diversity.failure_features(
        results_of(tmp_path, [("left/moving", "left", trajectory)] * 10)
    )
    counts = diversity.clusters_against_classes(features, method=method)
    assert counts.loc[0, ["clusters", "unclustered"]].tolist() == [1, 0]
    assert (diversity.embed(features)[["x", "y"]] == 0.0).all().all()


@pytest.mark.parametrize("method", ["hdbscan", "kmeans"])
def test_failures_beyond_the_sample_join_the_cluster_of_their_nearest_neighbour(tmp_path, method):
    features = diversity.failure_features(two_groups(tmp_path, size=20))
    points = diversity.standardised(features)
    labels = diversity.cluster_labels(points, method, most=20)
    assert (labels >= 0).all()
    cells = pd.crosstab(features["class"], labels).values.tolist()
    assert sorted(cells) == [[0, 20], [20, 0]]
