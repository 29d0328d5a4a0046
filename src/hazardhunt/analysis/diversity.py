"""Diversity beyond the taxonomy (SPEC 10): failures clustered on features of their trajectories.

A failure's class is hazardhunt's own reading of its mechanism, so counting classes favours
whatever that taxonomy happens to separate. Here every failure becomes a vector of numbers read
from its stored trajectory at and before the contact (:data:`FEATURE_NAMES`), standardised, and
clustered with scikit-learn: HDBSCAN by default, k-means with the number of clusters of the best
silhouette as the alternative. Comparing the clusters with the classes (counts, the adjusted
Rand index, a contingency table) shows whether the classes split what the data splits.

Everything is deterministic: HDBSCAN has no randomness, and k-means, the silhouette's sample
and t-SNE take a fixed ``random_state``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from sklearn.cluster import HDBSCAN, KMeans
from sklearn.decomposition import PCA
from sklearn.manifold import TSNE
from sklearn.metrics import adjusted_rand_score, silhouette_score
from sklearn.neighbors import NearestNeighbors
from sklearn.preprocessing import StandardScaler

from hazardhunt.analysis.results import RUN_KEYS, Results
from hazardhunt.spec.failure_classes import FACES
from hazardhunt.testers.registry import sort_testers

FEATURE_NAMES = (
    "bearing_cos",
    "bearing_sin",
    *(f"face_{face}" for face in FACES),
    "relative_forward_velocity",
    "relative_left_velocity",
    "robot_speed",
    "stops_before_contact",
    "stop_holding",
    "time_since_release",
    "time_to_contact",
    "contact_x",
    "contact_y",
)
"""The features of a failure, in order:

- ``bearing_cos``, ``bearing_sin``: where the human's centre was around the robot's body at
  the contact (the bearing in the robot's frame: 0 ahead, pi/2 on the left), as its cosine and
  sine so that bearings just either side of +-pi (behind) lie close together;
- ``face_front`` ... ``face_rear``: the robot's face touched, one-hot (all 0 without a face);
- ``relative_forward_velocity``, ``relative_left_velocity``: the human's velocity relative to
  the robot's centre, in the robot's frame at the contact, in m/s (the human's from its last
  two positions);
- ``robot_speed``: the robot's speed at the contact, in m/s;
- ``stops_before_contact``: emergency stops the safety layer triggered up to the contact, as
  seen in the samples (every 0.2 s);
- ``stop_holding``: 1 if the stop held at the contact (the robot braked), else 0;
- ``time_since_release``: time from the release of the last stop to the contact, in s (0
  while the stop holds, and without a released stop: then the time to contact says it all);
- ``time_to_contact``: the simulated time of the contact, in s;
- ``contact_x``, ``contact_y``: the human's position on the floor at the contact, in m.
"""

TRAJECTORY_FEATURE_COLUMNS = (
    "episode",
    "time",
    "human_x",
    "human_y",
    "robot_x",
    "robot_y",
    "robot_heading",
    "robot_speed",
    "emergency_stop",
)
"""The stored trajectory columns the features are read from."""

ClusterMethod = Literal["hdbscan", "kmeans"]
EmbeddingMethod = Literal["pca", "tsne"]

CASE = ("scenario", "field")
"""What the report clusters separately: each (scenario, field) case, testers and seeds pooled,
as Table I counts the classes of a case."""

ALL = "all"
"""Stands for every scenario, field or tester in a row of :func:`clusters_against_classes`."""

FEWEST_TO_SPLIT = 4
"""Fewer failures than this form one cluster: too few to tell groups apart."""

MOST_CLUSTERED = 5000
"""Above this many failures, a fixed random sample of this many is clustered and every other
failure joins the cluster of its nearest sampled failure (HDBSCAN takes about 40 s for 30,000
failures, and its time grows faster than their number)."""


# ------------------------------------------------------------------ features
def trajectory_features(stored: pd.DataFrame, faces: pd.Series) -> pd.DataFrame:
    """The features (:data:`FEATURE_NAMES`) of failures, from their stored trajectories.

    Args:
        stored: Trajectories keyed by ``episode`` (and the columns of
            :class:`~hazardhunt.spec.episode.TrajectorySample`), each in time order with the
            contact last, as a run's ``trajectories/`` holds them.
        faces: The robot's face touched (``front``, ``left``, ``right``, ``rear``; None without
            one), by episode.

    Returns:
        One row per episode of ``stored`` (the index), in order of first appearance.
    """
    episode = stored["episode"]
    contact = stored.groupby(episode, sort=False).tail(1).set_index("episode")
    end = stored.groupby(episode, sort=False)["time"].transform("last")
    earlier = stored[stored["time"] < end]
    previous = earlier.groupby("episode", sort=False).tail(1).set_index("episode")
    previous = previous.reindex(contact.index)
    elapsed = contact["time"] - previous["time"]
    human_vx = ((contact["human_x"] - previous["human_x"]) / elapsed).fillna(0.0)
    human_vy = ((contact["human_y"] - previous["human_y"]) / elapsed).fillna(0.0)
    cos, sin = np.cos(contact["robot_heading"]), np.sin(contact["robot_heading"])
    speed = contact["robot_speed"]
    forward, left = _robot_frame(
        contact["human_x"] - contact["robot_x"], contact["human_y"] - contact["robot_y"], cos, sin
    )
    relative_forward, relative_left = _robot_frame(
        human_vx - speed * cos, human_vy - speed * sin, cos, sin
    )
    bearing = np.arctan2(left, forward)
    stop = stored["emergency_stop"].astype(bool)
    before = stop.groupby(episode, sort=False).shift(1, fill_value=False).astype(bool)
    onsets = (stop & ~before).groupby(episode, sort=False).sum()
    released_at = stored["time"].where(~stop & before).groupby(episode, sort=False).max()
    holding = contact["emergency_stop"].astype(bool)
    face = faces.reindex(contact.index)
    return pd.DataFrame(
        {
            "bearing_cos": np.cos(bearing),
            "bearing_sin": np.sin(bearing),
            **{f"face_{name}": (face == name).astype(float) for name in FACES},
            "relative_forward_velocity": relative_forward,
            "relative_left_velocity": relative_left,
            "robot_speed": speed,
            "stops_before_contact": onsets.astype(float),
            "stop_holding": holding.astype(float),
            "time_since_release": (contact["time"] - released_at).where(~holding).fillna(0.0),
            "time_to_contact": contact["time"],
            "contact_x": contact["human_x"],
            "contact_y": contact["human_y"],
        },
        index=contact.index,
    ).astype(float)


def _robot_frame(
    east: pd.Series, north: pd.Series, cos: pd.Series, sin: pd.Series
) -> tuple[pd.Series, pd.Series]:
    """A world-frame vector in the frame of a robot heading (cos, sin): (forward, left)."""
    return cos * east + sin * north, -sin * east + cos * north


def contact_features(samples: pd.DataFrame, contact_face: str | None) -> dict[str, float]:
    """The features (:data:`FEATURE_NAMES`) of one failure, from its trajectory (the columns of
    :class:`~hazardhunt.spec.episode.TrajectorySample`, in time order, the contact last)."""
    one = trajectory_features(samples.assign(episode=0), pd.Series({0: contact_face}))
    return {name: float(value) for name, value in one.iloc[0].items()}


def failure_features(results: Results) -> pd.DataFrame:
    """The features of every failure whose trajectory is stored.

    Returns:
        One row per failure, in the order of ``results.failures``: the run's keys, ``episode``,
        ``class`` and :data:`FEATURE_NAMES`.
    """
    parts = []
    for run_id, group in results.failures.groupby("run_id", sort=False):
        folder = results.run_directory(str(run_id)) / "trajectories"
        if not any(folder.glob("*.parquet")):
            continue  # a run recorded without trajectories
        stored = pd.read_parquet(folder, columns=list(TRAJECTORY_FEATURE_COLUMNS))
        stored = stored.sort_values(["episode", "time"], kind="stable")
        faces = group.set_index("episode")["contact_face"]
        features = trajectory_features(stored, faces.where(faces.notna(), None))
        keys = group[[*RUN_KEYS, "episode", "class"]]
        parts.append(keys.join(features, on="episode", how="inner"))
    if not parts:
        return pd.DataFrame(columns=[*RUN_KEYS, "episode", "class", *FEATURE_NAMES])
    return pd.concat(parts).sort_index().reset_index(drop=True)


def standardised(features: pd.DataFrame) -> NDArray[np.float64]:
    """The features as a matrix, each column shifted to mean 0 and scaled to variance 1 (a
    constant column stays 0)."""
    values = np.asarray(features[list(FEATURE_NAMES)], dtype=np.float64)
    if len(values) == 0:
        return values
    return np.asarray(StandardScaler().fit_transform(values), dtype=np.float64)


# ------------------------------------------------------------------ clustering
def default_min_cluster_size(failures: int) -> int:
    """HDBSCAN's smallest cluster for this many failures: 5, or half the square root of the
    failures beyond 100 (16 for 1,000, 50 for 10,000), at most half of them, at least 2."""
    return max(2, min(failures // 2, max(5, round(math.sqrt(failures) / 2))))


def cluster_labels(
    points: NDArray[np.float64],
    method: ClusterMethod = "hdbscan",
    min_cluster_size: int | None = None,
    max_clusters: int = 10,
    random_state: int = 0,
    most: int = MOST_CLUSTERED,
) -> NDArray[np.int64]:
    """The cluster of every point: 0 for the largest cluster, 1 for the next, ...; -1 for a
    point HDBSCAN leaves unclustered (noise).

    Args:
        points: One row per failure (standardised features).
        method: ``hdbscan``, or ``kmeans`` with the number of clusters (2 to
            ``max_clusters``) of the best silhouette.
        min_cluster_size: HDBSCAN's smallest cluster (default:
            :func:`default_min_cluster_size` of the points clustered).
        max_clusters: The most clusters k-means tries.
        random_state: Seeds k-means, the silhouette's sample and the sample of ``most``.
        most: Cluster a sample of this many points at most; every other point joins the
            cluster of its nearest sampled point.
    """
    count = len(points)
    if count < FEWEST_TO_SPLIT or _distinct(points) < 2:
        return np.zeros(count, dtype=np.int64)
    chosen = np.arange(count)
    if count > most:
        chosen = np.sort(np.random.default_rng(random_state).choice(count, most, replace=False))
    sample = points[chosen]
    if method == "hdbscan":
        smallest = min_cluster_size or default_min_cluster_size(len(sample))
        labels = HDBSCAN(min_cluster_size=smallest, copy=True).fit_predict(sample)
    elif method == "kmeans":
        labels = _best_kmeans(sample, max_clusters, random_state)
    else:
        raise ValueError(f"unknown clustering method {method!r}: hdbscan or kmeans")
    labels = np.asarray(labels, dtype=np.int64)
    if len(sample) < count:
        nearest = NearestNeighbors(n_neighbors=1).fit(sample).kneighbors(points)[1][:, 0]
        labels = labels[nearest]
    return _by_size(labels)


def _best_kmeans(
    points: NDArray[np.float64], max_clusters: int, random_state: int
) -> NDArray[np.int64]:
    """k-means with the k of the best silhouette (one cluster if no k splits the points)."""
    best_score, best = -math.inf, np.zeros(len(points), dtype=np.int64)
    sample = len(points) if len(points) <= 2000 else 2000  # the silhouette is quadratic
    for k in range(2, min(max_clusters, len(points) - 1, _distinct(points)) + 1):
        labels = KMeans(n_clusters=k, n_init=10, random_state=random_state).fit_predict(points)
        if len(np.unique(labels)) < 2:
            continue
        score = silhouette_score(points, labels, sample_size=sample, random_state=random_state)
        if score > best_score:
            best_score, best = float(score), np.asarray(labels, dtype=np.int64)
    return best


def _distinct(points: NDArray[np.float64]) -> int:
    """How many different points there are (failures can repeat one another exactly)."""
    return len(np.unique(points, axis=0))


def _by_size(labels: NDArray[np.int64]) -> NDArray[np.int64]:
    """Renumber clusters by size, largest first (ties: first seen first); -1 stays."""
    clustered = labels[labels >= 0]
    ids, first, sizes = np.unique(clustered, return_index=True, return_counts=True)
    order = sorted(range(len(ids)), key=lambda i: (-sizes[i], first[i]))
    mapping = {int(ids[i]): rank for rank, i in enumerate(order)}
    return np.array([mapping.get(int(label), -1) for label in labels], dtype=np.int64)


def cluster_failures(
    features: pd.DataFrame,
    by: Sequence[str] = CASE,
    method: ClusterMethod = "hdbscan",
    min_cluster_size: int | None = None,
) -> pd.DataFrame:
    """``features`` with a ``cluster`` column: each group of ``by`` (default: every (scenario,
    field) case; ``()``: all failures together) standardised and clustered on its own, so
    cluster ids are per group."""
    clusters = pd.Series(-1, index=features.index, dtype=np.int64)
    for _, group in _groups(features, by):
        points = standardised(group)
        clusters[group.index] = cluster_labels(points, method, min_cluster_size)
    return features.assign(cluster=clusters)


def _groups(features: pd.DataFrame, by: Sequence[str]) -> list[tuple[Any, pd.DataFrame]]:
    if not by:
        return [((), features)]
    return list(features.groupby(list(by), sort=True))


def clusters_against_classes(
    features: pd.DataFrame,
    method: ClusterMethod = "hdbscan",
    min_cluster_size: int | None = None,
) -> pd.DataFrame:
    """Clusters found beside classes found, per (scenario, field) case and tester.

    Each case is clustered on its own (testers and seeds pooled); a tester's row counts the
    clusters of its case its failures fall into. With more than one case, all failures are also
    clustered together (scenario and field ``all``). The adjusted Rand index compares the
    clusters with the classes over the clustered failures (noise left out): 1 when both split
    the failures alike, about 0 when they are unrelated.
    """
    cases = cluster_failures(features, CASE, method, min_cluster_size)
    rows = []
    if features[list(CASE)].drop_duplicates().shape[0] > 1:
        pooled = cluster_failures(features, (), method, min_cluster_size)
        rows += _count_rows(pooled, {"scenario": ALL, "field": ALL})
    for (scenario, field), group in cases.groupby(list(CASE), sort=True):
        rows += _count_rows(group, {"scenario": scenario, "field": field})
    columns = [
        "scenario",
        "field",
        "tester",
        "failures",
        "classes",
        "clusters",
        "unclustered",
        "adjusted Rand index",
    ]
    return pd.DataFrame(rows, columns=columns)


def _count_rows(clustered: pd.DataFrame, keys: dict[str, str]) -> list[dict[str, Any]]:
    """One row for all testers of ``clustered``, and one per tester if there are several."""
    rows = [_counts(clustered, keys | {"tester": ALL})]
    testers = sort_testers(clustered["tester"])
    if len(testers) > 1:
        rows += [
            _counts(clustered[clustered["tester"] == t], keys | {"tester": t}) for t in testers
        ]
    return rows


def _counts(clustered: pd.DataFrame, keys: dict[str, str]) -> dict[str, Any]:
    inside = clustered[clustered["cluster"] >= 0]
    agreement = (
        adjusted_rand_score(inside["class"], inside["cluster"]) if len(inside) > 1 else math.nan
    )
    return keys | {
        "failures": len(clustered),
        "classes": clustered["class"].nunique(),
        "clusters": inside["cluster"].nunique(),
        "unclustered": len(clustered) - len(inside),
        "adjusted Rand index": float(agreement),
    }


def contingency_table(clustered: pd.DataFrame) -> pd.DataFrame:
    """Failures of each class in each cluster, one row per (scenario, field, class) from the
    clusters of :func:`cluster_failures`: columns ``cluster 0``, ``cluster 1``, ... and
    ``unclustered`` (blank where a case has no such cluster). A class spread over clusters was
    split by the data; a cluster spread over classes was split by the taxonomy only."""
    if clustered.empty:
        return pd.DataFrame(columns=["scenario", "field", "class"])
    names = clustered["cluster"].map(lambda c: "unclustered" if c < 0 else f"cluster {c}")
    counts = pd.crosstab([clustered["scenario"], clustered["field"], clustered["class"]], names)
    present = [c for c in counts.columns if c != "unclustered"]
    ordered = sorted(present, key=lambda name: int(name.split()[1]))
    if "unclustered" in counts.columns:
        ordered.append("unclustered")
    table = counts[ordered].astype(object).reset_index().rename_axis(columns=None)
    for (scenario, field), group in table.groupby(list(CASE), sort=False):
        case = clustered[(clustered["scenario"] == scenario) & (clustered["field"] == field)]
        absent = [c for c in ordered if c not in set(names[case.index])]
        table.loc[group.index, absent] = ""
    return table


# ------------------------------------------------------------------ embedding
def embed(
    features: pd.DataFrame,
    by: Sequence[str] = CASE,
    method: EmbeddingMethod = "pca",
    random_state: int = 0,
) -> pd.DataFrame:
    """``features`` with ``x`` and ``y``: a 2-D embedding of each group's standardised
    features (PCA by default; t-SNE with ``method="tsne"``), for a picture."""
    coordinates = pd.DataFrame(0.0, index=features.index, columns=["x", "y"])
    for _, group in _groups(features, by):
        points = standardised(group)
        coordinates.loc[group.index, ["x", "y"]] = _embedding(points, method, random_state)
    return features.assign(x=coordinates["x"], y=coordinates["y"])


def _embedding(
    points: NDArray[np.float64], method: EmbeddingMethod, random_state: int
) -> NDArray[np.float64]:
    plane = np.zeros((len(points), 2))
    if len(points) < 2 or _distinct(points) < 2:
        return plane  # nothing to spread out (and t-SNE fails on it)
    if method == "pca":
        components = min(2, len(points))
        plane[:, :components] = PCA(components, random_state=random_state).fit_transform(points)
    elif method == "tsne":
        perplexity = min(30.0, (len(points) - 1) / 3)
        plane[:] = TSNE(
            2, perplexity=perplexity, init="pca", random_state=random_state
        ).fit_transform(points)
    else:
        raise ValueError(f"unknown embedding {method!r}: pca or tsne")
    return plane
