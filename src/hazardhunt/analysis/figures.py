"""The report's figures as PNG files, drawn with matplotlib's object API (no pyplot state)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle
from matplotlib.ticker import MaxNLocator

from hazardhunt.env.rendering import draw_floor
from hazardhunt.spec.descriptors import MEASURE_RANGES
from hazardhunt.testers.registry import colour_of, sort_testers
from hazardhunt.world.scenario import Scenario, load_scenario

FIELD_ORDER = ("none", "1.25m", "2m")


def _ordered_fields(values: pd.Series) -> list[str]:
    present = list(dict.fromkeys(values))
    return [f for f in FIELD_ORDER if f in present] + [f for f in present if f not in FIELD_ORDER]


def _save(figure: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    figure.savefig(path)
    return path


def failures_bar_chart(runs: pd.DataFrame, path: Path, log: bool = False) -> Path:
    """Mean failures per run by scenario and tester, one panel per field setting; the error bar
    is the standard deviation over seeds and the dots are the seeds. With ``log``, on a
    logarithmic axis (the error bar clipped at the axis' foot)."""
    fields = _ordered_fields(runs["field"])
    scenarios = sorted(runs["scenario"].unique())
    testers = sort_testers(runs["tester"])
    figure = Figure(figsize=(4.2 * len(fields), 3.6), dpi=100)
    width = 0.8 / len(testers)
    for column, field in enumerate(fields):
        ax = figure.add_subplot(1, len(fields), column + 1)
        for offset, tester in enumerate(testers):
            positions, means, spreads = [], [], []
            for index, scenario in enumerate(scenarios):
                seeds = runs[
                    (runs["field"] == field)
                    & (runs["scenario"] == scenario)
                    & (runs["tester"] == tester)
                ]["failures"]
                if seeds.empty:
                    continue
                position = index - 0.4 + width * (offset + 0.5)
                positions.append(position)
                means.append(seeds.mean())
                spreads.append(seeds.std(ddof=1) if len(seeds) > 1 else 0.0)
                ax.plot([position] * len(seeds), seeds, ".", color="black", markersize=3)
            if positions:
                ax.bar(positions, means, width, yerr=spreads, capsize=2, color=colour_of(tester))
        ax.set_xticks(range(len(scenarios)), scenarios)
        ax.set_title(f"field {field}")
        ax.set_ylabel("failures per run")
        if log:
            ax.set_yscale("log", nonpositive="clip")
        else:
            _count_axis(ax, runs.loc[runs["field"] == field, "failures"].max())
        if column == 0:  # every tester, whether or not this panel has its bars
            patches = [Rectangle((0, 0), 1, 1, color=colour_of(tester)) for tester in testers]
            ax.legend(patches, testers, fontsize=8)
    return _save(figure, path)


def _count_axis(ax: Axes, largest: float) -> None:
    """The y axis of counts whose largest is ``largest``: from zero, never below it; a panel
    that counted nothing says so (matplotlib would centre an axis from -0.04 to 0.04 on it)."""
    if largest > 0:
        ax.set_ylim(bottom=0)
    else:
        ax.set_ylim(0, 1)
        ax.text(0.5, 0.5, "no failures", transform=ax.transAxes, ha="center", color="grey")


def learning_curves_figure(curves: pd.DataFrame, path: Path) -> Path:
    """Failures per N episodes over the runs (the last column of
    :func:`~hazardhunt.analysis.tables.learning_curves`), one panel per field, one line per
    tester."""
    rate = str(curves.columns[-1])
    fields = _ordered_fields(curves["field"])
    figure = Figure(figsize=(4.2 * max(1, len(fields)), 3.4), dpi=100)
    for column, field in enumerate(fields):
        ax = figure.add_subplot(1, len(fields), column + 1)
        in_field = curves[curves["field"] == field]
        for tester in sort_testers(in_field["tester"]):
            group = in_field[in_field["tester"] == tester]
            ax.plot(
                group["episode"],
                group[rate],
                marker=".",
                color=colour_of(tester),
                label=tester,
            )
        ax.set_title(f"field {field}")
        ax.set_xlabel("episode")
        ax.set_ylabel(rate)
        ax.set_ylim(bottom=0)
        if column == 0:
            ax.legend(fontsize=8)
    return _save(figure, path)


def failure_heat_map(failures: pd.DataFrame, scenario: str | Scenario, path: Path) -> Path:
    """Where on the floor the human was at contact, one panel per tester, counted on a 0.5 m
    grid over the floor of ``scenario`` (a name or file, or the scenario itself)."""
    testers = sort_testers(failures["tester"]) or ["(none)"]
    floor_scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    floor = floor_scenario.floor
    edges_x = np.arange(0.0, floor.width + 0.5, 0.5)
    edges_y = np.arange(0.0, floor.height + 0.5, 0.5)
    counts = {
        tester: np.histogram2d(
            failures.loc[failures["tester"] == tester, "contact_x"],
            failures.loc[failures["tester"] == tester, "contact_y"],
            bins=(edges_x, edges_y),
        )[0]
        for tester in testers
    }
    most = max(1.0, *(float(c.max()) for c in counts.values()))
    figure = Figure(figsize=(4.0 * len(testers), 3.8), dpi=100)
    for column, tester in enumerate(testers):
        ax = figure.add_subplot(1, len(testers), column + 1)
        draw_floor(ax, floor_scenario)
        masked = np.ma.masked_equal(counts[tester].T, 0)
        mesh = ax.pcolormesh(
            edges_x, edges_y, masked, cmap="inferno_r", vmin=0, vmax=most, zorder=3
        )
        figure.colorbar(mesh, ax=ax, shrink=0.7, label="failures per 0.5 m cell")
        found = int(counts[tester].sum())
        ax.set_title(f"{tester}: {found} failure{'' if found == 1 else 's'}")
    return _save(figure, path)


def failure_rates_figure(rates: pd.DataFrame, path: Path) -> Path:
    """Failure rate per scenario, field and tester with its confidence interval."""
    labels = [
        f"{row.scenario} / {row.field} / {row.tester}" for row in rates.itertuples(index=False)
    ]
    figure = Figure(figsize=(6.5, 0.28 * len(rates) + 1.0), dpi=100)
    ax = figure.add_subplot()
    positions = np.arange(len(rates))[::-1]
    errors = np.vstack([rates["rate"] - rates["low"], rates["high"] - rates["rate"]])
    for position, row, low, high in zip(
        positions, rates.itertuples(index=False), errors[0], errors[1], strict=True
    ):
        ax.errorbar(
            100.0 * row.rate,
            position,
            xerr=[[100.0 * low], [100.0 * high]],
            fmt="o",
            color=colour_of(str(row.tester)),
            capsize=2,
            markersize=4,
        )
    ax.set_yticks(positions, labels, fontsize=7)
    ax.set_xlabel("failures per 100 episodes (95 % Clopper-Pearson interval)")
    ax.set_xlim(left=0)
    return _save(figure, path)


def robustness_figure(robustness: pd.DataFrame, path: Path) -> Path:
    """Each requirement's robustness over the episodes (one panel per requirement, one
    histogram per tester); left of the line at 0 the episodes violated it."""
    names = list(dict.fromkeys(robustness["requirement"]))
    figure = Figure(figsize=(4.2 * len(names), 3.2), dpi=100)
    for column, name in enumerate(names):
        ax = figure.add_subplot(1, len(names), column + 1)
        mine = robustness[robustness["requirement"] == name]
        edges = np.histogram_bin_edges(mine["robustness"], bins=30).tolist()
        for tester in sort_testers(mine["tester"]):
            values = mine.loc[mine["tester"] == tester, "robustness"]
            ax.hist(values, bins=edges, histtype="step", color=colour_of(tester), label=tester)
        ax.axvline(0.0, color="black", linewidth=0.8)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("robustness (below 0: violated)")
        ax.set_ylabel("episodes")
        ax.legend(fontsize=7)
    return _save(figure, path)


CLUSTER_MARKERS = "osD^v<>phP*X"
"""One marker per cluster id (cycled); unclustered failures are small crosses."""


def _case_panels(
    figure: Figure, frame: pd.DataFrame, width: float = 4.2, height: float = 3.4
) -> list[tuple[str, str, Axes]]:
    """One panel per (scenario, field) case of ``frame``: scenarios down, fields across."""
    scenarios = sorted(frame["scenario"].unique()) or ["(none)"]
    fields = _ordered_fields(frame["field"]) or ["(none)"]
    figure.set_size_inches(width * len(fields), height * len(scenarios))
    panels = []
    for row, scenario in enumerate(scenarios):
        for column, field in enumerate(fields):
            ax = figure.add_subplot(len(scenarios), len(fields), row * len(fields) + column + 1)
            ax.set_title(f"{scenario} / field {field}", fontsize=9)
            panels.append((scenario, field, ax))
    return panels


def class_discovery_figure(curves: pd.DataFrame, path: Path) -> Path:
    """Distinct classes found against episodes played, one step curve per tester, one panel
    per (scenario, field) case (``tables.class_discovery_curves``)."""
    figure = Figure(dpi=100)
    for scenario, field, ax in _case_panels(figure, curves):
        case = curves[(curves["scenario"] == scenario) & (curves["field"] == field)]
        for tester in sort_testers(case["tester"]):
            group = case[case["tester"] == tester]
            ax.step(
                group["episodes"],
                group["classes found"],
                where="post",
                color=colour_of(str(tester)),
                label=str(tester),
            )
        ax.set_xlabel("episodes played")
        ax.set_ylabel("classes found")
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        if not case.empty:
            ax.legend(fontsize=8, loc="lower right")
    return _save(figure, path)


def failure_clusters_figure(embedded: pd.DataFrame, path: Path, axis_name: str = "PCA") -> Path:
    """The failures of each (scenario, field) case in a 2-D embedding of their features
    (``diversity.embed``), coloured by class, one marker per cluster with its id at the
    cluster's median (``diversity.cluster_failures``)."""
    names = sorted(embedded["class"].unique())
    palette = colormaps["tab10" if len(names) <= 10 else "tab20"]
    colours = {name: palette(index % palette.N) for index, name in enumerate(names)}
    figure = Figure(dpi=100)
    for scenario, field, ax in _case_panels(figure, embedded, width=4.6, height=4.0):
        case = embedded[(embedded["scenario"] == scenario) & (embedded["field"] == field)]
        for cluster, points in case.groupby("cluster", sort=True):
            clustered = cluster >= 0
            ax.scatter(
                points["x"],
                points["y"],
                s=22 if clustered else 12,
                marker=CLUSTER_MARKERS[cluster % len(CLUSTER_MARKERS)] if clustered else "x",
                color=[colours[name] for name in points["class"]],
                alpha=0.75,
                linewidths=0.8,
            )
        for cluster, points in case[case["cluster"] >= 0].groupby("cluster", sort=True):
            ax.text(
                points["x"].median(),
                points["y"].median(),
                str(cluster),
                fontsize=10,
                fontweight="bold",
                ha="center",
                va="center",
                bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "alpha": 0.7},
            )
        classes = _count(case["class"].nunique(), "class", "classes")
        clusters = _count(case.loc[case["cluster"] >= 0, "cluster"].nunique(), "cluster")
        ax.set_title(f"{scenario} / field {field}: {classes}, {clusters}", fontsize=9)
        ax.set_xlabel(f"{axis_name} 1")
        ax.set_ylabel(f"{axis_name} 2")
        if not case.empty:
            handles = [
                Line2D([], [], marker="o", linestyle="", color=colours[name], label=str(name))
                for name in sorted(case["class"].unique())
            ]
            ax.legend(handles=handles, fontsize=6, loc="best", title="class", title_fontsize=7)
    return _save(figure, path)


def _count(number: int, one: str, many: str = "") -> str:
    return f"{number} {one if number == 1 else many or one + 's'}"


ARCHIVE_AXES: dict[str, tuple[str, int]] = {
    "bearing": ("bearing around the robot (deg; 0 ahead, 90 left)", 12),
    "robot_speed": ("robot speed (m/s)", 6),
    "emergency_stop": ("safety layer (0 never stopped, 1 holding, 2 released)", 3),
    "route_share": ("robot's share of its route (0 start, 1 goal)", 5),
    "human_speed": ("human speed (m/s)", 6),
}
"""Per archive measure: its axis label and its cells; the range drawn is the measure's
:data:`~hazardhunt.spec.descriptors.MEASURE_RANGES` (bearings in degrees), widened to the
values."""


def _archive_axis(archive: pd.DataFrame, name: str | None) -> tuple[str, Any, Any]:
    """An axis of the heat map: its label, its cell edges and each cell's values on it."""
    if name is None:
        return "", np.array([0.0, 1.0]), np.zeros(len(archive))
    label, cells = ARCHIVE_AXES.get(name, (name, 6))
    low, high = MEASURE_RANGES.get(name, (0.0, 1.0))
    values = archive[name].to_numpy(dtype=float)
    if name == "bearing":
        values, low, high = np.degrees(values), math.degrees(low), math.degrees(high)
    if len(values):
        low, high = min(low, float(values.min())), max(high, float(values.max()))
    return label, np.linspace(low, high, cells + 1), values


def archive_heat_map(archive: pd.DataFrame, path: Path, title: str) -> Path:
    """A quality-diversity archive (``tester/archive.parquet``) as a heat map over its first two
    measures (by default the bearing of the contact or closest approach and the robot's speed
    there): each cell the best episode's maximum risk over the archive's other axes; cells
    holding a failure (risk >= 100) framed."""
    measures = [c for c in archive.columns if c not in ("index", "objective")]
    x_label, bearing_edges, x_values = _archive_axis(archive, measures[0])
    y_label, speed_edges, y_values = _archive_axis(archive, (measures[1:] or [None])[0])
    best = np.full((len(speed_edges) - 1, len(bearing_edges) - 1), np.nan)
    columns = np.clip(np.digitize(x_values, bearing_edges) - 1, 0, best.shape[1] - 1)
    rows = np.clip(np.digitize(y_values, speed_edges) - 1, 0, best.shape[0] - 1)
    for row, column, objective in zip(rows, columns, archive["objective"], strict=True):
        best[row, column] = np.fmax(best[row, column], objective)
    figure = Figure(figsize=(7.0, 3.4), dpi=100)
    ax = figure.add_subplot()
    # Risk spans near misses (below 1) and collisions (100 to 200): a log scale shows both.
    shown = ax.pcolormesh(
        bearing_edges, speed_edges, np.log10(np.maximum(best, 1e-3)), cmap="magma", shading="flat"
    )
    for row, column in zip(*np.nonzero(best >= 100.0), strict=True):
        ax.add_patch(
            Rectangle(
                (bearing_edges[column], speed_edges[row]),
                bearing_edges[column + 1] - bearing_edges[column],
                speed_edges[row + 1] - speed_edges[row],
                fill=False,
                edgecolor="#2ca02c",
                linewidth=2,
            )
        )
    figure.colorbar(shown, ax=ax, label="log10 of the maximum risk")
    ax.set_xlabel(x_label)
    ax.set_ylabel(y_label)
    ax.set_title(title, fontsize=9)
    return _save(figure, path)
