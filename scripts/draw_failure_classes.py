"""Draw one schematic per failure class of the default taxonomy into docs/images/classes/.

Each picture is in the robot's frame (the robot drives to the right): the robot, its protective
field where the class has one (red once the stop holds), the human's path as an arrow ending at
the contact, an octagon where the human triggered the stop, and a blue arrow for the robot's own
motion where it is the robot that closes the gap. Run from the repository root:

    .venv/bin/python scripts/draw_failure_classes.py
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hazardhunt.env.rendering import draw_human, draw_robot
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.bodies import HumanParams, RobotParams

OUT = Path(__file__).resolve().parent.parent / "docs" / "images" / "classes"
FIELD = FIELD_SETTINGS["1.25m"]
NO_FIELD = FIELD_SETTINGS["none"]
"""Field diameter drawn for the classes with a field, in m."""

Point = tuple[float, float]


@dataclass(frozen=True)
class Sketch:
    """What to draw for one class, in the robot's frame (x ahead, y to the left), in m."""

    field: bool
    """Whether the robot has a protective field."""
    path: tuple[Point, ...]
    """The human's path; its last point is the human's centre at contact."""
    stop: Point | None = None
    """Where the human triggered the emergency stop, if it did."""
    braking: bool = False
    """Whether the stop still holds at contact (the field is drawn red)."""
    robot_moves: Point | None = None
    """The robot's own motion, as an arrow from its centre to this point."""
    robot_turns: float = 0.0
    """Bend of that arrow for a turning robot (matplotlib's ``arc3`` radius; 0: straight)."""


def mirrored(sketch: Sketch) -> Sketch:
    """The same sketch on the robot's other side."""

    def flip(point: Point | None) -> Point | None:
        return None if point is None else (point[0], -point[1])

    return Sketch(
        field=sketch.field,
        path=tuple((x, -y) for x, y in sketch.path),
        stop=flip(sketch.stop),
        braking=sketch.braking,
        robot_moves=flip(sketch.robot_moves),
        robot_turns=-sketch.robot_turns,
    )


LEFT_NO_STOP = Sketch(True, ((0.0, 1.3), (-0.05, 0.5)))
LEFT_RESTARTED = Sketch(
    True,
    ((1.7, 1.3), (0.75, 0.75), (0.15, 0.62), (-0.15, 0.5)),
    stop=(0.75, 0.75),
    robot_moves=(0.3, 0.0),
)
LEFT_BRAKING = Sketch(True, ((1.4, 1.3), (0.42, 0.48)), stop=(0.78, 0.86), braking=True)
LEFT_MOVING = Sketch(False, ((0.0, 1.3), (-0.05, 0.5)))
LEFT_STANDING = Sketch(False, ((0.45, 0.45),), robot_moves=(0.3, -0.12), robot_turns=0.3)

SKETCHES: dict[str, Sketch] = {
    "side-left/no-stop": LEFT_NO_STOP,
    "side-right/no-stop": mirrored(LEFT_NO_STOP),
    "side-left/restarted": LEFT_RESTARTED,
    "side-right/restarted": mirrored(LEFT_RESTARTED),
    "side-left/braking": LEFT_BRAKING,
    "side-right/braking": mirrored(LEFT_BRAKING),
    "field/braking/moving": Sketch(True, ((1.7, 0.0), (0.57, 0.0)), stop=(1.2, 0.0), braking=True),
    "field/braking/standing": Sketch(
        True, ((1.7, 0.3), (1.0, 0.05), (0.6, 0.0)), stop=(1.2, 0.12), braking=True
    ),
    "edge-entry/moving": Sketch(
        True, ((-0.6, -1.2), (0.07, -0.58), (0.12, -0.49)), stop=(0.07, -0.58), braking=True
    ),
    "edge-entry/standing": Sketch(
        True,
        ((-0.6, -1.2), (0.1, -0.52)),
        stop=(0.07, -0.58),
        braking=True,
        robot_moves=(0.3, -0.12),
        robot_turns=-0.3,
    ),
    "front/moving": Sketch(False, ((1.5, -1.1), (1.0, -0.3), (0.57, 0.0))),
    "front/standing": Sketch(False, ((0.6, 0.0),), robot_moves=(0.35, 0.0)),
    "left/moving": LEFT_MOVING,
    "right/moving": mirrored(LEFT_MOVING),
    "left/standing": LEFT_STANDING,
    "right/standing": mirrored(LEFT_STANDING),
    "rear/moving": Sketch(False, ((-0.2, -1.3), (-0.7, -0.5), (-0.55, -0.42))),
    "rear/standing": Sketch(False, ((-0.58, -0.15),), robot_moves=(0.25, -0.12), robot_turns=-0.5),
    "other": Sketch(True, ((-0.2, -1.3), (-0.7, -0.5), (-0.55, -0.42))),
}
"""A sketch for every class the default classifier names, with a field and without."""


def draw_sketch(ax: Axes, sketch: Sketch, robot: RobotParams, human: HumanParams) -> None:
    """The robot, its field, the human at contact, the paths and the stop marker."""
    draw_robot(ax, (0.0, 0.0, 0.0), robot, FIELD if sketch.field else NO_FIELD, sketch.braking)
    contact = sketch.path[-1]
    before = sketch.path[-2] if len(sketch.path) > 1 else (0.0, 0.0)
    heading = math.atan2(contact[1] - before[1], contact[0] - before[0])
    draw_human(ax, contact, heading, human, alpha=0.45)
    if len(sketch.path) > 1:
        xs, ys = zip(*sketch.path, strict=True)
        ax.plot(xs[:-1], ys[:-1], color="#d9730d", linewidth=1.5, zorder=6)
        ax.annotate(
            "",
            xy=contact,
            xytext=before,
            arrowprops={"arrowstyle": "-|>", "color": "#d9730d", "linewidth": 1.5},
            zorder=6,
        )
    if sketch.robot_moves is not None:
        ax.annotate(
            "",
            xy=sketch.robot_moves,
            xytext=(0.0, 0.0),
            arrowprops={
                "arrowstyle": "-|>",
                "color": "white",
                "linewidth": 1.5,
                "connectionstyle": f"arc3,rad={sketch.robot_turns}",
            },
            zorder=6,
        )
    if sketch.stop is not None:
        ax.plot(*sketch.stop, marker="8", markersize=8, color="#d62728", zorder=7)
    ax.set_xlim(-1.4, 2.0)
    ax.set_ylim(-1.3, 1.3)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def write_picture(name: str, sketch: Sketch, out: Path) -> Path:
    """Write one class's picture (about 300 x 220 px) and return its path."""
    figure = Figure(figsize=(3.0, 2.2), dpi=100)
    FigureCanvasAgg(figure)
    ax = figure.add_axes((0.02, 0.02, 0.96, 0.86))
    draw_sketch(ax, sketch, RobotParams(), HumanParams())
    figure.suptitle(name, fontsize=9, y=0.97)
    path = out / f"{name.replace('/', '_')}.png"
    figure.savefig(path)
    return path


def main() -> None:
    classifier = MechanismClassifier()
    names = dict.fromkeys((*classifier.classes_for(FIELD), *classifier.classes_for(NO_FIELD)))
    missing = set(names) - set(SKETCHES)
    if missing:
        raise SystemExit(f"no sketch for {sorted(missing)}")
    OUT.mkdir(parents=True, exist_ok=True)
    for name in names:
        print(write_picture(name, SKETCHES[name], OUT))


if __name__ == "__main__":
    main()
