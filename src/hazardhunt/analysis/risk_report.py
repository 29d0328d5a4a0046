"""The report of an estimate (``hazardhunt report ESTIMATE_DIR``): how likely a failure is, per
class, how the estimate converged against episodes, and the most likely failures drawn.

The most likely failures are replayed from their draws against the estimate's SUT, once each
draw is checked to be one of the model's and the models to be the ones the estimate recorded;
one that no longer fails is drawn as what it did, not as a failure. An estimate that names a
plug-in (controller, safety layer or model of people by import path) is data whose code is not
run: its failures are listed, not drawn.
"""

from __future__ import annotations

import json
import math
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import matplotlib
import numpy as np
import pandas as pd
from markupsafe import Markup, escape
from matplotlib.figure import Figure

from hazardhunt.analysis.page import Block, Prose, Section, Table, Text, image, render_page, table
from hazardhunt.campaign.progress import shown_scenario
from hazardhunt.campaign.store import write_bytes_atomic
from hazardhunt.env.rendering import RecordedEpisode, animate_episode, plot_episode
from hazardhunt.errors import InputError
from hazardhunt.likelihood.encounters import Draw, SimulationEncounters
from hazardhunt.likelihood.results import NOTES, estimate_record_problem
from hazardhunt.likelihood.run import (
    EstimateConfig,
    batch_path,
    check_no_links,
    draw_of,
    encounters_of,
    load_config,
    models_of,
    played_batches,
)

REPLAYED = {
    "goal": "reached the goal",
    "timeout": "timed out",
    "stall": "stalled (its emergency stop held too long)",
    "safe_contact": "ended in a safe contact",
    "sut_error": "ended in a SUT error",
}
"""What a replay that does not fail did, by its outcome."""


def is_estimate(directory: Path) -> bool:
    """Whether ``directory`` holds an estimate (rather than a run or campaign)."""
    return (directory / "config.json").is_file() and batch_path(directory, 0).parent.is_dir()


def write_estimate_report(directory: Path, tell: Callable[[str], None] | None = None) -> Path:
    """Write ``report/index.html`` of the estimate in ``directory``; its path.

    Raises:
        InputError: The estimate is not finished (no ``estimate.json``: run the command again).
    """
    say = tell or (lambda step: None)
    check_no_links(directory)
    config = load_config(directory)
    path = directory / "estimate.json"
    if not path.is_file():
        raise InputError(
            f"{directory}: the estimate is not finished (no estimate.json); run its "
            "hazardhunt estimate command again to finish it"
        )
    try:
        summary = json.loads(path.read_text())
        if (problem := estimate_record_problem(summary)) is not None:
            raise ValueError(f"not an estimate's summary: {problem}")
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as error:  # JSON's too
        raise InputError(
            f"{path}: cannot be read ({error}); run the estimate's hazardhunt estimate command "
            "again to write it anew from the batches"
        ) from None
    say("reading episodes")
    batches = played_batches(directory)
    if not batches:
        raise InputError(f"{directory}: the estimate's batches are missing (batches/)")
    episodes = pd.concat(batches, ignore_index=True)
    played = set(episodes["episode"])
    for found in (summary.get("most_likely") or {}).values():
        if found["episode"] not in played:
            raise InputError(
                f"{path}: most_likely names episode {found['episode']}, which the batches do "
                "not hold; run the estimate's hazardhunt estimate command again to write it "
                "anew from the batches"
            )
    replays = _replays(directory, config, summary.get("most_likely") or {}, episodes)
    final = directory / "report"
    scratch = directory / ".report.partial"
    shutil.rmtree(scratch, ignore_errors=True)
    (scratch / "figures").mkdir(parents=True)
    sections = [_probabilities(scratch, config, summary), _convergence(scratch, summary)]
    # Class names are text, never matplotlib's mathtext.
    with matplotlib.rc_context({"text.parse_math": False}):
        sections.append(_most_likely(scratch, directory, summary, replays, say))
    facts = (
        f"{shown_scenario(config.scenario)}, field {config.field}, {summary['method']}, "
        f"{summary['episodes']:,} episodes, seed {config.seed}"
    )
    write_bytes_atomic(
        scratch / "index.html", render_page(directory, None, sections, facts).encode()
    )
    shutil.rmtree(final, ignore_errors=True)
    scratch.replace(final)
    return final / "index.html"


def _table(scratch: Path, name: str, data: pd.DataFrame, caption: str = "") -> Table:
    """``data`` shown on the page, with its CSV file beside it (``tables/NAME.csv``)."""
    (scratch / "tables").mkdir(exist_ok=True)
    data.to_csv(scratch / "tables" / f"{name}.csv", index=False)
    return table(name, data, caption)


def _untested(summary: dict[str, Any]) -> list[Block]:
    """What the episodes the SUT could not play mean for the probability, and what leaving
    them out assumes."""
    untested = summary.get("untested") or {}
    note = untested.get("note")
    return [Text(_range(summary), "warning"), *([Text(note, "warning")] if note else [])]


def _range(summary: dict[str, Any]) -> str:
    """Where the probability of a failure lies whatever the episodes the SUT could not play
    would have done."""
    untested = summary.get("untested") or {}
    low = (untested.get("failure_and_tested") or {}).get("low")
    high = (untested.get("failure_or_untested") or {}).get("high")
    errors = summary["sut_errors"]
    said = f"{errors:,} episodes ended in a SUT error and tested nothing"
    if isinstance(low, float) and isinstance(high, float):
        said += (
            f": the probability above is over the tested episodes. Whatever those {errors:,} "
            f"would have done, the probability of a failure lies between {low:.3g} (counting "
            f"them as safe) and {high:.3g} (counting them as failures)."
        )
        return said
    # An estimate.json written before 0.2.0: its probability counts them as safe encounters.
    said += (
        "; the probability above counts them as safe encounters: run the estimate's command "
        "again to have it over the tested episodes"
    )
    if isinstance(high, float):
        said += f"; counting them as failures, the probability of a failure is up to {high:.3g}"
    return said + "."


def _episodes(summary: dict[str, Any]) -> str:
    """The episodes the headline is over: all of them, or, when some ended in a SUT error, the
    tested ones it counts, of all."""
    if not summary.get("sut_errors") or "episodes_tested" not in summary:
        return f"{summary['episodes']:,}"
    return f"the {summary['probability']['episodes']:,} tested of {summary['episodes']:,}"


def _probabilities(scratch: Path, config: EstimateConfig, summary: dict[str, Any]) -> Section:
    section = Section(
        "How likely a failure is",
        "The probability of an unsafe contact per encounter, when people behave as the model of "
        "people says and the SUT's uncertainties vary as their model says (docs/risk.md).",
    )
    result = summary["probability"]
    section.blocks.append(
        Prose(
            Markup(
                "Probability of a failure per encounter: <b>{}</b>, 95 % interval [{}, {}] "
                "({}; {} failures in {} episodes)."
            ).format(
                f"{result['probability']:.3g}",
                f"{result['low']:.3g}",
                f"{result['high']:.3g}",
                result["interval"],
                f"{result['failures']:,}",
                _episodes(summary),
            ),
            "headline",
        )
    )
    equivalent = summary.get("monte_carlo_equivalent")
    if equivalent and not summary.get("levels_warning"):
        section.blocks.append(
            Text(
                f"Relative error {equivalent['relative_error']:.0%}: plain Monte Carlo would "
                f"need about {equivalent['episodes_for_same_error']:,.0f} episodes for it, "
                f"{equivalent['ratio']:.1f} times the {summary['episodes']:,} played here; "
                f"for {equivalent['target_relative_error']:.0%} about "
                f"{equivalent['episodes_for_target']:,.0f}."
            )
        )
    for note in NOTES:
        if summary.get(note):
            section.blocks.append(Text(summary[note], "warning"))
    if summary.get("sut_errors"):
        section.blocks += _untested(summary)
    rows = [
        {
            "class": name,
            "probability": part["probability"],
            "low": part["low"],
            "high": part["high"],
            "failures": part["failures"],
        }
        for name, part in summary["classes"].items()
    ]
    if rows:
        section.blocks.append(_table(scratch, "classes", pd.DataFrame(rows), "Per failure class"))
    section.blocks.append(
        Text(
            f"People: {config.people or 'the built-in shop-floor walkers'}; uncertainties: "
            f"{config.uncertainties or 'the built-in ones'}."
        )
    )
    return section


def _convergence(scratch: Path, summary: dict[str, Any]) -> Section:
    section = Section(
        "How the estimate converged",
        "The estimate and its interval after each batch (level, for splitting) against the "
        "episodes played so far.",
    )
    points = [p for p in summary["convergence"] if p["probability"] and p["probability"] > 0]
    if not points:
        section.blocks.append(Text("No failure yet: nothing to draw."))
        return section
    figure = Figure(figsize=(7, 4), dpi=110)
    ax = figure.add_subplot()
    x = [p["episodes"] for p in points]
    ax.fill_between(
        x,
        [max(p["low"], 1e-300) for p in points],
        [p["high"] for p in points],
        alpha=0.25,
        label="95 % interval",
    )
    ax.plot(x, [p["probability"] for p in points], marker="o", label="estimate")
    ax.set_yscale("log")
    ax.set_xlabel("episodes")
    ax.set_ylabel("failures per encounter")
    ax.legend()
    figure.tight_layout()
    path = scratch / "figures" / "convergence.png"
    figure.savefig(path)
    section.blocks.append(image(path, "The estimate against episodes"))
    return section


class Replays(NamedTuple):
    """The most likely failures to replay: the encounters they are played in, and each one's
    class (``all`` for the likeliest of all), episode and draw."""

    source: SimulationEncounters
    draws: list[tuple[str, int, Draw]]


def _replays(
    directory: Path, config: EstimateConfig, likeliest: dict[str, Any], episodes: pd.DataFrame
) -> Replays | None:
    """The most likely failures' draws, checked before anything is written; None when there
    is none, or the estimate names plug-ins (whose code a report does not run).

    Raises:
        InputError: A model the estimate recorded has changed since (its file names it), or a
            draw is not one of the model's (its batch names it).
    """
    plugins = config.controller or config.safety_layer or (config.people and ":" in config.people)
    if plugins or not likeliest:
        return None
    if config.digests is not None:
        models = models_of(config)
        current = models.digests()
        changed = next((k for k in config.digests if config.digests[k] != current.get(k)), None)
        if changed is not None:
            raise InputError(
                f"{models.source(changed)}: changed since the estimate in {directory} was made "
                f"(its SHA-256 is not the one config.json records for {changed}): its most "
                "likely failures cannot be replayed on it; restore it to report on the estimate"
            )
    source = encounters_of(config)
    rows = episodes.drop_duplicates("episode").set_index("episode")
    draws: list[tuple[str, int, Draw]] = []
    for name, found in likeliest.items():
        if found["episode"] not in {episode for _, episode, _ in draws}:  # all's is a class's
            row = rows.loc[found["episode"]]
            draws.append((name, found["episode"], _checked_draw(directory, row, source)))
    return Replays(source, draws)


def _checked_draw(directory: Path, row: Any, source: SimulationEncounters) -> Draw:
    """The draw an episode's row records, if it is one of the model's.

    Raises:
        InputError: A value the model does not draw (out of range, not a number) or a column
            missing, naming the batch.
    """
    batch = row.get("batch")
    shown = batch_path(directory, int(batch)) if isinstance(batch, int | np.integer) else "batches"
    where = f"{shown}: episode {row.name}"
    mend = (
        "the batch changed since it was played (delete it and run the estimate's hazardhunt "
        "estimate command again to play it anew), or the model since the estimate was made"
    )
    try:
        draw = draw_of(row, source.dimensions)
    except KeyError as error:
        raise InputError(f"{where}: no column {error}, a part of its draw: {mend}") from None
    except (TypeError, ValueError) as error:
        raise InputError(f"{where}: its draw is not numbers ({error}): {mend}") from None
    for dim in source.dimensions:
        value = draw.values[dim.name]
        if not math.isfinite(dim.log_prob(value)):
            raise InputError(
                f"{where}: x.{dim.name} is {value!r}, which the model does not draw: {mend}"
            )
    if draw.seed < 0:
        raise InputError(f"{where}: noise_seed is {draw.seed}, not a seed (>= 0): {mend}")
    return draw


def _most_likely(
    scratch: Path,
    directory: Path,
    summary: dict[str, Any],
    replays: Replays | None,
    say: Callable[[str], None],
) -> Section:
    section = Section(
        "The most likely failures",
        "Per class, the failing episode of highest likelihood under the model, replayed from "
        "its draw.",
    )
    likeliest = summary.get("most_likely") or {}
    if not likeliest:
        section.blocks.append(Text("No failure was found."))
        return section
    rows = [
        {"class": name, "episode": found["episode"], "log-likelihood": found["log_p"]}
        for name, found in likeliest.items()
    ]
    section.blocks.append(_table(scratch, "most_likely", pd.DataFrame(rows)))
    if replays is None:
        section.blocks.append(
            Text(
                "Not drawn: the estimate names plug-ins, whose code a report does not run. "
                "Each failure's draw is its row in batches/ (columns x.*, noise_seed)."
            )
        )
        return section
    say("replaying the most likely failures")
    for name, episode, draw in replays.draws:
        section.blocks += _drawn(scratch, directory, replays.source, draw, name, episode)
    return section


def _drawn(
    scratch: Path,
    directory: Path,
    source: SimulationEncounters,
    draw: Draw,
    name: str,
    episode: int,
) -> list[Block]:
    """One failure replayed from its draw: its tracks, its last seconds and its draw; said
    plainly when the replay does not fail (the SUT or the model changed since)."""
    result = source.episode(draw, keep_trajectory=True)
    simulation = source.simulation
    title = f"{name}: episode {episode}"
    changed: list[Block] = []
    if result.summary.outcome != "failure":
        did = REPLAYED.get(str(result.summary.outcome), str(result.summary.outcome))
        title += f" (replayed: {did}, no longer a failure)"
        said = (
            f"Episode {episode} failed when the estimate played it; replayed from its draw, it "
            f"{did}: the SUT or the model has changed since the estimate was made, and what "
            "is drawn here is not the failure the estimate counted."
        )
        changed.append(Text(said, "warning"))
        warnings.warn(
            f"{directory}: the most likely failure of {name} (episode {episode}) {did} when "
            "replayed from its draw: the SUT or the model has changed since the estimate was "
            "made (the report draws it as such)",
            stacklevel=2,
        )
    samples = tuple(result.trajectory or ())
    stem = scratch / "figures" / f"likeliest-{episode}"
    picture = plot_episode(
        stem.with_suffix(".png"),
        simulation.scenario,
        simulation.route,
        samples,
        simulation.field,
        title,
        result.outcome,
        simulation.robot_params,
    )
    recorded = RecordedEpisode(
        simulation.scenario, simulation.route, simulation.field, simulation.robot_params, samples
    )
    animation = animate_episode(
        stem.with_suffix(".gif"), recorded, title=name, fps=5, last_seconds=6.0, size=4.5
    )
    values = ", ".join(
        f"{key} {value:.3g}" for key, value in draw.values.items() if math.isfinite(value)
    )
    return [
        *changed,
        image(picture, title),
        image(animation, f"{name}: the last 6 s"),
        Prose(Markup("Draw: {}").format(escape(values))),
    ]
