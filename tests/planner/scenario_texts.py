"""A small valid scenario text; tests derive malformed variants from it."""

BASE = """\
name = "tiny"
formula = "!Haz U Goal"

[world]
size = [4.0, 3.0]
cell = 1.0

[initial]
cells = [[0, 1]]
start = [0.5, 1.5]

[regions.Goal]
rects = [[3.0, 0.0, 4.0, 3.0]]

[regions.Haz]
cells = [
    [2, 0],
    [2, 2],
]

[regions.A]
cells = [[1, 2]]

[rewards]
A = 20.0
"""
