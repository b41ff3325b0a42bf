"""Foreign measurement files: a column map with units (pint), and every fault named by
file, line and column; ``boomfmi recording import`` into the recording format."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from boomfmi.cli import main
from boomfmi.foreign import (import_recording, parse_map, read_foreign, read_options, read_with,
                             recording_frame)
from boomfmi.recording import RecordingError, read_recording

REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "cylinder-friction-leak"
needs_real = pytest.mark.skipif(not REAL.is_dir(), reason=f"the real data are not at {REAL}")

TAB = "0.000\t3.5\t1.4\t3.2\t0.004\t2.992\t149.425\n10.000\t3.5\t1.4\t3.2\t0.120\t2.993\t149.470\n"
MAP = "t=1:ms,x=5:mm,p_gauge=6:bar,F=7:N"


def write(tmp_path, text, name="data.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_and_converts_units_by_the_map(tmp_path):
    table = read_foreign(write(tmp_path, TAB), MAP, delimiter="tab")
    assert table.columns["t"].tolist() == [0.0, 0.01]
    assert table.columns["x"] == pytest.approx([4e-6, 1.2e-4])
    assert table.columns["p_gauge"] == pytest.approx([299200.0, 299300.0])
    assert table.columns["F"].tolist() == [149.425, 149.470]
    assert table.lines.tolist() == [1, 2]
    assert table.gauge() == pytest.approx([299200.0, 299300.0])


def test_wrong_delimiter_names_file_line_and_the_delimiter_found(tmp_path):
    path = write(tmp_path, TAB.replace("\t", ","))
    with pytest.raises(RecordingError) as e:
        read_foreign(path, MAP, delimiter="tab")
    msg = str(e.value)
    assert str(path) in msg and "line 1" in msg and "column '7'" in msg
    assert "1 field where the map needs column 7" in msg and "not separated by --delimiter 'tab'" in msg
    assert "commas" in msg


def test_unknown_unit_names_the_map_entry(tmp_path):
    with pytest.raises(RecordingError) as e:
        read_foreign(write(tmp_path, TAB), "t=1:ms,x=5:furlongz", delimiter="tab")
    assert "map entry 'x=5:furlongz': pint does not know the unit 'furlongz'" in str(e.value)
    assert "column '5'" in str(e.value)


def test_unit_of_the_wrong_dimension_is_refused(tmp_path):
    with pytest.raises(RecordingError) as e:
        read_foreign(write(tmp_path, TAB), "t=1:ms,x=6:bar", delimiter="tab")
    msg = str(e.value)
    assert "map entry 'x=6:bar': 'bar' is a unit of [mass] / [length] / [time] ** 2" in msg
    assert "x (piston position) needs a unit of [length] such as m" in msg


def test_pressure_must_say_gauge_or_absolute(tmp_path):
    with pytest.raises(RecordingError, match=r"map entry 'p=6:bar': say whether the pressure is gauge or "
                                             r"absolute: p_gauge=\.\.\. or p_abs=\.\.\."):
        parse_map("t=1:ms,p=6:bar", tmp_path / "x.csv")


def test_column_beyond_the_rows_fields(tmp_path):
    path = write(tmp_path, TAB)
    with pytest.raises(RecordingError) as e:
        read_foreign(path, "t=1:ms,F=9:N", delimiter="tab")
    msg = str(e.value)
    assert f"{path}, line 1, column '9'" in msg
    assert "7 fields where the map needs column 9 (F, map entry 'F=9:N'): a column the file does not have" in msg


def test_header_name_not_found(tmp_path):
    path = write(tmp_path, "Tijd (s);Test 1\n0,0;0\n0,1;-1\n")
    with pytest.raises(RecordingError) as e:
        read_foreign(path, "t=Tijd (s):s,dp=Test 9:mbar", delimiter="semicolon", decimal=",", header=True)
    msg = str(e.value)
    assert f"{path}, line 1, column 'Test 9'" in msg
    assert "no column 'Test 9' in the header (it has 'Tijd (s)', 'Test 1')" in msg
    with pytest.raises(RecordingError, match="names a column by its header: give --header"):
        read_foreign(path, "t=Tijd (s):s", delimiter="semicolon", decimal=",")


def test_text_in_a_number_gives_line_column_and_text(tmp_path):
    lines = TAB.splitlines()
    path = write(tmp_path, "skip me\n" + lines[0] + "\n" + lines[1].replace("0.120", "0.1x0") + "\n")
    with pytest.raises(RecordingError) as e:
        read_foreign(path, MAP, delimiter="tab", skip_rows=1)
    msg = str(e.value)
    assert f"{path}, line 3, column '5': '0.1x0' is not a number (x, map entry 'x=5:mm')" in msg


def test_decimal_comma_and_thousands_separator_are_checked(tmp_path):
    path = write(tmp_path, "t;p\n1.000,5;7,25\n1.001,5;7,5\n")
    table = read_foreign(path, "t=1:ms,p_gauge=2:bar", delimiter=";", skip_rows=1, decimal=",", thousands=".")
    assert table.columns["t"] == pytest.approx([1.0005, 1.0015])
    assert table.columns["p_gauge"] == pytest.approx([725000.0, 750000.0])
    bad = write(tmp_path, "1.00,5;7,25\n", "bad.csv")           # a '.' that does not group thousands
    with pytest.raises(RecordingError, match=r"line 1, column '1': '1\.00,5' is not a number \(with --decimal "
                                             r"',' and --thousands '\.'\)"):
        read_foreign(bad, "t=1:ms,p_gauge=2:bar", delimiter=";", decimal=",", thousands=".")
    with pytest.raises(RecordingError, match=r"'7,5' is not a number \(a decimal comma\? give --decimal ,\)"):
        read_foreign(write(tmp_path, "1\t7,5\n", "c.csv"), "t=1:s,p_gauge=2:bar", delimiter="tab")


def test_separators_per_column(tmp_path):
    """A time written with '.' grouping beside a pressure with a decimal point."""
    path = write(tmp_path, "0.000;3.658;7.315\n143.495.000;3.774;7.547\n")
    table = read_foreign(path, "t=1:us,p_gauge=3:bar", delimiter="semicolon", thousands={"t": "."})
    assert table.columns["t"] == pytest.approx([0.0, 143.495])
    assert table.columns["p_gauge"] == pytest.approx([731500.0, 754700.0])


def test_non_finite_and_decreasing_time(tmp_path):
    path = write(tmp_path, TAB.replace("149.470", "nan"))
    with pytest.raises(RecordingError, match=r"line 2, column '7': 'nan' is not a finite number \(F\)"):
        read_foreign(path, MAP, delimiter="tab")
    path = write(tmp_path, "0\t0\t0\t0\n0.5\t1\t1\t1\n0.2\t2\t0\t0\n", "back.csv")
    with pytest.raises(RecordingError, match=r"line 3, column '1': as a recording: time does not increase"):
        import_recording(path, tmp_path / "rec.csv",
                         read_options(map="t=1:s,u=2:V,p_a_gauge=3:Pa,p_b_gauge=4:Pa,alpha=2:rad"))
    assert not (tmp_path / "rec.csv").exists()


def test_recording_import_says_which_columns_are_missing(tmp_path):
    table = read_foreign(write(tmp_path, TAB), MAP, delimiter="tab")
    with pytest.raises(RecordingError) as e:
        recording_frame(table)
    msg = str(e.value)
    assert "cannot become a recording: the map gives no u (valve command), p_a (as p_a_gauge or p_a_abs), " \
           "p_b (as p_b_gauge or p_b_abs), alpha (boom angle)" in msg
    assert "this map gives t, x, p_gauge, F" in msg


def test_round_trip_into_the_recording_format(tmp_path):
    """A DAQ file in its own layout (preamble, header, ';', decimal comma, ms, bar
    absolute, degrees, mm) becomes a recording whose values are the same quantities
    in SI units, gauge pressures."""
    rows = ["LabVIEW export", "Zeit;Befehl;pA;pB;Winkel;Weg;Kraft"]
    t_ms = np.arange(0, 200, 1.0)
    for k, t in enumerate(t_ms):
        rows.append(";".join(f"{v}".replace(".", ",") for v in
                             (t, 5.0 + k / 100, 1.01325 + 0.5 + k / 1000, 7.01325 - k / 1000, 35.0 + k / 10,
                              10.0 + k / 20, 12.5 - k / 8)))
    src = write(tmp_path, "\n".join(rows) + "\n", "daq.csv")
    opts = read_options(map="t=Zeit:ms,u=Befehl:V,p_a_abs=pA:bar,p_b_abs=pB:bar,alpha=Winkel:deg,x=Weg:mm,"
                            "f_ext=Kraft:N", delimiter="semicolon", skip_rows=1, header=True, decimal=",")
    out = import_recording(src, tmp_path / "out" / "run.csv", opts)
    rec = read_recording(out)
    d = rec.data
    assert list(d.columns) == ["t", "u", "p_a", "p_b", "alpha", "f_ext", "x"]
    k = np.arange(len(t_ms))
    assert d["t"].to_numpy() == pytest.approx(t_ms / 1000.0)
    assert d["u"].to_numpy() == pytest.approx(5.0 + k / 100)
    assert d["p_a"].to_numpy() == pytest.approx((0.5 + k / 1000) * 1e5)
    assert d["p_b"].to_numpy() == pytest.approx((6.0 - k / 1000) * 1e5)
    assert d["alpha"].to_numpy() == pytest.approx(np.radians(35.0 + k / 10))
    assert d["x"].to_numpy() == pytest.approx((10.0 + k / 20) / 1000.0)
    assert d["f_ext"].to_numpy() == pytest.approx(12.5 - k / 8)


def test_cli_import_and_its_error(tmp_path, capsys):
    src = write(tmp_path, "0,6,0.5,0.5,0.1\n0.001,6,0.6,0.4,0.1\n0.002,6,0.7,0.3,0.1\n")
    out = tmp_path / "rec.csv"
    assert main(["recording", "import", str(src), "--map", "t=1:s,u=2:V,p_a_gauge=3:bar,p_b_gauge=4:bar,"
                 "alpha=5:rad", "--delimiter", "comma", "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out and read_recording(out).data["p_a"].iloc[2] == pytest.approx(7e4)
    assert main(["recording", "import", str(src), "--map", "t=1:s,u=2:V,p_a_gauge=3:bar,p_b_gauge=4:bar,"
                 "alpha=5:rad", "--out", str(tmp_path / "r2.csv")]) == 1
    err = capsys.readouterr().err
    assert "boomfmi recording:" in err and "line 1" in err and "not separated by --delimiter 'tab'" in err


@needs_real
def test_presets_read_the_real_files():
    table = read_with(REAL / "friction" / "Circle_3bar.csv", read_options("zillen2021"))
    assert table.lines[0] == 16 and len(table) == 7834 - 15
    assert table.columns["t"][0] == pytest.approx(2.802) and table.columns["x"][0] == pytest.approx(0.020863)
    assert table.columns["p_gauge"][0] == pytest.approx(3.016e5) and table.columns["F"][0] == pytest.approx(156.293)
    leak = read_with(REAL / "airchamber_leakage" / "Prusa.csv", read_options("zillen2021-leak"))
    assert leak.columns["t"][-1] == pytest.approx(143.696) and leak.columns["p_gauge"][-1] == pytest.approx(7.548e5)
    rep = read_foreign(REAL / "airchamber_leakage" / "Resultaten_opnieuwaanzetten.csv",
                       "t=Tijd (s):s,dp=SLA Prusa:mbar", delimiter="semicolon", decimal=",", header=True)
    assert rep.columns["t"][1] == pytest.approx(0.1) and rep.columns["dp"][-1] == pytest.approx(-9000.0)
