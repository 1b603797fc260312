import tomllib

from planner.toml_lines import key_lines, line_of

TEXT = '''# comment
name = "x"  # trailing
multi = """line one
line "two" = 3
"""
[world]
size = [15.0,
        15.0]
"quoted.key" = 1
[regions.Goal]
rects = [
    [1.0, 2.0, 3.0, 4.0],  # first
    # a comment between elements
    [5.0, 6.0, 7.0, 8.0],
]
[[runs]]
seed = 1
[[runs]]
seed = 2
inline = { a = 1, b = [1,
  2] }
dotted.sub = 'lit'
'''


def test_text_is_valid_toml():
    tomllib.loads(TEXT)


def test_key_lines_maps_keys_tables_and_elements():
    lines = key_lines(TEXT)
    assert lines["name"] == 2
    assert lines["multi"] == 3
    assert lines["world"] == 6
    assert lines["world.size"] == 7
    assert lines["world.size[1]"] == 8
    assert lines["world.quoted.key"] == 9
    assert lines["regions"] == 10
    assert lines["regions.Goal"] == 10
    assert lines["regions.Goal.rects"] == 11
    assert lines["regions.Goal.rects[0]"] == 12
    assert lines["regions.Goal.rects[1]"] == 14
    assert lines["runs[0]"] == 16
    assert lines["runs[0].seed"] == 17
    assert lines["runs[1].seed"] == 19
    assert lines["runs[1].inline.b[1]"] == 21
    assert lines["runs[1].dotted.sub"] == 22
    # The content of the multi-line string is not a key.
    assert 'line "two"' not in lines


def test_line_of_falls_back_to_enclosing_key():
    lines = key_lines(TEXT)
    assert line_of(lines, "regions.Goal.rects[1][3]") == 14
    assert line_of(lines, "regions.Goal.cells") == 10
    assert line_of(lines, "nothing.here") is None


def test_scanner_never_raises_on_garbage():
    assert isinstance(key_lines('a = [1, 2\n[b\n"unterminated'), dict)


def _paths(value, prefix=""):
    if isinstance(value, dict):
        for k, v in value.items():
            p = f"{prefix}.{k}" if prefix else k
            yield p, k
            yield from _paths(v, p)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, f"{prefix}[{i}]")


def test_every_key_of_the_shipped_scenarios_has_its_line():
    from planner.scenario import SHIPPED_SCENARIOS, resolve_scenario_path

    for name in SHIPPED_SCENARIOS:
        text = resolve_scenario_path(name).read_text()
        lines = key_lines(text)
        rows = text.splitlines()
        for path, key in _paths(tomllib.loads(text)):
            assert path in lines, (name, path)
            assert key in rows[lines[path] - 1], (name, path, rows[lines[path] - 1])
