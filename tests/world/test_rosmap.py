"""Site maps as ROS map_server writes them: the map's cells as a scenario's floor."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from hazardhunt.benchmark.conservative import ConservativeController
from hazardhunt.campaign.scenario_record import SCENARIO_FILE, played_before_change
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.route import inflated_obstacles, scenario_route
from hazardhunt.world.kinematics import move_human
from hazardhunt.world.rosmap import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    cell_rectangles,
    grid_floor,
    load_ros_map,
    rasterise,
)
from hazardhunt.world.scenario import (
    ScenarioError,
    builtin_scenario_path,
    load_scenario,
    scenario_data,
    scenario_from_data,
)
from tests.helpers import hazardhunt

SCENARIOS = builtin_scenario_path("crossing").parent

MAP_YAML = """image: {image}
resolution: {resolution}
origin: [-1.0, -2.0, 0.0]
negate: {negate}
occupied_thresh: 0.65
free_thresh: 0.25
mode: {mode}
"""


def write_map(folder, shades, *, mode="trinary", negate=0, resolution=0.5, name="site"):
    """A map_server YAML and its image (a PGM of ``shades``, top row first; a PNG when the
    array has an alpha channel)."""
    shades = np.asarray(shades, dtype=np.uint8)
    image = f"{name}.png" if shades.ndim == 3 else f"{name}.pgm"
    Image.fromarray(shades).save(folder / image)
    path = folder / f"{name}.yaml"
    path.write_text(MAP_YAML.format(image=image, resolution=resolution, negate=negate, mode=mode))
    return path


def test_trinary_cells_follow_the_thresholds_and_the_top_row_is_north(tmp_path):
    # Occupancy 1 - shade/255: black 1.0 (occupied), 0.60 and 0.30 in between, white 0.
    grid = load_ros_map(write_map(tmp_path, [[0, 102], [179, 255]]))
    assert grid.cells.tolist() == [[UNKNOWN, FREE], [OCCUPIED, UNKNOWN]]
    assert grid.origin == (-1.0, -2.0, 0.0)
    assert (grid.width, grid.height) == (1.0, 1.0)


def test_map_savers_grey_is_unknown_below_a_free_threshold_of_0_196_as_in_ros(tmp_path):
    # Grey 205 is occupancy 0.196..., which nav2's default free_thresh of 0.25 reads as free.
    path = write_map(tmp_path, [[205, 254]])
    assert load_ros_map(path).cells.tolist() == [[FREE, FREE]]
    path.write_text(path.read_text().replace("free_thresh: 0.25", "free_thresh: 0.196"))
    assert load_ros_map(path).cells.tolist() == [[UNKNOWN, FREE]]


def test_negate_swaps_black_and_white(tmp_path):
    grid = load_ros_map(write_map(tmp_path, [[0, 255]], negate=1))
    assert grid.cells.tolist() == [[FREE, OCCUPIED]]


def test_scale_mode_grades_the_cells_in_between_and_transparency_is_unknown(tmp_path):
    # Occupancy 0.45 lies halfway between the thresholds; a transparent pixel is unknown.
    pixels = [[[0, 0, 0, 255], [140, 140, 140, 255], [255, 255, 255, 255], [0, 0, 0, 0]]]
    grid = load_ros_map(write_map(tmp_path, pixels, mode="scale"))
    assert grid.cells.tolist() == [[OCCUPIED, 50, FREE, UNKNOWN]]


def test_trinary_mode_averages_the_transparency_in(tmp_path):
    # White but transparent: shade (3 x 1 + 0) / 4 = 0.75, occupancy 0.25, not below free.
    grid = load_ros_map(write_map(tmp_path, [[[255, 255, 255, 0], [255, 255, 255, 255]]]))
    assert grid.cells.tolist() == [[UNKNOWN, FREE]]


def test_raw_mode_takes_the_shade_as_the_value(tmp_path):
    grid = load_ros_map(write_map(tmp_path, [[0, 37, 100, 101, 255]], mode="raw"))
    assert grid.cells.tolist() == [[FREE, 37, OCCUPIED, UNKNOWN, UNKNOWN]]


def test_an_ascii_pgm_reads_like_a_binary_one(tmp_path):
    (tmp_path / "site.pgm").write_text("P2\n# a comment\n3 1\n255\n0 128 254\n")
    path = tmp_path / "site.yaml"
    path.write_text(MAP_YAML.format(image="site.pgm", resolution=0.05, negate=0, mode="trinary"))
    assert load_ros_map(path).cells.tolist() == [[OCCUPIED, UNKNOWN, FREE]]


def test_cells_merge_into_rectangles_that_cover_each_blocked_cell_once():
    rng = np.random.default_rng(3)
    blocked = rng.random((30, 40)) < 0.4
    covered = np.zeros(blocked.shape, dtype=int)
    for x0, y0, x1, y1 in cell_rectangles(blocked):
        covered[y0:y1, x0:x1] += 1
    assert (covered == blocked).all()


ROOM = """
name = "room"
map = "site.yaml"
[robot]
start = {{ x = 1.0, y = 1.0, heading_deg = 0.0 }}
goal = {{ x = 9.0, y = 1.0 }}
[human]
start = {{ x = {human_x}, y = 5.0, heading_deg = 0.0 }}
"""


def room(tmp_path, wall=0, human_x=3.0):
    """A 10 m x 10 m room at 0.5 m per cell: an outer wall, and a wall of shade ``wall``
    (0: occupied, 128: unknown) at x 5..6 m from y 0.5 m to 8 m, the robot's way from
    (1, 1) to (9, 1) leading round it through the north."""
    shades = np.full((20, 20), 254, dtype=np.uint8)
    shades[0, :] = shades[-1, :] = shades[:, 0] = shades[:, -1] = 0
    shades[4:19, 10:12] = wall  # image rows 4..18 are y 0.5..8 m
    write_map(tmp_path, shades)
    path = tmp_path / "room.toml"
    path.write_text(ROOM.format(human_x=human_x))
    return load_scenario(path)


@pytest.mark.parametrize("wall", [0, 128], ids=["occupied", "unknown"])
def test_blocked_cells_stop_the_human_and_turn_the_route(tmp_path, wall):
    scenario = room(tmp_path, wall)
    floor = scenario.floor
    assert (floor.width, floor.height) == (10.0, 10.0)
    assert floor.inside_obstacle(np.array([5.5, 4.0]))
    assert not floor.inside_obstacle(np.array([5.5, 9.0]))
    # The human walking east at 1.5 m/s for 2 s stops at the wall's face, x = 5 m.
    x = 3.0
    for _ in range(40):
        x = move_human(x, 5.0, 0.0, 1.5, 0.0, 0.05, floor, 0.25).x
    assert x == pytest.approx(4.75, abs=0.08)
    route = scenario_route(scenario, 0.5)
    assert route.points[:, 1].max() > 8.0  # round the wall's north end
    assert route.length > 16.0


def test_a_scenario_on_a_map_places_its_points_on_free_cells(tmp_path):
    with pytest.raises(ScenarioError, match=r"room\.toml: human\.start: \(5\.5, 5\) lies inside"):
        room(tmp_path, human_x=5.5)


def test_the_shipped_shop_floor_map_is_the_built_in_floor_rasterised(tmp_path):
    polygons = load_scenario("crossing").floor
    grid = load_ros_map(SCENARIOS / "shopfloor.yaml")
    assert np.array_equal(grid.cells, rasterise(polygons, 0.1).cells)
    on_map = load_scenario(crossing_on_map(SCENARIOS, tmp_path)).floor

    def rectangles(floor):
        return sorted(tuple(map(tuple, o.polygon.tolist())) for o in floor.obstacles)

    # Every wall and shelf edge lies on a cell boundary: the same rectangles, to the bit.
    assert rectangles(on_map) == rectangles(polygons)


def crossing_on_map(scenarios, folder):
    """The built-in crossing scenario with the shop floor's ROS map for its map."""
    text = (
        (scenarios / "crossing.toml")
        .read_text()
        .replace('map = "shopfloor.toml"', f'map = "{scenarios / "shopfloor.yaml"}"')
    )
    path = folder / "crossing-on-map.toml"
    path.write_text(text)
    return path


SEEDS = range(4)


def seeded_actions(simulation, seed):
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (simulation.horizon, 2))


def test_the_crossing_plays_the_same_episodes_on_the_map_as_on_the_polygons(tmp_path):
    # The floor's physics does not depend on the order the obstacles are listed in: with a
    # controller that plans nothing around them the episodes are equal to the bit.
    on_map = load_scenario(crossing_on_map(SCENARIOS, tmp_path))
    polygons = load_scenario("crossing")
    for seed in SEEDS:
        a, b = (
            Simulation.build(s, "1.25m", controller=ConservativeController())
            for s in (polygons, on_map)
        )
        first, second = (s.simulate(seeded_actions(s, seed)) for s in (a, b))
        assert first.summary == second.summary
        assert first.trajectory == second.trajectory


NMPC_TOLERANCE = 1e-4
"""m: how far the robot and the human may be apart on the two floors with the NMPC."""


def test_the_nmpc_crossing_on_the_map_ends_alike_within_a_tenth_of_a_millimetre(tmp_path):
    # The robot drives the main aisle's centre line, 1.5 m from the shelf blocks on either
    # side: equidistant obstacles reach the NMPC's constraints in the order the floor lists
    # them (the map lists its rectangles south to north), which moves the solver's answers by
    # far less than a millimetre; outcomes and contact faces agree.
    on_map = load_scenario(crossing_on_map(SCENARIOS, tmp_path))
    a, b = (Simulation.build(s, "1.25m") for s in (load_scenario("crossing"), on_map))
    for seed in SEEDS:
        first, second = (s.simulate(seeded_actions(s, seed)) for s in (a, b))
        assert first.outcome == second.outcome
        assert first.summary.contact_face == second.summary.contact_face
        assert len(first.trajectory) == len(second.trajectory)
        for x, y in zip(first.trajectory, second.trajectory, strict=True):
            gap = max(
                abs(x.robot_x - y.robot_x),
                abs(x.robot_y - y.robot_y),
                abs(x.human_x - y.human_x),
                abs(x.human_y - y.human_y),
            )
            assert gap < NMPC_TOLERANCE


def test_a_run_records_the_map_and_notices_it_changed(tmp_path):
    scenario_file = room(tmp_path).source
    data = scenario_data(scenario_file)
    assert data["map"]["occupancy"]["columns"] == 20
    rebuilt = scenario_from_data(json.loads(json.dumps(data)), "scenario.json")
    assert np.array_equal(
        rebuilt.floor.occupancy.cells, load_scenario(scenario_file).floor.occupancy.cells
    )
    assert len(rebuilt.floor.obstacles) == len(load_scenario(scenario_file).floor.obstacles)
    run = tmp_path / "run"
    run.mkdir()
    (run / SCENARIO_FILE).write_text(json.dumps(data))
    assert played_before_change(scenario_file, run) is None
    # A shelf drawn into the image, or a threshold moved, is a changed scenario.
    shades = np.asarray(Image.open(tmp_path / "site.pgm")).copy()
    shades[2, 2] = 0
    Image.fromarray(shades).save(tmp_path / "site.pgm")
    assert (
        played_before_change(scenario_file, run)
        == f"played on {scenario_file} before the file changed"
    )
    room(tmp_path)
    yaml_path = tmp_path / "site.yaml"
    yaml_path.write_text(yaml_path.read_text().replace("free_thresh: 0.25", "free_thresh: 0.0"))
    assert played_before_change(scenario_file, run) is not None


GOOD = {
    "image": "site.pgm",
    "resolution": "0.5",
    "origin": "[0.0, 0.0, 0.0]",
    "negate": "0",
    "occupied_thresh": "0.65",
    "free_thresh": "0.25",
}


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("resolution", None, "resolution: missing"),
        ("resolution", "0", "resolution: must be greater than 0"),
        ("resolution", '"0.05"', 'resolution: must be a number, not "0.05"'),
        ("origin", "[0.0, 0.0]", "origin: must be [x, y, yaw], not 2 numbers"),
        ("occupied_thresh", "1.5", "occupied_thresh: must be less than or equal to 1"),
        ("free_thresh", "0.7", "free_thresh: must be less than occupied_thresh (0.65), not 0.7"),
        ("negate", "2", "negate: must be 0 or 1"),
        ("mode", "fancy", "mode: must be 'trinary', 'scale' or 'raw'"),
        ("image", None, "image: missing"),
        ("image", "nothere.pgm", "image: 'nothere.pgm': no such image file"),
        ("image", "notes.pgm", "image: 'notes.pgm' is not an image (PGM, PNG or BMP)"),
        ("image", "cut.pgm", "image: 'cut.pgm' cannot be read"),
        ("image", "photo.jpg", "image: 'photo.jpg' is a JPEG image, not one of BMP, PGM, PNG"),
    ],
)
def test_a_bad_map_is_one_line_naming_the_file_and_the_field(tmp_path, key, value, expected):
    room(tmp_path)
    (tmp_path / "notes.pgm").write_text("a shopping list\n")
    (tmp_path / "cut.pgm").write_bytes(b"P5\n20 20\n255\n" + bytes(50))
    Image.new("L", (4, 4)).save(tmp_path / "photo.jpg")
    fields = dict(GOOD)
    if value is None:
        del fields[key]
    else:
        fields[key] = value
    (tmp_path / "site.yaml").write_text("".join(f"{k}: {v}\n" for k, v in fields.items()))
    with pytest.raises(ScenarioError) as error:
        load_scenario(tmp_path / "room.toml")
    message = str(error.value)
    assert message.startswith(f"{tmp_path / 'site.yaml'}: {expected}")
    assert "\n" not in message


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("image: [unclosed\n", r"not valid YAML \(line 2\)"),
        ("just a line\n", "not a map_server map"),
    ],
)
def test_a_map_file_that_is_no_map_names_the_file(tmp_path, text, expected):
    room(tmp_path)
    (tmp_path / "site.yaml").write_text(text)
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(tmp_path))}/site.yaml: {expected}"):
        load_scenario(tmp_path / "room.toml")


def test_an_inlined_grid_that_does_not_fit_names_the_field(tmp_path):
    data = scenario_data(room(tmp_path).source)
    data["map"]["occupancy"]["rows"] = 19
    with pytest.raises(ScenarioError, match=r"^case: map\.occupancy\.cells: holds 400 cells"):
        scenario_from_data(data, "case")
    data["map"]["occupancy"]["rows"] = 20
    data["map"]["width"] = 12.0
    with pytest.raises(ScenarioError, match=r"^case: map\.\(top level\): width, height: must"):
        scenario_from_data(data, "case")


def test_a_run_on_a_bad_map_exits_2_before_writing_anything(tmp_path):
    room(tmp_path)
    (tmp_path / "site.yaml").write_text(
        (tmp_path / "site.yaml").read_text().replace("resolution: 0.5", "resolution: -1")
    )
    out = tmp_path / "out"
    result = hazardhunt("run", "--scenario", tmp_path / "room.toml", "--out", out, "--episodes", 2)
    assert result.returncode == 2
    assert f"{tmp_path / 'site.yaml'}: resolution: must be greater than 0" in result.stderr
    assert not out.exists()


EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "site_map"


def test_the_warehouse_example_plans_round_one_outline_per_group_of_cells():
    from scipy.ndimage import label

    scenario = load_scenario(EXAMPLE / "warehouse_crossing.toml")
    floor = scenario.floor
    assert floor.occupancy is not None
    assert floor.occupancy.origin == (-4.5, -2.25, 0.0)
    _, groups = label(floor.occupancy.blocked())  # cells that share a side
    # Hundreds of rectangles of cells, a few dozen connected groups to plan round.
    assert len(floor.obstacles) > 10 * groups
    assert len(inflated_obstacles(floor, 0.5)) <= groups
    route = scenario_route(scenario, 0.5)
    assert route.points[-1].tolist() == [28.0, 10.0]


def test_the_nearest_obstacle_point_on_a_map_of_many_rectangles_is_the_nearest():
    # The human slides along what it touches: the point it is pushed away from must be the
    # nearest of all the map's rectangles (the search takes the nearest boxes first).
    floor = load_scenario(EXAMPLE / "warehouse_crossing.toml").floor
    points = np.random.default_rng(5).uniform((0.0, 0.0), (floor.width, floor.height), (300, 2))
    for point in np.vstack([points, np.round(points * 4) / 4]):
        nearest = floor.nearest_obstacle_point(point)
        assert math.hypot(*(nearest - point)) == pytest.approx(
            floor.boundary_distance(point), abs=1e-12
        )


@pytest.mark.slow
def test_a_campaign_resumed_after_the_map_image_changed_plays_its_run_again(tmp_path):
    room(tmp_path)
    file, out = tmp_path / "campaign.toml", tmp_path / "campaign"
    file.write_text(
        'scenarios = ["room.toml"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [0]\n'
        "episodes = 2\n"
    )
    assert hazardhunt("campaign", file, "--out", out).returncode == 0
    assert "before the file changed" not in hazardhunt("campaign", file, "--out", out).stdout
    shades = np.asarray(Image.open(tmp_path / "site.pgm")).copy()
    shades[2, 2] = 0  # a crate in the north-west corner
    Image.fromarray(shades).save(tmp_path / "site.pgm")
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 0, result.stderr
    assert (
        f"run room__none__random__seed0 was played on {tmp_path / 'room.toml'} before the file "
        "changed; running it again" in " ".join(result.stdout.split())
    )
    recorded = json.loads((out / "runs" / "room__none__random__seed0" / SCENARIO_FILE).read_text())
    assert recorded == json.loads(json.dumps(scenario_data(tmp_path / "room.toml")))


def test_a_point_off_a_map_with_an_origin_says_where_positions_are_measured_from(tmp_path):
    scenario = (EXAMPLE / "warehouse_crossing.toml").read_text()
    (tmp_path / "warehouse.yaml").write_text((EXAMPLE / "warehouse.yaml").read_text())
    (tmp_path / "warehouse.png").write_bytes((EXAMPLE / "warehouse.png").read_bytes())
    # The goal as the map's own frame has it: 4.5 m west and 2.25 m south of the floor's.
    moved = tmp_path / "moved.toml"
    moved.write_text(scenario.replace("x = 28.0, y = 10.0", "x = 23.5, y = -2.25"))
    with pytest.raises(ScenarioError) as error:
        load_scenario(moved)
    assert str(error.value) == (
        f"{moved}: robot.goal: (23.5, -2.25) lies off the 30 m x 20 m floor (positions are "
        "measured from the map's lower-left corner, at (-4.5, -2.25) in the map's frame)"
    )


def test_any_floor_rasterises_to_the_cells_whose_centres_lie_in_an_obstacle():
    from hazardhunt.world.floor import FloorMap, Obstacle
    from hazardhunt.world.geometry import point_in_polygon

    triangle = np.array([[1.0, 1.0], [4.2, 1.3], [2.1, 3.7]])
    floor = FloorMap("triangle", 5.0, 4.0, (Obstacle("slab", triangle),))
    grid = rasterise(floor, 0.25)
    assert grid.cells.shape == (16, 20)
    for row in range(16):
        for column in range(20):
            centre = np.array([(column + 0.5) * 0.25, (row + 0.5) * 0.25])
            inside = point_in_polygon(centre, triangle)
            assert grid.cells[row, column] == (OCCUPIED if inside else FREE)
    with pytest.raises(ValueError, match=r"no whole number of 0\.3 m cells"):
        rasterise(floor, 0.3)


def test_a_turned_map_frame_is_kept_and_leaves_the_floor_along_the_image(tmp_path):
    path = write_map(tmp_path, [[0, 254], [254, 254]])
    straight = grid_floor("site", load_ros_map(path))
    path.write_text(path.read_text().replace("[-1.0, -2.0, 0.0]", "[-1.0, -2.0, 0.5]"))
    turned = load_ros_map(path)
    assert turned.origin == (-1.0, -2.0, 0.5)
    # The image's top-left cell is the floor's north-west corner either way.
    assert [o.polygon.tolist() for o in grid_floor("site", turned).obstacles] == [
        o.polygon.tolist() for o in straight.obstacles
    ]
    assert straight.inside_obstacle(np.array([0.25, 0.75]))
