import json
import struct

from hopper_sim.cli import main
from tests.planner.scenario_texts import BASE


def test_scenario_command_prints_map(capsys):
    assert main(["scenario", "a"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if len(line) == 15 and set(line) <= set(".#GsABw@")]
    assert len(rows) == 15
    assert rows[14 - 7][1] == "@"  # start cell (1, 7)
    assert all(row[7] in "#." for row in rows) and rows[14 - 7][7] == "."  # wall with a gap


def test_scenario_command_json_and_png(tmp_path, capsys):
    png = tmp_path / "world.png"
    assert main(["scenario", "d", "--json", "--png", str(png)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["reward_known"] is False and data["runner"]["runs"] == 10
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert struct.unpack(">II", png.read_bytes()[16:24]) == (1600, 1120)  # 8 x 5.6 in, 200 dpi


def test_scenario_command_writes_svg_and_pdf_by_extension(tmp_path, capsys):
    svg, pdf = tmp_path / "world.svg", tmp_path / "world.pdf"
    assert main(["scenario", "a", "--png", str(svg)]) == 0
    assert main(["scenario", "a", "--png", str(pdf)]) == 0
    assert svg.read_bytes().startswith(b"<?xml") and pdf.read_bytes().startswith(b"%PDF-")
    capsys.readouterr()
    assert main(["scenario", "a", "--png", str(tmp_path / "world.bmp")]) == 2
    err = capsys.readouterr().err
    assert "unknown figure format '.bmp'" in err and len(err.strip().splitlines()) == 1


def test_scenario_command_reports_key_and_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(BASE.replace("[2, 2],", "[3, 2],"))
    assert main(["scenario", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}, line 12: key 'regions.Goal'" in err and "share cells" in err
