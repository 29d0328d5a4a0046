import math

import numpy as np
import pytest

from hazardhunt.world.scenario import BUILTIN_SCENARIOS, ScenarioError, load_scenario


@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_builtin_scenarios_load_on_one_shared_map(name):
    scenario = load_scenario(name)
    assert scenario.name == name
    assert scenario.floor.name == "shopfloor"
    assert (scenario.floor.width, scenario.floor.height) == (20.0, 20.0)
    assert not scenario.floor.disc_blocked(scenario.human_start.position, 0.25)


def test_initial_states_match_their_names():
    crossing, head_on, overtaking = (load_scenario(n) for n in BUILTIN_SCENARIOS)
    assert abs(crossing.human_start.heading - crossing.robot_start.heading) == pytest.approx(
        math.pi / 2
    )
    assert abs(head_on.human_start.heading - head_on.robot_start.heading) == pytest.approx(math.pi)
    assert overtaking.human_start.heading == overtaking.robot_start.heading
    assert overtaking.human_start.x > overtaking.robot_start.x  # the robot starts behind


def write(tmp_path, text, name="bad.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


SHOPFLOOR = str(load_scenario("crossing").source).replace("crossing.toml", "shopfloor.toml")

VALID = f"""
name = "mine"
map = "{SHOPFLOOR}"
[robot]
start = {{ x = 2.0, y = 10.0, heading_deg = 0.0 }}
goal = {{ x = 18.0, y = 10.0 }}
[human]
start = {{ x = 10.0, y = 5.0, heading_deg = 90.0 }}
"""


def test_a_user_scenario_file_loads(tmp_path):
    scenario = load_scenario(write(tmp_path, VALID))
    assert scenario.name == "mine"
    assert scenario.goal == pytest.approx(np.array([18.0, 10.0]))


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (("x = 2.0, y = 10.0", 'x = "two", y = 10.0'), "robot.start.x"),
        (("heading_deg = 90.0", "heading_deg = 90.0, speed = 3"), "human.start.speed"),
        (('name = "mine"', 'name = "mine"\ncolour = "red"'), "colour"),
        (("[human]", "[humans]"), "human"),
        (("x = 10.0, y = 5.0", "x = 5.0, y = 3.0"), "human.start: (5, 3) lies inside an obstacle"),
        (("x = 10.0, y = 5.0", "x = 8.6, y = 7.0"), "human.start: (8.6, 7) overlaps an obstacle"),
        (("x = 18.0, y = 10.0", "x = 25.0, y = 10.0"), "robot.goal: (25, 10) lies off"),
        (("name = ", "name = = "), "not valid TOML"),
        (
            ("heading_deg = 90.0", "heading_deg = nan"),
            "human.start.heading_deg: must be a finite",
        ),
        (("x = 2.0, y = 10.0", "x = -inf, y = 10.0"), "robot.start.x: must be a finite"),
        (("x = 10.0, y = 5.0", "x = true, y = 5.0"), "human.start.x: must be a number, not true"),
        (("x = 10.0, y = 5.0", 'x = "10", y = 5.0'), 'human.start.x: must be a number, not "10"'),
    ],
)
def test_bad_scenario_files_name_the_file_and_the_field(tmp_path, change, expected):
    path = write(tmp_path, VALID.replace(*change))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    message = str(caught.value)
    assert str(path) in message
    assert expected in message


def test_a_scenario_file_that_is_not_text_names_the_file(tmp_path):
    path = tmp_path / "binary.toml"
    path.write_bytes(VALID.encode() + b"\xff\xfe")
    with pytest.raises(ScenarioError, match=r"binary\.toml: not a text file"):
        load_scenario(path)


def test_a_missing_scenario_says_which_ones_exist(tmp_path):
    with pytest.raises(ScenarioError, match="crossing, head-on, overtaking"):
        load_scenario(tmp_path / "nope.toml")


def test_a_bad_map_names_the_map_file_and_the_obstacle(tmp_path):
    write(
        tmp_path,
        'name = "m"\nwidth = 10.0\nheight = 10.0\n[[obstacles]]\nname = "bow tie"\n'
        "polygon = [[0, 0], [2, 2], [2, 0], [0, 1]]\n",
        "map.toml",
    )
    path = write(tmp_path, VALID.replace(SHOPFLOOR, "map.toml"))
    with pytest.raises(ScenarioError, match=r"map\.toml: obstacles\.0\.polygon: .*cross"):
        load_scenario(path)


def map_file(tmp_path, table, polygon):
    write(
        tmp_path,
        f'name = "m"\nwidth = 20.0\nheight = 20.0\n[[{table}]]\nname = "x"\npolygon = {polygon}\n',
        "map.toml",
    )
    return write(tmp_path, VALID.replace(SHOPFLOOR, "map.toml"))


@pytest.mark.parametrize(
    ("table", "polygon", "expected"),
    [
        (
            "obstacles",
            "[[0, 0], [2, 2], [2, 0], [0, 1]]",
            "obstacles.0.polygon: polygon edges cross or touch each other near "
            "(0.666667, 0.666667)",
        ),
        (
            "blind_zones",
            "[[0, 0], [4, 0], [4, 4], [2, 0], [0, 4]]",  # touches its own bottom edge
            "blind_zones.0.polygon: polygon edges cross or touch each other near (2, 0)",
        ),
        ("obstacles", "[[0, 0], [1, 1], [2, 2]]", "obstacles.0.polygon: polygon has no area"),
        ("blind_zones", "[[0, 0], [1, 0], [1, 0]]", "blind_zones.0.polygon: polygon has no area"),
        (
            "obstacles",
            "[[0, 0], [1, 0], [1, nan]]",
            "obstacles.0.polygon.2.1: must be a finite number",
        ),
    ],
)
def test_a_polygon_that_is_not_a_simple_area_names_the_field(tmp_path, table, polygon, expected):
    with pytest.raises(ScenarioError) as caught:
        load_scenario(map_file(tmp_path, table, polygon))
    assert f"map.toml: {expected}" in str(caught.value)


@pytest.mark.parametrize(("size", "key"), [("width = inf", "width"), ("height = nan", "height")])
def test_a_map_of_no_finite_size_names_the_key(tmp_path, size, key):
    write(
        tmp_path,
        f'name = "m"\n{size}\n' + ("height = 20.0\n" if key == "width" else "width = 20.0\n"),
        "map.toml",
    )
    with pytest.raises(ScenarioError) as caught:
        load_scenario(write(tmp_path, VALID.replace(SHOPFLOOR, "map.toml")))
    assert f"map.toml: {key}: must be a finite number" in str(caught.value)


def round_column(vertices: int) -> list[list[float]]:
    """A column of radius 1.5 m at (15, 15) as a polygon of ``vertices`` vertices."""
    angles = np.linspace(0.0, 2 * np.pi, vertices, endpoint=False)
    return np.column_stack([15 + 1.5 * np.cos(angles), 15 + 1.5 * np.sin(angles)]).tolist()


def test_a_polygon_of_10000_vertices_loads_and_one_that_crosses_itself_does_not(tmp_path):
    column = round_column(10_000)
    floor = load_scenario(map_file(tmp_path, "obstacles", column)).floor
    assert len(floor.obstacles[0].polygon) == 10_000
    assert floor.inside_obstacle(np.array([15.0, 15.0]))
    column[5000], column[5001] = column[5001], column[5000]
    with pytest.raises(ScenarioError, match=r"obstacles\.0\.polygon: polygon edges cross"):
        load_scenario(map_file(tmp_path, "obstacles", column))


def test_polygons_are_stored_counter_clockwise_in_the_order_given(tmp_path):
    clockwise = [[1.0, 1.0], [1.0, 2.0], [2.0, 2.0], [2.0, 1.0]]
    floor = load_scenario(map_file(tmp_path, "obstacles", clockwise)).floor
    assert floor.obstacles[0].polygon.tolist() == clockwise[::-1]
    counter_clockwise = clockwise[::-1]
    floor = load_scenario(map_file(tmp_path, "blind_zones", counter_clockwise)).floor
    assert floor.blind_zones[0].tolist() == counter_clockwise


def test_a_scenario_keeps_its_field_tables_for_the_safety_layer(tmp_path):
    text = VALID + "[fields.sides]\ndiameter = 1.25\nside_margin = 0.4\n"
    scenario = load_scenario(write(tmp_path, text))
    assert scenario.fields == {"sides": {"diameter": 1.25, "side_margin": 0.4}}


def test_a_human_whose_body_reaches_off_the_floor_is_refused(tmp_path):
    # The centre lies on a floor without walls, the disc around it does not.
    path = map_file(tmp_path, "obstacles", "[[15, 15], [16, 15], [16, 16]]")
    path.write_text(path.read_text().replace("x = 10.0, y = 5.0", "x = 0.1, y = 5.0"))
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert f"{path}: human.start: (0.1, 5) lies too near the edge of the floor" in str(caught.value)


def test_an_inline_map_table_names_its_key(tmp_path):
    # The inline table of a scenario file, as a regression case holds it: the key at fault is
    # map.KEY (it was "map.str: must be text, not a table").
    from hazardhunt.world.scenario import scenario_data, scenario_from_data

    data = scenario_data("crossing")
    del data["map"]["width"]
    with pytest.raises(ScenarioError, match=r"^case\.toml: map\.width: missing$"):
        scenario_from_data(data, "case.toml")
    inline = VALID.replace(f'map = "{SHOPFLOOR}"', "").replace(
        "[robot]", '[map]\nname = "m"\nwidth = 20.0\nheigth = 20.0\n[robot]'
    )
    with pytest.raises(ScenarioError, match=r"map\.heigth: unknown key \(did you mean height\?\)"):
        load_scenario(write(tmp_path, inline))
