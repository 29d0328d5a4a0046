"""Pictures of the workplace: floor, shelves, route, robot with its protective field, human."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon, Wedge
from numpy.typing import NDArray

from hazardhunt.spec.episode import TrajectorySample
from hazardhunt.sut.route import Route
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.world.bodies import HumanParams, RobotParams
from hazardhunt.world.geometry import rectangle_corners
from hazardhunt.world.scenario import Scenario

if TYPE_CHECKING:
    from hazardhunt.sim.simulation import Simulation


class Scene(Protocol):
    """What drawing an episode needs: a played :class:`~hazardhunt.sim.Simulation`, or an
    episode as a run recorded it (:class:`RecordedEpisode`)."""

    @property
    def scenario(self) -> Scenario: ...
    @property
    def route(self) -> Route: ...
    @property
    def field(self) -> FieldShape: ...
    @property
    def robot_params(self) -> RobotParams: ...
    @property
    def human_params(self) -> HumanParams: ...

    def trajectory(self) -> list[TrajectorySample]:
        """The episode's samples, every 0.2 s and at its end."""
        ...


@dataclass(frozen=True)
class RecordedEpisode:
    """An episode as a run stored it, to draw without building its system under test."""

    scenario: Scenario
    route: Route
    field: FieldShape
    robot_params: RobotParams
    samples: tuple[TrajectorySample, ...]
    human_params: HumanParams = HumanParams()

    def trajectory(self) -> list[TrajectorySample]:
        return list(self.samples)


OUTCOME_COLOURS = {
    "failure": "#d62728",
    "safe_contact": "#ff7f0e",
    "goal": "#2ca02c",
    "timeout": "#7f7f7f",
    "stall": "#9467bd",
    "sut_error": "#8c564b",
}


def draw_floor(ax: Axes, scenario: Scenario, route: Route | None = None) -> None:
    """Walls, shelf blocks, blind zones, the route and the goal."""
    floor = scenario.floor
    for zone in floor.blind_zones:
        ax.add_patch(Polygon(zone, closed=True, facecolor="#fff3b0", edgecolor="none", zorder=0))
    for obstacle in floor.obstacles:
        colour = "#404040" if obstacle.kind == "wall" else "#a67c52"
        ax.add_patch(Polygon(obstacle.polygon, closed=True, facecolor=colour, edgecolor="none"))
    if route is not None:
        ax.plot(*route.points.T, linestyle="--", color="#1f77b4", linewidth=1, label="route")
    ax.plot(*scenario.goal, marker="*", markersize=12, color="#2ca02c", linestyle="none")
    ax.set_xlim(0, floor.width)
    ax.set_ylim(0, floor.height)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def draw_robot(
    ax: Axes,
    pose: tuple[float, float, float],
    params: RobotParams,
    field: FieldShape,
    emergency_stop: bool = False,
    alpha: float = 1.0,
) -> None:
    """The robot's rectangle and its protective field: the half-disc ahead and the side
    bands, red while the emergency stop holds."""
    x, y, heading = pose
    style: dict[str, Any] = {
        "facecolor": "#d62728" if emergency_stop else "#2ca02c",
        "alpha": 0.25 * alpha,
        "edgecolor": "none",
    }
    if field.diameter is not None:
        front = (
            x + params.length / 2 * math.cos(heading),
            y + params.length / 2 * math.sin(heading),
        )
        degrees = math.degrees(heading)
        ax.add_patch(Wedge(front, field.diameter / 2, degrees - 90, degrees + 90, **style))
    if field.side_margin > 0.0:
        offset = params.width / 2 + field.side_margin / 2
        for side in (1.0, -1.0):
            centre_x = x - side * offset * math.sin(heading)
            centre_y = y + side * offset * math.cos(heading)
            band = rectangle_corners(centre_x, centre_y, heading, params.length, field.side_margin)
            ax.add_patch(Polygon(band, closed=True, **style))
    corners = rectangle_corners(x, y, heading, params.length, params.width)
    ax.add_patch(
        Polygon(corners, closed=True, facecolor="#1f77b4", edgecolor="black", alpha=alpha, zorder=3)
    )


def draw_human(
    ax: Axes, position: Sequence[float], heading: float, params: HumanParams, alpha: float = 1.0
) -> None:
    """The human's disc with a tick for its heading."""
    center = (float(position[0]), float(position[1]))
    ax.add_patch(
        Circle(center, params.radius, facecolor="#ff7f0e", edgecolor="black", alpha=alpha, zorder=4)
    )
    tip = (
        position[0] + params.radius * math.cos(heading),
        position[1] + params.radius * math.sin(heading),
    )
    ax.plot([position[0], tip[0]], [position[1], tip[1]], color="black", linewidth=1, zorder=5)


def floor_figure_size(scenario: Scenario, size: float) -> tuple[float, float]:
    """Width and height, in inches, of a picture of ``scenario``'s floor whose longer side is
    ``size``: the floor's own proportions (a square floor: ``size`` by ``size``), no side below
    half of ``size``, so that a long narrow floor is not drawn between two bands of white."""
    floor = scenario.floor
    longest = max(floor.width, floor.height)
    return (
        size * max(0.5, floor.width / longest),
        size * max(0.5, floor.height / longest),
    )


def plot_episode(
    path: Path,
    scenario: Scenario,
    route: Route,
    trajectory: Sequence[TrajectorySample],
    field: FieldShape,
    title: str,
    outcome: str | None = None,
    robot: RobotParams = RobotParams(),
    human: HumanParams = HumanParams(),
) -> Path:
    """Write a PNG of one episode: both tracks and the final poses."""
    figure = Figure(figsize=floor_figure_size(scenario, 7), dpi=110)
    ax = figure.add_subplot()
    draw_floor(ax, scenario, route)
    robot_track = np.array([[row.robot_x, row.robot_y] for row in trajectory])
    human_track = np.array([[row.human_x, row.human_y] for row in trajectory])
    ax.plot(*robot_track.T, color="#1f77b4", linewidth=1.5, label="robot")
    ax.plot(*human_track.T, color="#ff7f0e", linewidth=1.5, label="human")
    ax.plot(*robot_track[0], "s", color="#1f77b4", markerfacecolor="white", label="start")
    ax.plot(*human_track[0], "o", color="#ff7f0e", markerfacecolor="white")
    stops = np.array([row.emergency_stop for row in trajectory], dtype=bool)
    if stops.any():
        ax.plot(*robot_track[stops].T, "x", color="#d62728", markersize=4, label="emergency stop")
    last = trajectory[-1]
    draw_robot(
        ax, (last.robot_x, last.robot_y, last.robot_heading), robot, field, last.emergency_stop
    )
    draw_human(ax, (last.human_x, last.human_y), last.human_heading, human)
    colour = OUTCOME_COLOURS.get(outcome or "", "black")
    ax.set_title(title, color=colour)
    ax.legend(loc="upper right", fontsize=8)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    return path


def render_rgb(simulation: Simulation) -> NDArray[np.uint8]:
    """The simulation's current state as an RGB array (height, width, 3)."""
    sim = simulation
    figure = Figure(figsize=(5, 5), dpi=80)
    canvas = FigureCanvasAgg(figure)
    ax = figure.add_subplot()
    draw_floor(ax, sim.scenario, sim.route)
    rows = sim.trajectory()
    if rows:
        ax.plot([r.human_x for r in rows], [r.human_y for r in rows], color="#ff7f0e")
        ax.plot([r.robot_x for r in rows], [r.robot_y for r in rows], color="#1f77b4")
    robot = sim.robot
    pose = (robot.x, robot.y, robot.heading)
    draw_robot(ax, pose, sim.robot_params, sim.field, sim.emergency_stop)
    human_x, human_y, human_heading = sim.human_pose
    draw_human(ax, (human_x, human_y), human_heading, sim.human_params)
    ax.set_title(f"t = {sim.sim_time:.1f} s")
    canvas.draw()  # type: ignore[no-untyped-call]
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()  # type: ignore[no-untyped-call]


def animate_episode(
    path: Path,
    simulation: Scene,
    title: str = "",
    frame_step: int = 1,
    fps: int = 10,
    last_seconds: float | None = None,
    size: float = 6.0,
) -> Path:
    """Write an animated GIF of the played episode (one frame per 0.2 s sample).

    Args:
        path: The GIF to write.
        simulation: A simulation whose episode has been played, or a recorded episode.
        title: Shown above every frame, followed by the time.
        frame_step: Use every ``frame_step``-th sample.
        fps: Frames per second of the animation (10 plays twice as fast as real time).
        last_seconds: Animate only the episode's last seconds (None: all of it); the tracks
            are drawn from the start.
        size: The longer side of the picture, in inches at 80 dpi (the other follows the
            floor's proportions: :func:`floor_figure_size`).
    """
    from matplotlib.animation import FuncAnimation, PillowWriter

    every = simulation.trajectory()
    if not every:
        raise ValueError("the episode has no trajectory: play an episode first")
    since = -np.inf if last_seconds is None else every[-1].time - last_seconds
    first = next(i for i, row in enumerate(every) if row.time >= since)
    frames = list(range(first, len(every)))[::-1][::frame_step][::-1]
    figure = Figure(
        figsize=floor_figure_size(simulation.scenario, size), dpi=80, layout="constrained"
    )
    FigureCanvasAgg(figure)
    ax = figure.add_subplot()
    # Laid out once, for the frame with the longest title, so that the floor stays put.
    longest = max(frames, key=lambda index: len(frame_title(title, every[index])))
    draw_state(ax, simulation, every[: longest + 1], title)
    figure.canvas.draw()
    figure.set_layout_engine("none")
    position = ax.get_position()

    def draw(index: int) -> list[Any]:
        ax.clear()
        draw_state(ax, simulation, every[: frames[index] + 1], title)
        ax.set_position(position)
        return []

    animation = FuncAnimation(figure, draw, frames=len(frames), blit=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    animation.save(str(path), writer=PillowWriter(fps=fps))
    return path


def draw_state(
    ax: Axes, simulation: Scene, rows: Sequence[TrajectorySample], title: str = ""
) -> None:
    """The floor, both tracks up to the last of ``rows`` and the poses at that sample."""
    sim = simulation
    draw_floor(ax, sim.scenario, sim.route)
    ax.plot([r.robot_x for r in rows], [r.robot_y for r in rows], color="#1f77b4")
    ax.plot([r.human_x for r in rows], [r.human_y for r in rows], color="#ff7f0e")
    row = rows[-1]
    pose = (row.robot_x, row.robot_y, row.robot_heading)
    draw_robot(ax, pose, sim.robot_params, sim.field, row.emergency_stop)
    if row.predicted_human is not None:
        ax.plot(*np.asarray(row.predicted_human).reshape(-1, 2).T, ":", color="#ff7f0e")
    draw_human(ax, (row.human_x, row.human_y), row.human_heading, sim.human_params)
    ax.set_title(frame_title(title, row), fontsize=9)


def frame_title(title: str, row: TrajectorySample) -> str:
    """The title of the frame drawn at ``row``: ``title``, the time, and whether the emergency
    stop holds."""
    stop = ", EMERGENCY STOP" if row.emergency_stop else ""
    return f"{title}  t = {row.time:.1f} s{stop}".strip()


def plot_frames(
    path: Path,
    simulation: Scene,
    times: Sequence[float],
    captions: Sequence[str] | None = None,
    zoom: float | None = 4.0,
) -> Path:
    """Write a PNG of the played episode at a few instants side by side (a frame sequence).

    Args:
        path: The PNG to write.
        simulation: A simulation whose episode has been played.
        times: The instants, in s; each frame shows the last sample at or before it.
        captions: One caption per frame (default: the time).
        zoom: Half the width of the window around the robot, in m (None: the whole floor).
    """
    rows = simulation.trajectory()
    if not rows:
        raise ValueError("the episode has no trajectory: play an episode first")
    figure = Figure(figsize=(3.2 * len(times), 3.4), dpi=90)
    for column, moment in enumerate(times):
        upto = [row for row in rows if row.time <= moment + 1e-9] or rows[:1]
        ax = figure.add_subplot(1, len(times), column + 1)
        caption = captions[column] if captions is not None else ""
        draw_state(ax, simulation, upto, caption)
        if zoom is not None:
            centre = upto[-1]
            ax.set_xlim(centre.robot_x - zoom, centre.robot_x + zoom)
            ax.set_ylim(centre.robot_y - zoom, centre.robot_y + zoom)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    return path
