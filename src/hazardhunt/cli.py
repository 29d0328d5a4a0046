"""The ``hazardhunt`` command."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.scenario import BUILTIN_SCENARIOS, ScenarioError

app = typer.Typer(
    help="Find the human behaviours that make a robot's control stack unsafe.",
    no_args_is_help=True,
    add_completion=False,
)
console = Console()


@app.callback()
def main() -> None:
    """hazardhunt: simulation-based safety testing of a mobile robot's control stack."""


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="Directory for the pictures.")] = Path("demo-output"),
    field: Annotated[str, typer.Option(help="Protective field: none, 1.25m or 2m.")] = "1.25m",
    seed: Annotated[int, typer.Option(help="Seed of the random human.")] = 0,
    solver: Annotated[str, typer.Option(help="NMPC solver: fatrop or ipopt.")] = "fatrop",
) -> None:
    """Simulate one episode per built-in scenario with a random human and draw each."""
    from hazardhunt.env.agv import AGVEnv
    from hazardhunt.env.rendering import plot_episode

    if field not in FIELD_SETTINGS:
        raise typer.BadParameter(f"choose one of {', '.join(FIELD_SETTINGS)}", param_hint="--field")
    table = Table("scenario", "outcome", "sim time (s)", "min clearance (m)", "e-stops", "picture")
    rng = np.random.default_rng(seed)
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task("simulating", total=len(BUILTIN_SCENARIOS))
        for name in BUILTIN_SCENARIOS:
            progress.update(task, description=f"simulating {name}")
            env = AGVEnv(name, field, solver=solver)
            env.reset(seed=seed)
            info: dict[str, object] = {}
            done = False
            while not done:
                action = rng.uniform(-1.0, 1.0, size=2).astype(np.float32)
                _, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
            outcome = str(info["outcome"])
            picture = plot_episode(
                out / f"{name}.png",
                env.scenario,
                env.route,
                env.trajectory(),
                env.field_diameter,
                title=f"{name}, field {field}: {outcome} at {info['sim_time']:.1f} s",
                outcome=outcome,
            )
            table.add_row(
                name,
                outcome,
                f"{info['sim_time']:.1f}",
                f"{info['min_clearance']:.2f}",
                str(info["estop_count"]),
                str(picture),
            )
            progress.advance(task)
    console.print(table)
    console.print(f"Pictures written to [bold]{out.resolve()}[/bold]")


def run() -> None:
    """Entry point that turns input errors into one clear line."""
    try:
        app()
    except ScenarioError as error:
        console.print(f"[red]error:[/red] {error}")
        raise SystemExit(2) from None


if __name__ == "__main__":
    run()
