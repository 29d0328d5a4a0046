"""The ``hazardhunt`` command.

Long (over 500 lines) because each subcommand's signature is its options, with their help
texts: the commands only read their options and call the packages below, which do the work.
"""

from __future__ import annotations

import inspect
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, NoReturn, TypeVar

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress
from rich.table import Column, Table
from typer.core import TyperCommand, TyperGroup

from hazardhunt.campaign.config import ConfigError
from hazardhunt.errors import HazardhuntError
from hazardhunt.sut.guard import notice_ctrl_c
from hazardhunt.testers.registry import TESTERS, is_import_path
from hazardhunt.textfiles import TOMLDecodeError, TomlTooDeepError, cut_short, loads_toml
from hazardhunt.warning_lines import printable, show_warnings_in_one_line
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

if TYPE_CHECKING:
    from hazardhunt.campaign.config import RunConfig
    from hazardhunt.campaign.plugins import PluginSpec
    from hazardhunt.campaign.records import RequirementCount, RunSummary
    from hazardhunt.campaign.replay import ReplayResult
    from hazardhunt.cases import RegressionResult
    from hazardhunt.sim.simulation import Simulation


class _FlagsWithoutType:
    """Flags (``--json``, ``--help``) shown without a value type: typer 0.29 shows them as
    ``--json <bool>``, as if they took a value."""

    def get_params(self, ctx: Any) -> Any:
        params = super().get_params(ctx)  # type: ignore[misc]
        for param in params:
            if getattr(param, "is_flag", False):
                param.metavar = ""
        return params


class _Group(_FlagsWithoutType, TyperGroup):
    pass


class _Command(_FlagsWithoutType, TyperCommand):
    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        """Arguments in the usage line as ``DIRECTORY`` and ``[NAMES]...``, as the help's own
        text names them: typer 0.29 writes ``{directory}`` and ``[names]...``."""
        return [
            re.sub(r"^([{\[])(\w+)[}\]]", _argument_in_usage, piece)
            for piece in super().collect_usage_pieces(ctx)
        ]


def _argument_in_usage(match: re.Match[str]) -> str:
    name = match[2].upper()
    return name if match[1] == "{" else f"[{name}]"


app = typer.Typer(
    cls=_Group,
    help="Find the human behaviours that make a robot's control stack unsafe.",
    no_args_is_help=True,
    add_completion=False,
)
console = Console()
err_console = Console(stderr=True, soft_wrap=True)


def _transient_bar(on: Console) -> Progress:
    """A progress bar that disappears when done; none where ``on`` is not a terminal (a
    transient bar leaves an empty line in a pipe or a file)."""
    return Progress(console=on, transient=True, disable=not on.is_terminal)


T = TypeVar("T")


def _print_version(requested: bool) -> None:
    if requested:
        import hazardhunt

        console.print(f"hazardhunt {hazardhunt.__version__}", highlight=False)
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            help="Print the version and exit.",
            callback=_print_version,
            is_eager=True,
        ),
    ] = False,
) -> None:
    """hazardhunt: simulation-based safety testing of a mobile robot's control stack."""


@app.command(cls=_Command)
def scenarios(
    names: Annotated[
        list[str] | None,
        typer.Argument(
            help="Scenarios to draw: built-in names or scenario files (default: all built-in ones)."
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="Directory for the pictures.")] = Path("scenarios"),
    field: Annotated[
        str, typer.Option(help="Protective field: none, 1.25m, 2m or one the scenario defines.")
    ] = "1.25m",
    seed: Annotated[int, typer.Option(min=0, help="Seed of the random human.")] = 0,
    solver: Annotated[str, typer.Option(help="NMPC solver: fatrop or ipopt.")] = "fatrop",
) -> None:
    """Simulate one episode per scenario with a random human and draw each."""
    from hazardhunt.campaign.config import check_output_location

    chosen = names or list(BUILTIN_SCENARIOS)
    check_output_location(out)
    for name in chosen:  # every file and option checked before the first is simulated
        _check_scenario(name, field)
    table = Table(
        "scenario", "outcome", "sim time (s)", "min clearance (m)", "emergency stops", "picture"
    )
    rng = np.random.default_rng(seed)
    with _transient_bar(console) as progress:
        task = progress.add_task("simulating", total=len(chosen))
        for name in chosen:  # one simulation at a time: each holds its own NMPC
            progress.update(task, description=f"simulating {name}")
            simulation = _scenario_simulation(name, field, solver)
            table.add_row(*_simulate_and_draw(name, simulation, field, rng, out))
            progress.advance(task)
    console.print(table)
    console.print(f"Pictures written to [bold]{out.resolve()}[/bold]")


def _check_scenario(name: str, field: str) -> None:
    """Raises unless scenario ``name`` loads, its robot can drive its route and it has ``field``."""
    from hazardhunt.campaign.config import cached_scenario, route_problem
    from hazardhunt.sut.safety_layer import field_shape
    from hazardhunt.world.bodies import RobotParams
    from hazardhunt.world.scenario import ScenarioError

    scenario = cached_scenario(name)  # read once, here and for the route's check
    problem = route_problem(name, RobotParams())
    if problem is not None:
        raise ScenarioError(problem)
    try:
        field_shape(scenario, field)
    except ValueError as error:
        raise typer.BadParameter(str(error), param_hint="--field") from None


def _scenario_simulation(name: str, field: str, solver: str) -> Simulation:
    """The simulation of scenario ``name`` (checked: :func:`_check_scenario`) behind ``field``."""
    from hazardhunt.campaign.config import cached_scenario
    from hazardhunt.sim.simulation import Simulation

    try:
        return Simulation.build(cached_scenario(name), field, solver=solver)
    except ValueError as error:
        raise typer.BadParameter(str(error), param_hint="--solver") from None


def _simulate_and_draw(
    name: str, simulation: Simulation, field: str, rng: np.random.Generator, out: Path
) -> tuple[str, ...]:
    """One episode of scenario ``name`` with a random human, drawn into ``out``: its row of
    the ``scenarios`` command's table."""
    from hazardhunt.env.rendering import plot_episode

    result = simulation.simulate(lambda _: rng.uniform(-1.0, 1.0, size=2))
    summary = result.summary
    stem = Path(name).stem
    picture = plot_episode(
        out / f"{stem}.png",
        simulation.scenario,
        simulation.route,
        result.trajectory or (),
        simulation.field,
        title=f"{stem}, field {field}: {summary.outcome} at {summary.sim_time:.1f} s",
        outcome=summary.outcome,
    )
    return (
        stem,
        str(summary.outcome),
        f"{summary.sim_time:.1f}",
        f"{summary.min_clearance:.2f}",
        str(summary.emergency_stops),
        str(picture),
    )


ControllerOption = Annotated[
    str | None,
    typer.Option(
        help="Your controller as package.module:Class, or ros2 (your ROS 2 node, "
        "docs/ros2.md), instead of the built-in NMPC."
    ),
]
RegressControllerOption = Annotated[
    str | None,
    typer.Option(help="A controller as package.module:Class, instead of the case's own."),
]
ControllerParamOption = Annotated[
    list[str] | None,
    typer.Option(metavar="KEY=VALUE", help="A controller parameter as KEY=VALUE; repeatable."),
]
ControllerTimeoutOption = Annotated[
    float | None,
    typer.Option(
        help="Wall-clock limit on each call of the controller and of the safety layer, in s; a "
        "call that exceeds it ends the episode as sut_error (default: no limit)."
    ),
]
RecordedTimeoutOption = Annotated[
    float | None,
    typer.Option(
        "--controller-timeout",
        help="Wall-clock limit on each call of the controller and of the safety layer, in s, "
        "instead of the one recorded (the run's or the case's); a call that exceeds it ends "
        "the episode as sut_error.",
    ),
]
SafetyLayerOption = Annotated[
    str | None,
    typer.Option(help="Your safety layer as package.module:Class, instead of the laser field."),
]
RegressSafetyLayerOption = Annotated[
    str | None,
    typer.Option(help="A safety layer as package.module:Class, instead of the case's own."),
]
SafetyLayerParamOption = Annotated[
    list[str] | None,
    typer.Option(metavar="KEY=VALUE", help="A safety-layer parameter as KEY=VALUE; repeatable."),
]
ClassifierParamOption = Annotated[
    list[str] | None,
    typer.Option(metavar="KEY=VALUE", help="A classifier parameter as KEY=VALUE; repeatable."),
]
RequirementOption = Annotated[
    list[str] | None,
    typer.Option(
        metavar="NAME",
        help="Judge every episode by this requirement too: a name of hazardhunt's library "
        "(separation, slow-near-people, no-restart-in-field, reach-goal), a requirements file "
        "(.toml, every requirement in it) or FILE.toml:NAME; repeatable.",
    ),
]
RunClassifierOption = Annotated[
    str | None,
    typer.Option(
        help="Your failure classifier as package.module:Class, instead of the built-in one."
    ),
]
CampaignClassifierOption = Annotated[
    str | None,
    typer.Option(
        help="Your failure classifier as package.module:Class, instead of the campaign file's "
        "\\[classifier] table or the built-in one."
    ),
]
ReadClassifierOption = Annotated[
    str | None,
    typer.Option(
        help="Classify every failure anew with your failure classifier (package.module:Class). "
        "Without it, the classes the runs recorded count: hazardhunt never imports code named "
        "in results."
    ),
]
TrustPluginsOption = Annotated[
    bool,
    typer.Option(
        "--trust-plugins",
        help="Import the controller and safety-layer plug-ins the files read name (by default "
        "hazardhunt imports no code named in a run or case; name a plug-in with --controller "
        "or --safety-layer instead to choose it yourself).",
    ),
]
RegressClassifierOption = Annotated[
    str | None,
    typer.Option(
        help="Classify the replayed failures with your failure classifier (package.module:Class) "
        "instead of the built-in one; needed for cases classified by a plug-in."
    ),
]


EpisodesOption = Annotated[
    int | None,
    typer.Option(help="Budget of episodes \\[default: 20,000, the study's, about half an hour]."),
]
TesterParamOption = Annotated[
    list[str] | None,
    typer.Option(
        metavar="KEY=VALUE",
        help="A tester parameter as KEY=VALUE (TOML value), e.g. workers=2 (portfolio, cem, "
        "qd), space=aim (cem, qd) or n_envs=2 (ppo-*); repeat for several "
        "(docs/search-methods.md).",
    ),
]
RobotOption = Annotated[
    list[str] | None,
    typer.Option(
        metavar="KEY=VALUE",
        help="A robot parameter as KEY=VALUE (length, width, max_speed, max_acceleration, ...: "
        "docs/environment.md); repeatable.",
    ),
]
SutErrorLimitOption = Annotated[
    float,
    typer.Option(
        help="Fail the run once this share of its episodes ended in a SUT error (the "
        "controller or safety layer raised, hung or returned something unusable); 1: when "
        "every one did."
    ),
]


@app.command(
    "run",
    cls=_Command,
    help="Run one tester on one scenario and field setting for a budget of episodes.\n\n"
    "Exits with code 1 when the run tested nothing (every episode, or --sut-error-limit of "
    "them, ended in a SUT error) or could not write its results; 2 for bad input, before "
    "anything is written (a plug-in that fails on a trial episode included).",
)
def run_command(
    scenario: Annotated[
        str, typer.Option(help="crossing, head-on, overtaking or a .toml file.")
    ] = "crossing",
    field: Annotated[
        str,
        typer.Option(help="Protective field: none, 1.25m, 2m or a field the scenario defines."),
    ] = "1.25m",
    *,
    out: Annotated[Path, typer.Option(help="Directory for the run's results.")],
    tester: Annotated[
        str, typer.Option(help=f"{', '.join(TESTERS)}, or yours as package.module:Class.")
    ] = "portfolio",
    episodes: EpisodesOption = None,
    seed: Annotated[int, typer.Option(help="Seed of the run.")] = 0,
    decision_period: Annotated[float, typer.Option(help="Seconds per human action.")] = 2.0,
    solver: Annotated[str, typer.Option(help="NMPC solver: fatrop or ipopt.")] = "fatrop",
    controller_timeout: ControllerTimeoutOption = None,
    episode_duration: Annotated[
        float, typer.Option(help="Simulated seconds after which an episode times out.")
    ] = 30.0,
    stall_duration: Annotated[
        float, typer.Option(help="Seconds of emergency stop in a row that end an episode.")
    ] = 10.0,
    robot: RobotOption = None,
    tester_param: TesterParamOption = None,
    controller: ControllerOption = None,
    controller_param: ControllerParamOption = None,
    safety_layer: SafetyLayerOption = None,
    safety_layer_param: SafetyLayerParamOption = None,
    classifier: RunClassifierOption = None,
    classifier_param: ClassifierParamOption = None,
    sut_error_limit: SutErrorLimitOption = 1.0,
    requirement: RequirementOption = None,
    search_on: Annotated[
        str | None,
        typer.Option(
            help="Search on this requirement (one of --requirement's): the episode-level "
            "testers hunt its violations, guided by its robustness, instead of unsafe contacts; "
            "ppo-max learns from it as its reward."
        ),
    ] = None,
    json_output: Annotated[
        bool, typer.Option("--json", help="Print a one-object JSON summary on stdout.")
    ] = False,
) -> None:
    """The command; long because its signature is the command's options, one per field of a run's
    configuration (``RunConfig``, ``EnvOptions``)."""
    from hazardhunt.campaign.config import (
        EnvOptions,
        RunConfig,
        check_output_location,
        check_plugins,
    )

    tester_plugin = _plugin("--tester", tester, tester_param) if is_import_path(tester) else None
    config = _validated(
        lambda: RunConfig(
            scenario=scenario,
            field=field,
            tester_plugin=tester_plugin,
            tester=tester,
            seed=seed,
            episodes=DEFAULT_EPISODES if episodes is None else episodes,
            env=EnvOptions(
                decision_period=decision_period,
                solver=solver,
                episode_duration=episode_duration,
                stall_duration=stall_duration,
                controller_timeout=controller_timeout,
                robot=_assignments("--robot", robot),
            ),
            tester_params={} if tester_plugin else _assignments("--tester-param", tester_param),
            controller=_plugin("--controller", controller, controller_param),
            safety_layer=_plugin("--safety-layer", safety_layer, safety_layer_param),
            classifier=_plugin("--classifier", classifier, classifier_param),
            sut_error_limit=sut_error_limit,
            requirements=requirement or [],
            search_on=search_on,
        )
    )
    check_plugins(config)
    check_output_location(out)
    if episodes is None:
        _say_default_budget()
    _execute_and_print(config, out, json_output)


def _say_default_budget() -> None:
    err_console.print(
        f"playing {DEFAULT_EPISODES:,} episodes, the study's budget (about half an hour with "
        "the built-in NMPC on one core); --episodes sets another",
        highlight=False,
    )


DEFAULT_EPISODES = 20_000
"""The budget of ``hazardhunt run`` without ``--episodes``: a run of the study."""


def _execute_and_print(config: RunConfig, out: Path, json_output: bool) -> None:
    """Execute a run and print its summary (JSON or a table); a failed run exits with 1."""
    from hazardhunt.campaign.records import RunFailed
    from hazardhunt.campaign.run import execute_run

    try:
        summary = execute_run(config, out, console=err_console)
    except RunFailed as error:
        err_console.print(f"[red]error:[/red] {escape(str(error))}")
        raise typer.Exit(1) from None
    if json_output:
        print(json.dumps(summary))
    else:
        _print_run_summary(summary, out)


def _assignments(option: str, assignments: list[str] | None) -> dict[str, Any]:
    """``KEY=VALUE`` strings as a dict; VALUE is read as TOML, and as a string if it is none
    (a VALUE that opens a list, a table or a quoted string must be TOML)."""
    params: dict[str, Any] = {}
    for assignment in assignments or []:
        key, separator, value = assignment.partition("=")
        if not separator or not key.strip():
            raise ConfigError(f"{option}: {assignment!r} is not KEY=VALUE")
        try:
            params[key.strip()] = loads_toml(f"value = {value}")["value"]
        except TomlTooDeepError as error:
            raise ConfigError(f"{option}: {key.strip()}: {error}") from None
        except TOMLDecodeError as error:
            if value.strip().startswith(("[", "{", '"', "'")):
                # Its position would count the "value = " that VALUE is read under.
                problem = re.sub(r" \(at [^)]*\)$", "", str(error))
                raise ConfigError(
                    f"{option}: {key.strip()}: {value} does not read as TOML ({problem})"
                ) from None
            params[key.strip()] = value
    return params


def _plugin(option: str, path: str | None, params: list[str] | None) -> PluginSpec | None:
    """A plug-in's specification from the command line; its module may sit in the working
    directory.

    Raises:
        ConfigError: The parameters do not read, or the module does not import or lacks the
            name: naming ``option``.
    """
    from hazardhunt.campaign.plugins import PluginSpec, warn_if_in_results
    from hazardhunt.sut.plugins import PluginError, controller_path, load_attribute

    if path is None:
        if params:
            raise ConfigError(f"{option}-param: given without {option}")
        return None
    spec = PluginSpec(
        path=path,
        params=_assignments(f"{option}-param", params),
        search_path=[str(Path.cwd())],
    )
    warn_if_in_results(spec, f"{option} {path}")
    try:  # the user named it: importing it here says which option names what does not load
        load_attribute(
            controller_path(spec.path) if option == "--controller" else spec.path,
            spec.search_path,
        )
    except PluginError as error:
        raise ConfigError(f"{option}: {error}") from None
    return spec


def _announcer() -> Callable[[str], None]:
    """Prints each message about a module to be imported once, on stderr."""
    said: set[str] = set()

    def announce(message: str) -> None:
        if message not in said:
            said.add(message)
            err_console.print(escape(message))

    return announce


@app.command(cls=_Command)
def replay(
    run_directory: Annotated[Path, typer.Argument(help="A run directory.")],
    episode: Annotated[
        int,
        typer.Option(
            help="The episode of the failure (or of a requirement's violation), as the run "
            "numbers it."
        ),
    ],
    gif: Annotated[Path | None, typer.Option(help="Write an animation of the replay.")] = None,
    controller: Annotated[
        str | None,
        typer.Option(
            help="Replay with this controller (package.module:Class): the run's own import "
            "path to confirm it (with its parameters), or another one."
        ),
    ] = None,
    controller_param: ControllerParamOption = None,
    safety_layer: Annotated[
        str | None,
        typer.Option(
            help="Replay with this safety layer (package.module:Class): the run's own import "
            "path to confirm it (with its parameters), or another one."
        ),
    ] = None,
    safety_layer_param: SafetyLayerParamOption = None,
    controller_timeout: RecordedTimeoutOption = None,
    trust_plugins: TrustPluginsOption = False,
) -> None:
    """Re-simulate a recorded failure and confirm it ends the same way at the same time.

    An episode that violated a requirement beyond the contact rule must also violate it again
    by the same robustness, judged by the formula the run recorded with the violation.

    A run whose controller or safety layer is a plug-in replays only with that plug-in named
    (--controller, --safety-layer) or with --trust-plugins: a run directory is data.
    """
    from hazardhunt.campaign.replay import replay_failure

    _check_gif(gif)
    _check_timeout(controller_timeout)
    replay = replay_failure(
        run_directory,
        episode,
        controller=_plugin("--controller", controller, controller_param),
        safety_layer=_plugin("--safety-layer", safety_layer, safety_layer_param),
        trust_plugins=trust_plugins,
        announce=_announcer(),
        controller_timeout=controller_timeout,
    )
    _print_replay(replay)
    if gif is not None:
        from hazardhunt.env.rendering import animate_episode

        animate_episode(gif, replay.simulation, title=f"episode {episode}")
        console.print(f"animation written to [bold]{gif}[/bold]")
    if not replay.matches:
        raise typer.Exit(1)


def _print_replay(replay: ReplayResult) -> None:
    """What the record says, what the replay did, and whether that reproduces it (never when
    the SUT erred in the replay: it tested nothing)."""
    verdict = "[green]reproduced[/green]" if replay.matches else "[red]NOT reproduced[/red]"
    if replay.sut_error is not None:
        verdict += f": the SUT erred, so the replay tested nothing ({shown(replay.sut_error)})"
    # An episode that has not ended when its recorded actions run out has no outcome.
    replayed = replay.result.outcome or "no end (its recorded actions ran out)"
    console.print(
        f"episode {replay.episode}: recorded {shown(replay.recorded_outcome)} at "
        f"{replay.recorded_sim_time:.2f} s, replayed {replayed} at "
        f"{replay.result.summary.sim_time:.2f} s: {verdict}"
    )
    for name, robustness in replay.recorded_robustness.items():
        again = replay.result.verdicts.get(name)
        console.print(
            f"  requirement {escape(name)}: recorded robustness {robustness:.6g}, replayed "
            f"{'not judged' if again is None else f'{again.robustness:.6g}'}"
        )


def _check_timeout(controller_timeout: float | None) -> None:
    """Raises ConfigError unless ``controller_timeout`` (None: none given) is a limit a run
    would take, before anything is replayed."""
    from hazardhunt.campaign.config import EnvOptions

    if controller_timeout is not None:
        _validated(lambda: EnvOptions(controller_timeout=controller_timeout))


def _check_gif(gif: Path | None) -> None:
    """Raises ConfigError unless an animation can be written to ``gif`` (None: none asked
    for), before anything is replayed."""
    from hazardhunt.campaign.config import check_output_location

    if gif is None:
        return
    if gif.is_dir():
        raise ConfigError(f"--gif: {gif} is a folder; name a file, such as {gif / 'failure.gif'}")
    if gif.suffix.lower() != ".gif":
        raise ConfigError(
            f"--gif: {gif} does not end in .gif; the animation is a GIF, such as "
            f"{gif.with_suffix('.gif')}"
        )
    check_output_location(gif.parent, option="--gif")


@app.command(cls=_Command)
def campaign(
    file: Annotated[Path, typer.Argument(help="A campaign file (TOML).")],
    out: Annotated[Path, typer.Option(help="The campaign directory (created or resumed).")],
    workers: Annotated[int, typer.Option(help="Runs executed at once.")] = 1,
    executor: Annotated[str, typer.Option(help="local (process pool) or ray.")] = "local",
    address: Annotated[
        str | None, typer.Option(help="Address of an existing Ray cluster (with --executor ray).")
    ] = None,
    classifier: CampaignClassifierOption = None,
    classifier_param: ClassifierParamOption = None,
    runs: Annotated[
        list[str] | None,
        typer.Option(
            metavar="PATTERN",
            help="Run only the runs whose id matches this shell pattern (e.g. "
            "'crossing__*__seed0'; repeatable) and leave the others for later: a large "
            "campaign in slices, into one directory.",
        ),
    ] = None,
) -> None:
    """Run every run of a campaign file; run it again to finish an interrupted campaign.

    Exits with code 1 when some runs failed (they raised, or tested nothing: sut_error_limit
    of their episodes ended in a SUT error), after the others finished; `hazardhunt report`
    reads the runs that finished and names those that failed.
    """
    from hazardhunt.campaign.campaign import EXECUTORS, CampaignFailed, run_campaign
    from hazardhunt.campaign.config import check_output_location, load_campaign

    if executor not in EXECUTORS:
        raise typer.BadParameter(f"use {' or '.join(EXECUTORS)}", param_hint="--executor")
    if workers < 1:
        raise typer.BadParameter("must be at least 1", param_hint="--workers")
    if address is not None and executor != "ray":
        raise typer.BadParameter("only with --executor ray", param_hint="--address")
    config = load_campaign(file, _plugin("--classifier", classifier, classifier_param))
    for name in config.unused_tester_tables:
        err_console.print(
            f"[yellow]warning:[/yellow] {escape(str(file))}: \\[tester.{escape(name)}] is not "
            f"run (testers = {escape(str(config.testers))}): its settings are not used",
            highlight=False,
        )
    check_output_location(out)
    try:
        run_campaign(
            config,
            out,
            workers=workers,
            executor=executor,
            address=address,
            console=console,
            only=runs or (),
        )
    except CampaignFailed:
        raise typer.Exit(1) from None


@app.command(cls=_Command)
def report(
    directory: Annotated[Path, typer.Argument(help="A run, campaign or estimate directory.")],
    reclassify: Annotated[
        bool,
        typer.Option(
            help="Classify every failure anew from its trajectory with the built-in taxonomy "
            "(or --classifier's).",
        ),
    ] = False,
    classifier: ReadClassifierOption = None,
    classifier_param: ClassifierParamOption = None,
) -> None:
    """Write the study's figures and tables for a run or campaign into DIRECTORY/report (for
    an estimate: its probabilities, convergence and most likely failures).

    Exits with code 1 when runs of the campaign failed (they tested nothing, or raised): the
    report covers the others, if any, and its verdict names them first; 2 when the directory
    holds no results (not a run or campaign, or no run has finished yet).
    """
    from hazardhunt.analysis.page import check_report_folder
    from hazardhunt.analysis.report import write_report
    from hazardhunt.analysis.risk_report import is_estimate, write_estimate_report
    from hazardhunt.campaign.plugins import make_classifier

    check_report_folder(directory / "report")
    if is_estimate(directory):
        with _transient_bar(console) as progress:
            task = progress.add_task("report", total=None)
            index = write_estimate_report(
                directory, lambda step: progress.update(task, description=f"report: {step}")
            )
        console.print(f"report written to [bold]{index.resolve()}[/bold]")
        return

    spec = _plugin("--classifier", classifier, classifier_param)
    chosen = make_classifier(spec) if spec is not None or reclassify else None
    failed = _warn_of_left_out_runs(directory)
    with _transient_bar(console) as progress:
        task = progress.add_task("report", total=None)
        index = write_report(
            directory, lambda step: progress.update(task, description=f"report: {step}"), chosen
        )
    console.print(f"report written to [bold]{index.resolve()}[/bold]")
    _exit_if_runs_failed(failed, "the report covers")


@app.command(cls=_Command)
def export(
    directory: Annotated[Path, typer.Argument(help="A run or campaign directory.")],
    out: Annotated[Path, typer.Option(help="Folder for the case files (created).")],
    all_failures: Annotated[
        bool,
        typer.Option("--all", help="One case per failure, not one per class, scenario and field."),
    ] = False,
    pytest_module: Annotated[
        bool,
        typer.Option(
            "--pytest",
            help="Also write test_hazardhunt_cases.py: the cases as pytest tests.",
        ),
    ] = False,
    classifier: ReadClassifierOption = None,
    classifier_param: ClassifierParamOption = None,
    trust_plugins: Annotated[
        bool,
        typer.Option(
            "--trust-plugins",
            help="With --pytest: the test module imports the controller and safety-layer "
            "plug-ins the cases name (TRUST_PLUGINS = True in it).",
        ),
    ] = False,
) -> None:
    """Write failures as self-contained regression cases (TOML), to re-run with regress.

    Exporting imports nothing: the cases name the runs' plug-ins as data. Exits with code 1
    when runs of the campaign failed (they tested nothing, or raised): the cases are those of
    the others, if any; 2 when the directory holds no results (not a run or campaign, or no
    run has finished yet).
    """
    from hazardhunt.cases import export_cases, write_pytest_module

    spec = _plugin("--classifier", classifier, classifier_param)
    failed = _warn_of_left_out_runs(directory)
    written = export_cases(directory, out, every_failure=all_failures, classifier=spec)
    cases = "1 case" if len(written) == 1 else f"{len(written)} cases"
    console.print(f"{cases} written to [bold]{out.resolve()}[/bold]")
    if not written:
        held = "the runs that completed hold" if failed else "the results hold"
        console.print(f"{held} no failure")
    if pytest_module:
        module = write_pytest_module(out, spec, trust_plugins=trust_plugins)
        console.print(f"pytest module written to [bold]{module}[/bold]")
    _exit_if_runs_failed(failed, "the cases cover")


@app.command(cls=_Command)
def copy(
    directory: Annotated[Path, typer.Argument(help="A run or campaign directory.")],
    out: Annotated[
        Path, typer.Option(help="Where the copy goes (created, or brought up to date).")
    ],
) -> None:
    """Copy results without the failures' trajectories: small enough to keep in version control.

    The copy holds every table, summary and configuration and the testers' state; report and
    export work on it (failures of the built-in SUT replay from their actions; the clusters of
    trajectories and --reclassify need the original). Only finished runs whose files match
    their checksums are copied; copying a campaign again adds the runs finished since. Runs
    that failed have nothing to copy: they are named on stderr (the exit code stays 0), and
    the copy's summary.json keeps their errors, so that report and export of the copy name
    them and exit 1 as for the original.
    """
    from hazardhunt.campaign.config import check_output_location
    from hazardhunt.campaign.copying import copy_results

    check_output_location(out)
    copied = copy_results(directory, out)
    for run_id, damage in copied.damaged.items():
        console.print(
            f"[yellow]warning:[/yellow] {shown(run_id)} not copied: damaged ({shown(damage)})"
        )
    _print_failed(copied.failed)
    if copied.ledger_problem is not None:
        err_console.print(
            f"[yellow]warning:[/yellow] the campaign's ledger is not copied, and runs not "
            f"finished may have failed: {shown(copied.ledger_problem)}"
        )
    failed = f"[red]{len(copied.failed)} failed[/red] (nothing to copy), " if copied.failed else ""
    console.print(
        f"{len(copied.copied)} {'run' if len(copied.copied) == 1 else 'runs'} copied, "
        f"{len(copied.already_there)} already there, {failed}"
        f"{len(copied.unfinished)} not finished yet; the copy is [bold]{out.resolve()}[/bold]"
    )


def _exit_if_runs_failed(failed: dict[str, str], written: str) -> None:
    """Name the runs of a campaign that failed (``failed``: run id -> error), in red on
    stderr, and exit with code 1 if there are any: what the command wrote (``written``: "the
    report covers") covers only the runs that completed, and must not read as a pass."""
    if not failed:
        return
    _print_failed(failed)
    one = len(failed) == 1
    err_console.print(
        f"[red]error: {len(failed)} {'run' if one else 'runs'} of the campaign failed[/red], "
        f"so {written} only the runs that completed; run the campaign again to retry "
        f"{'it' if one else 'them'} (errors above and in summary.json)",
        highlight=False,
    )
    raise typer.Exit(1)


def _print_failed(failed: dict[str, str]) -> None:
    """Each run of a campaign that failed, with its error, in red on stderr."""
    for run_id, error in failed.items():
        err_console.print(f"[red]failed:[/red] {shown(run_id)}: {shown(error)}", highlight=False)


def _warn_of_left_out_runs(directory: Path) -> dict[str, str]:
    """Name the runs of a campaign directory left out because their files are damaged, and
    say so if its ledger does not read (its failed runs then read as not finished); the runs
    that failed (run id -> error), which the command names once it has written what it covers.
    The runs are classified (their files checked against their checksums) once per command."""
    from hazardhunt.analysis.results import ResultsError, run_states

    try:
        states = run_states(directory)
    except ResultsError:
        return {}  # the command reports it
    for run_id, damage in states.damaged.items():
        err_console.print(
            f"[yellow]warning:[/yellow] run {shown(run_id)} is damaged ({shown(damage)}) and "
            "left out; running the campaign again redoes it"
        )
    if states.ledger_problem is not None and states.unfinished and states.complete:
        one = len(states.unfinished) == 1
        err_console.print(
            f"[yellow]warning:[/yellow] {len(states.unfinished)} {'run' if one else 'runs'} of "
            f"the campaign {'has' if one else 'have'} not finished, and may have failed: the "
            f"campaign's ledger cannot tell ({shown(states.ledger_problem)})"
        )
    return states.failed


@app.command(cls=_Command)
def regress(
    cases: Annotated[Path, typer.Argument(help="A case file or a folder of case files.")],
    controller: RegressControllerOption = None,
    controller_param: ControllerParamOption = None,
    safety_layer: RegressSafetyLayerOption = None,
    safety_layer_param: SafetyLayerParamOption = None,
    field: Annotated[
        str | None, typer.Option(help="Re-run with this field setting instead of the case's.")
    ] = None,
    classifier: RegressClassifierOption = None,
    classifier_param: ClassifierParamOption = None,
    controller_timeout: RecordedTimeoutOption = None,
    trust_plugins: TrustPluginsOption = False,
    json_output: Annotated[
        bool, typer.Option("--json", help="Print the results as JSON on stdout.")
    ] = False,
) -> None:
    """Re-run regression cases: each still fails, changed (fails differently) or is fixed.

    A case whose controller or safety layer is a plug-in re-runs only with a plug-in named
    (--controller, --safety-layer) or with --trust-plugins: a case file is data.

    Exits with code 1 while any case still fails or changed, so that it can gate a CI job, and
    with 3 when some case could not be tested at all (the SUT raised, hung or returned something
    unusable: verdict "error").
    """
    from hazardhunt.cases import VERDICTS, case_files, regress_case

    controller_spec = _plugin("--controller", controller, controller_param)
    safety_spec = _plugin("--safety-layer", safety_layer, safety_layer_param)
    classifier_spec = _plugin("--classifier", classifier, classifier_param)
    _check_timeout(controller_timeout)
    files = case_files(cases)
    announce = _announcer()
    results = []
    with _transient_bar(err_console) as progress:
        task = progress.add_task("re-running cases", total=len(files))
        for path in files:
            results.append(
                regress_case(
                    path,
                    controller=controller_spec,
                    safety_layer=safety_spec,
                    field=field,
                    classifier=classifier_spec,
                    trust_plugins=trust_plugins,
                    announce=announce,
                    controller_timeout=controller_timeout,
                )
            )
            progress.advance(task)
    counts = {v: sum(r.verdict == v for r in results) for v in VERDICTS}
    if json_output:
        print(json.dumps({"cases": [vars(r) for r in results], "counts": counts}))
    else:
        _print_regress(results, counts)
    if counts["error"]:
        raise typer.Exit(REGRESS_UNTESTED)
    if counts["still fails"] or counts["changed"]:
        raise typer.Exit(1)


def _print_regress(results: list[RegressionResult], counts: dict[str, int]) -> None:
    """The table of re-run cases, their counts, and each case that could not be tested."""
    colours = {"still fails": "red", "changed": "yellow", "error": "red", "fixed": "green"}
    table = Table(Column("case", overflow="fold"), "expected", "now", "at (s)", "verdict")
    for r in results:
        now = r.failure_class if r.failure_class is not None else r.outcome
        verdict = f"[{colours[r.verdict]}]{r.verdict}[/{colours[r.verdict]}]"
        table.add_row(
            shown(r.case), shown(r.expected_class), shown(now), f"{r.sim_time:.2f}", verdict
        )
    console.print(table)
    tally = ", ".join(f"{verdict}: {n}" for verdict, n in counts.items())
    console.print(f"{len(results)} {'case' if len(results) == 1 else 'cases'}: {tally}")
    for r in results:
        if r.error is not None:
            err_console.print(
                f"[red]error:[/red] {shown(r.case)}: the SUT erred and the case tested "
                f"nothing: {shown(r.error)}"
            )


REGRESS_UNTESTED = 3
"""``regress``'s exit code when some case could not be tested (its SUT erred)."""


@app.command("new-sut", cls=_Command)
def new_sut(
    directory: Annotated[Path, typer.Argument(help="A new folder for the files (created).")],
    ros2: Annotated[
        bool,
        typer.Option(
            "--ros2",
            help="A ROS 2 node to fill in, a site map (map_server YAML and PGM), a scenario on "
            "it and a campaign that runs the node through the ros2 bridge (docs/ros2.md).",
        ),
    ] = False,
) -> None:
    """Write a starting point for testing your own system: a controller plug-in, a floor map
    and a scenario to edit, a campaign file and a README of the next commands."""
    import shlex
    from importlib import resources

    from hazardhunt.campaign.config import check_output_location

    if directory.exists() and (not directory.is_dir() or any(directory.iterdir())):
        raise ConfigError(f"{directory}: exists and is not empty; name a new folder")
    check_output_location(directory, option="DIRECTORY")
    directory.mkdir(parents=True, exist_ok=True)
    kind = "new_sut_ros2" if ros2 else "new_sut"
    templates = resources.files("hazardhunt") / "templates" / kind
    names = sorted(t.name for t in templates.iterdir() if t.is_file())
    for name in names:
        content = (templates / name).read_bytes()
        if ros2 and name == "campaign.toml":
            # The node's command line: this Python (it has the ros2 extra) and the node's path.
            node = shlex.join([sys.executable, str(directory.resolve() / "my_node.py")])
            content = content.replace(b"@COMMAND@", json.dumps(node).encode())
        (directory / name).write_bytes(content)
    console.print(f"written to [bold]{escape(str(directory))}[/bold]: {', '.join(names)}")
    workers = "" if ros2 else " --workers 2"
    console.print(
        f"next: cd {escape(str(directory))} && hazardhunt campaign campaign.toml --out results"
        f"{workers} (README.md has the commands after it)",
        highlight=False,
    )


@app.command(
    "estimate",
    cls=_Command,
    help="Estimate the probability of a failure per encounter when people behave as a model of "
    "them says and the SUT's sensors and brake vary as a model of its uncertainties says "
    "(docs/risk.md).\n\nRun the same command again to resume an interrupted estimate; with "
    "a larger --episodes, to add episodes to a plain Monte Carlo one. The estimate is over the "
    "episodes the SUT played: exits with code 1 when none of those it counts was (each ended "
    "in a SUT error: nothing was tested); 2 for bad input, before anything runs.",
)
def estimate_command(
    out: Annotated[Path, typer.Option(help="Directory for the estimate's episodes and result.")],
    scenario: Annotated[
        str, typer.Option(help="crossing, head-on, overtaking or a .toml file.")
    ] = "crossing",
    field: Annotated[
        str,
        typer.Option(help="Protective field: none, 1.25m, 2m or a field the scenario defines."),
    ] = "1.25m",
    method: Annotated[
        str,
        typer.Option(
            help="mc (plain Monte Carlo), ce (cross-entropy importance sampling) or splitting "
            "(multilevel splitting): the last two for rare failures, docs/risk.md says when to "
            "trust them."
        ),
    ] = "mc",
    episodes: Annotated[int, typer.Option(help="Budget of episodes.")] = 2000,
    batch_size: Annotated[
        int | None,
        typer.Option(
            help="Episodes per batch (ce: the proposal moves between batches; splitting: "
            "samples per level) \\[default: the resumed estimate's; else 200, or fewer where "
            "--episodes would not give the method its fewest batches: 1 for mc, 3 for ce, 2 "
            "for splitting]."
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the estimate.")] = 0,
    people: Annotated[
        str | None,
        typer.Option(
            help="Model of people: a model file (.toml) or package.module:Class \\[default: the "
            "built-in shop-floor walkers]."
        ),
    ] = None,
    uncertainties: Annotated[
        str | None,
        typer.Option(
            help="The SUT's uncertainties: a file (.toml), or none \\[default: the built-in ones]."
        ),
    ] = None,
    controller: ControllerOption = None,
    controller_param: ControllerParamOption = None,
    safety_layer: SafetyLayerOption = None,
    safety_layer_param: SafetyLayerParamOption = None,
    controller_timeout: ControllerTimeoutOption = None,
    workers: Annotated[int, typer.Option(min=1, max=64, help="Processes that play episodes.")] = 1,
) -> None:
    """The command; long because its signature is the command's options."""
    from hazardhunt.campaign.config import EnvOptions, check_output_location
    from hazardhunt.likelihood.estimators import EstimatorParams
    from hazardhunt.likelihood.results import summarise, write_summary
    from hazardhunt.likelihood.run import (
        WALKING_PERIOD,
        EstimateConfig,
        EstimateRun,
        default_batch_size,
        resumed_batch_size,
    )

    if batch_size is None:
        batch_size = resumed_batch_size(out, method) or default_batch_size(method, episodes)
    if people is not None and not people.endswith(".toml") and is_import_path(people):
        _plugin("--people", people, None)  # one line naming the option if it does not import

    config = _validated(
        lambda: EstimateConfig(
            scenario=scenario,
            field=field,
            people=people,
            uncertainties=uncertainties,
            controller=_plugin("--controller", controller, controller_param),
            safety_layer=_plugin("--safety-layer", safety_layer, safety_layer_param),
            env=EnvOptions(decision_period=WALKING_PERIOD, controller_timeout=controller_timeout),
            estimator=EstimatorParams(method=method, batch_size=batch_size),  # type: ignore[arg-type]
            episodes=episodes,
            seed=seed,
        )
    )
    check_output_location(out)
    estimate_run = EstimateRun(config, out, workers=workers)
    with _transient_bar(err_console) as bar:
        task = bar.add_task(f"estimate ({method})", total=config.episodes)
        table = estimate_run.run(lambda done, total: bar.update(task, completed=done))
    summary = summarise(config, table, estimate_run.source.threshold)
    path = write_summary(out, summary)
    _print_estimate(summary, path)


def _print_estimate(summary: dict[str, Any], path: Path) -> None:
    from hazardhunt.likelihood.results import NOTES

    result, errors = summary["probability"], summary["sut_errors"]
    table = Table("failures per encounter", "95 % interval", "episodes", "failures", "method")
    table.add_row(
        f"{result['probability']:.3g}",
        f"[{result['low']:.3g}, {result['high']:.3g}] ({result['interval']})",
        f"{summary['episodes']:,}" + (f" [red]({errors:,} SUT errors)[/red]" if errors else ""),
        f"{result['failures']:,}",
        summary["method"],
    )
    for name, part in summary["classes"].items():
        table.add_row(
            f"  {shown(name)}: {part['probability']:.3g}",
            f"[{part['low']:.3g}, {part['high']:.3g}]",
            "",
            f"{part['failures']:,}",
            "",
        )
    console.print(table)
    equivalent = summary["monte_carlo_equivalent"]
    if equivalent is not None and summary["method"] == "mc":
        console.print(f"relative error {equivalent['relative_error']:.0%}", highlight=False)
    elif equivalent is not None and not summary.get("levels_warning"):
        console.print(
            f"relative error {equivalent['relative_error']:.0%}: plain Monte Carlo would need "
            f"about {equivalent['episodes_for_same_error']:,.0f} episodes for it "
            f"({equivalent['ratio']:.1f} times these)",
            highlight=False,
        )
    for note in NOTES:
        if summary.get(note):
            console.print(f"[yellow]note:[/yellow] {escape(summary[note])}", highlight=False)
    if errors:
        _warn_of_untested(summary)
    console.print(f"estimate: {escape(str(path))}", highlight=False)


def _warn_of_untested(summary: dict[str, Any]) -> None:
    """That some of an estimate's episodes ended in a SUT error: how many, the first error,
    that the estimate is over the others, and where the probability lies whatever they would
    have done."""
    errors, untested = summary["sut_errors"], summary["untested"]
    first = summary.get("first_sut_error")
    said = (
        f"[red]warning:[/red] {errors:,} of the {summary['episodes']:,} episodes ended in a SUT "
        "error and tested nothing"
        + (f" (the first: {shown(first)})" if first else "")
        + f"; the estimate and its interval are over the {summary['probability']['episodes']:,} "
        "tested episodes it counts"
    )
    low = untested["failure_and_tested"]["low"]
    high = untested["failure_or_untested"]["high"]
    said += (
        f". Whatever those {errors:,} would have done, the probability of a failure lies "
        f"between {low:.3g} (counting them as safe) and {high:.3g} (counting them as failures)"
    )
    err_console.print(said, highlight=False)
    err_console.print(f"[yellow]note:[/yellow] {escape(untested['note'])}", highlight=False)


def _validated(build: Callable[[], T]) -> T:
    from pydantic import ValidationError

    from hazardhunt.textfiles import format_validation_error

    try:
        return build()
    except ValidationError as error:
        raise ConfigError(format_validation_error(error)) from None


def _print_classes_found(summary: RunSummary, out: Path) -> None:
    """The failure classes a run found, its first failure and how to look at them; or, when
    it found none, that this is no proof of safety."""
    from hazardhunt.analysis.verdict import NOT_A_PASS, SLOW_TO_FIND

    first = summary.get("first_failure_episode")
    tested = summary["episodes"] - summary["sut_errors"]
    if not summary["failures"] and tested > 0:
        console.print(
            f"no unsafe failure found in {tested:,} episodes: {NOT_A_PASS}; {SLOW_TO_FIND}; run "
            "longer, or other testers, before taking that for safe.",
            highlight=False,
        )
    if not summary["failures"] or first is None:
        return
    classes = ", ".join(map(shown, summary.get("classes") or []))
    found = f"{summary.get('classes_found', 0)} of {summary.get('classes_total', '?')}"
    where = escape(str(out))
    console.print(
        f"failure classes found: {found}{f' ({classes})' if classes else ''}; first failure: "
        f"episode {first}. To see it: hazardhunt replay {where} --episode {first} --gif "
        f"failure.gif; every failure: hazardhunt report {where}",
        highlight=False,
    )


def _print_run_summary(summary: RunSummary, out: Path) -> None:
    sut_errors = summary["sut_errors"]
    table = Table(
        "episodes",
        "failures",
        "SUT errors",
        "safe contacts",
        "stalls",
        "wall time (s)",
        "episodes per s",
    )
    table.add_row(
        str(summary["episodes"]),
        str(summary["failures"]),
        f"[red]{sut_errors}[/red]" if sut_errors else "0",
        str(summary["safe_contacts"]),
        str(summary["stalls"]),
        f"{summary['wall_time_s']:.1f}",
        f"{summary['episodes_per_s']:.2f}",
    )
    console.print(table)
    _print_classes_found(summary, out)
    first = summary.get("first_sut_error")
    if sut_errors and first is not None:
        console.print(
            f"[red]warning: {sut_errors} of {summary['episodes']} episodes ended in a SUT error "
            f"and tested nothing[/red]; the first, episode {first['episode']}: "
            f"{escape(first['error'])}",
            highlight=False,
        )
    faulty = summary.get("first_classifier_error")
    for name, count in (summary.get("requirements") or {}).items():
        console.print(_requirement_line(name, count, summary["episodes"]), highlight=False)
    if faulty is not None:
        console.print(
            f"[red]warning: the failure classifier failed on {summary['classifier_errors']} "
            f"failures[/red] (recorded as other); the first, episode {faulty['episode']}: "
            f"{escape(faulty['error'])}",
            highlight=False,
        )
    console.print(f"results in [bold]{out.resolve()}[/bold]")


def _requirement_line(name: str, count: RequirementCount, episodes: int) -> str:
    """How a run's episodes stood against one requirement: over the episodes it judged, which
    leave out those that ended in a SUT error (a run before 0.2.0 judged every episode)."""
    judged = count.get("judged")
    if judged is None:
        said = f"requirement {shown(name)}: {count['violations']:,} episodes violated it"
    else:
        said = f"requirement {shown(name)}: {count['violations']:,} of {judged:,} tested episodes "
        said += "violated it"
        if judged < episodes:
            said += f" ({episodes - judged:,} ended in a SUT error and are not judged)"
    violated_first, lowest = count["first_violation_episode"], count["min_robustness"]
    if violated_first is not None:
        said += f", the first episode {violated_first}"
    if lowest is not None:
        said += f"; lowest robustness {lowest:.3g}"
    decided = count.get("decided_by") or {}
    if decided:
        said += "; decided by " + ", ".join(
            f"{shown(signals)} ({n:,})" for signals, n in decided.items()
        )
    return said


def _one_line_summaries() -> None:
    """Give every command the first paragraph of its help (or else of its docstring), joined
    into one line, as the summary the list of commands shows (typer keeps the line breaks)."""
    for command in app.registered_commands:
        if command.short_help is None and command.callback is not None:
            text = command.help if isinstance(command.help, str) else command.callback.__doc__
            first = inspect.cleandoc(text or "").split("\n\n")[0]
            command.short_help = " ".join(first.split())


_one_line_summaries()


def run() -> None:
    """Entry point: an error hazardhunt raises is one clear line on stderr and its exit code (2
    for bad input, see :mod:`hazardhunt.errors`), a file that cannot be written one line and
    exit code 1, a warning it gives one line too, and Ctrl-C says how to resume (told from a
    ``KeyboardInterrupt`` a plug-in raises, which is the plug-in's error)."""
    notice_ctrl_c()
    show_warnings_in_one_line(
        lambda text: err_console.print(
            f"[yellow]warning:[/yellow] {escape(cut_short(text))}", highlight=False
        )
    )
    try:
        app()
    except HazardhuntError as error:  # an input error exits 2 (InputError), the others 1
        _exit_with(str(error), error.exit_code)
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        _exit_with(f"{where}{error.strerror or error}", 1)
    except KeyboardInterrupt:
        _interrupted()
    except SystemExit as ended:
        if ended.code == INTERRUPTED:  # typer's answer to Ctrl-C
            _interrupted()
        raise


INTERRUPTED = 130
"""The exit code of a command interrupted with Ctrl-C (128 + SIGINT), as shells use it."""


def shown(text: str) -> str:
    """Text read from a file someone else may have made, as the terminal shows it: its control
    characters (escape sequences) written out as ``\\x1b`` and its rich markup escaped."""
    return escape(printable(text))


def _exit_with(message: str, code: int) -> NoReturn:
    err_console.print(f"[red]error:[/red] {shown(cut_short(message))}")
    raise SystemExit(code) from None


def _interrupted() -> NoReturn:
    command = sys.argv[1] if len(sys.argv) > 1 else ""
    how = {
        "run": ": run the same command again to resume (complete runs are kept, the rest is "
        "redone from its start)",
        "estimate": ": run the same command again to resume (the batches written are kept, the "
        "rest is played)",
    }.get("run" if command == "campaign" else command, "")
    err_console.print(f"[yellow]interrupted[/yellow]{how}")
    raise SystemExit(INTERRUPTED) from None


if __name__ == "__main__":
    run()
