import sys

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from planner._util.toml_lines import key_lines, line_of

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


# --- property: generated documents -----------------------------------------------------
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_keys = st.one_of(
    st.from_regex(r"[a-z][a-z0-9_-]{0,5}", fullmatch=True),
    st.from_regex(r"[a-z .#=\[\]]{1,6}", fullmatch=True).map(lambda k: f'"{k}"'),
)
_scalars = st.one_of(
    st.integers(-100, 100).map(str),
    st.floats(-10, 10, allow_nan=False).map(repr),
    st.booleans().map(lambda b: "true" if b else "false"),
    st.from_regex(r"[a-z \[\]=#,]{0,8}", fullmatch=True).map(lambda s: f'"{s}"'),
    st.from_regex(r"[a-z \[\]=#,]{0,8}", fullmatch=True).map(lambda s: f"'{s}'"),
)


@st.composite
def _value(draw, depth=0):
    if depth >= 2 or draw(st.booleans()):
        return draw(_scalars)
    items = draw(st.lists(_value(depth + 1), max_size=3))
    sep = ",\n  # note\n  " if draw(st.booleans()) else ", "
    return "[" + sep.join(items) + "]"


@st.composite
def _document(draw):
    lines: list[str] = []
    for _ in range(draw(st.integers(0, 3))):
        lines.append(f"{draw(_keys)} = {draw(_value())}  # c")
    for _ in range(draw(st.integers(0, 3))):
        header = ".".join(draw(st.lists(_keys, min_size=1, max_size=2)))
        lines.append(f"[{header}]" if draw(st.booleans()) else f"[[{header}]]")
        for _ in range(draw(st.integers(0, 3))):
            lines.append(f"{draw(_keys)} = {draw(_value())}")
    return "\n".join(lines) + "\n"


# Generation speed depends on the machine's load; only the property matters here.
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_document())
def test_generated_documents_map_every_key(text):
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return  # duplicate keys or tables: not a document to locate keys in
    lines = key_lines(text)
    rows = text.splitlines()
    for path, key in _paths(data):
        assert path in lines, (path, text)
        assert key in rows[lines[path] - 1], (path, text)


def test_headers_inside_arrays_of_tables():
    text = "[[a]]\nx = 1\n[a.b]\ny = 2\n[[a]]\n[[a.c]]\nz = 3\n[[a.c]]\nz = 4\n"
    data = tomllib.loads(text)
    assert data["a"][1]["c"][1]["z"] == 4
    lines = key_lines(text)
    assert lines["a[0].b.y"] == 4
    assert lines["a[1]"] == 5
    assert lines["a[1].c[0].z"] == 7
    assert lines["a[1].c[1].z"] == 9
    for path, _ in _paths(data):
        assert path in lines
