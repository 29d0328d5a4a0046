"""The report's figures as PNG files, drawn with matplotlib's object API (no pyplot state)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from hazardhunt.env.rendering import draw_floor
from hazardhunt.testers.registry import colour_of, sort_testers
from hazardhunt.world.scenario import load_scenario

FIELD_ORDER = ("none", "1.25m", "2m")


def _ordered_fields(values: pd.Series) -> list[str]:
    present = list(dict.fromkeys(values))
    return [f for f in FIELD_ORDER if f in present] + [f for f in present if f not in FIELD_ORDER]


def _save(figure: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    figure.savefig(path)
    return path


def failures_bar_chart(runs: pd.DataFrame, path: Path) -> Path:
    """Mean failures per run by scenario and tester, one panel per field setting; the error bar
    is the standard deviation over seeds and the dots are the seeds."""
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
            ax.bar(
                positions,
                means,
                width,
                yerr=spreads,
                capsize=2,
                color=colour_of(tester),
                label=tester,
            )
        ax.set_xticks(range(len(scenarios)), scenarios)
        ax.set_title(f"field {field}")
        ax.set_ylabel("failures per run")
        if column == 0:
            ax.legend(fontsize=8)
    return _save(figure, path)


def learning_curves_figure(curves: pd.DataFrame, path: Path) -> Path:
    """Failures per 100 episodes over the runs, one panel per field, one line per tester."""
    fields = _ordered_fields(curves["field"])
    figure = Figure(figsize=(4.2 * max(1, len(fields)), 3.4), dpi=100)
    for column, field in enumerate(fields):
        ax = figure.add_subplot(1, len(fields), column + 1)
        in_field = curves[curves["field"] == field]
        for tester in sort_testers(in_field["tester"]):
            group = in_field[in_field["tester"] == tester]
            ax.plot(
                group["episode"],
                group["failures per 100 episodes"],
                marker=".",
                color=colour_of(tester),
                label=tester,
            )
        ax.set_title(f"field {field}")
        ax.set_xlabel("episode")
        ax.set_ylabel("failures per 100 episodes")
        ax.set_ylim(bottom=0)
        if column == 0:
            ax.legend(fontsize=8)
    return _save(figure, path)


def failure_heat_map(failures: pd.DataFrame, scenario: str, path: Path) -> Path:
    """Where on the floor the human was at contact, one panel per tester, counted on a 0.5 m
    grid over the floor of ``scenario``."""
    testers = sort_testers(failures["tester"]) or ["(none)"]
    floor_scenario = load_scenario(scenario)
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
        ax.set_title(f"{tester}: {int(counts[tester].sum())} failures")
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
