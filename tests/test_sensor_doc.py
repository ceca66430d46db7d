"""docs/sensor-file.md is complete and true: every key the parser (fitgen/physics/sensor.py) reads has a row in the
document's tables and every row names a key it reads, table by table; every default and "required" the tables state
is the parser's; every range of the simple kinds (> 0, >= 0, not 0, A to B, a list of words) is where the parser
draws the line; the [unit] keys are the ones fitgen writes; and the example parses, is what the document says of it,
and its commands run and print what the document says they print."""

from __future__ import annotations

import ast
import copy
import csv
import math
import re
import shlex
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from fitgen.base.errors import InputError
from fitgen.physics import sensor as sensor_mod
from fitgen.physics.sensor import TRAVEL_AXES, GmrTransfer, RawTransfer, Tolerances, load_sensor, parse_sensor
from fitgen.physics.simulate import DEFAULT_RANGES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "sensor-file.md"
SOURCE = ROOT / "fitgen" / "physics" / "sensor.py"
HEADER = ["key", "unit", "default", "allowed range", "meaning"]
# the document's sections, in its order: "" is the top level
SCOPES = ["", "magnet", "board", "travel", "elements.ring", "elements.list", "ambient", "stage", "tolerances",
          "transfer", "transfer.raw", "transfer.gmr", "unit"]
# _Section's readers: a call with a string literal for its key names a key of the file
SECTION_METHODS = {"number", "integer", "string", "vector", "raw", "sub", "has"}
# not a key of any file: stage.map's rows are read as {"row": r} through _numbers (parse_sensor)
SYNTHETIC = {"row"}
# the required keys only (one ring and one list entry, so that both are read)
MINIMAL = {
    "magnet": {"diameter": 6.0, "height": 1.0},
    "board": {"thickness": 1.5, "gap": 11.0},
    "elements": {"ring": [{"count": 4, "radius": 10.0}],
                 "list": [{"position": [0.0, 7.0, 0.0], "axis": [0.0, 0.0, 1.0]}]},
    "transfer": {},
}


# --- the document --------------------------------------------------------------------------------------------


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _sections() -> list[tuple[str, str]]:
    """(heading, body) of each ``## `` section."""
    out = []
    for chunk in re.split(r"^## ", DOC.read_text(), flags=re.M)[1:]:
        head, _, body = chunk.partition("\n")
        out.append((head.strip(), body))
    return out


def _scope(heading: str) -> str | None:
    if heading.lower().startswith("top-level"):
        return ""
    m = re.fullmatch(r"`\[{1,2}([a-z_.]+)\]{1,2}`", heading)
    return m.group(1) if m else None


def _key_tables(body: str) -> list[list[dict]]:
    """The body's tables whose header is HEADER, as rows {key, unit, default, range, meaning}."""
    tables, lines = [], body.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].startswith("|") and _cells(lines[i]) == HEADER:
            rows, i = [], i + 2  # past the header and its --- row
            while i < len(lines) and lines[i].startswith("|"):
                cells = _cells(lines[i])
                assert len(cells) == len(HEADER), f"{DOC.name}: a row with {len(cells)} cells: {lines[i]}"
                m = re.fullmatch(r"`([^`]+)`", cells[0])
                assert m, f"{DOC.name}: a row's key is not one name in backticks: {lines[i]}"
                rows.append(dict(zip(("key", "unit", "default", "range", "meaning"), [m.group(1)] + cells[1:])))
                i += 1
            tables.append(rows)
        i += 1
    return tables


def _doc_rows() -> dict[str, list[dict]]:
    """Per section scope its table's rows; every key table of the document is in a table's section, one each."""
    out = {}
    for heading, body in _sections():
        scope, tables = _scope(heading), _key_tables(body)
        if scope is None:
            assert not tables, f"{DOC.name}: section {heading!r} has a key table but names no file table"
            continue
        assert len(tables) == 1, f"{DOC.name}: section {heading!r} has {len(tables)} key tables, not 1"
        out[scope] = tables[0]
    return out


def _table_name(key: str) -> str | None:
    """``[transfer.raw]`` or ``[[elements.ring]]`` -> ``transfer.raw`` / ``elements.ring``; None for a plain key."""
    m = re.fullmatch(r"\[{1,2}([a-z_.]+)\]{1,2}", key)
    return m.group(1) if m else None


def _scoped(key_path: str) -> set[tuple[str, str]]:
    """A table's path as the (table, key) lookups that reach it: ``transfer.raw`` -> ("", transfer), (transfer, raw)."""
    parts = key_path.split(".")
    return {(".".join(parts[:i]), p) for i, p in enumerate(parts)}


def _doc_keys(rows: dict) -> set[tuple[str, str]]:
    """Every (table, key) the document's tables name."""
    keys = set()
    for scope, table in rows.items():
        for row in table:
            name = _table_name(row["key"])
            if name is not None:
                keys |= _scoped(name)
            else:
                keys.add((scope, row["key"]))
    return keys


def _literal(cell: str):
    """A default cell as its TOML value (backticks off); ValueError when it is none."""
    text = cell.strip()
    if text.startswith("`") and text.endswith("`"):
        text = text[1:-1]
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        raise ValueError(cell) from None


def _example() -> str:
    blocks = re.findall(r"^```toml\n(.*?)^```[ \t]*$", DOC.read_text(), re.S | re.M)
    assert len(blocks) == 1, f"{DOC.name} has {len(blocks)} toml blocks, not the one example"
    return blocks[0]


def _commands() -> list[list[str]]:
    blocks = re.findall(r"^```sh\n(.*?)^```[ \t]*$", DOC.read_text(), re.S | re.M)
    assert len(blocks) == 1, f"{DOC.name} has {len(blocks)} sh blocks, not the one of the example's commands"
    cmds = [shlex.split(line, comments=True) for line in blocks[0].splitlines()]
    return [c for c in cmds if c]


# --- the parser ----------------------------------------------------------------------------------------------


def _source_keys() -> dict[str, set[str]]:
    """Key -> the readers that read it by a string literal in sensor.py (the _Section methods' first argument,
    _table_list's and _numbers' second)."""
    keys: dict[str, set[str]] = {}
    for node in ast.walk(ast.parse(SOURCE.read_text())):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Attribute) and f.attr in SECTION_METHODS:
            reader, arg = f.attr, node.args[:1]
        elif isinstance(f, ast.Name) and f.id in ("_table_list", "_numbers"):
            reader, arg = f.id, node.args[1:2]
        else:
            continue
        if arg and isinstance(arg[0], ast.Constant) and isinstance(arg[0].value, str):
            keys.setdefault(arg[0].value, set()).add(reader)
    return keys


def _choices() -> dict[str, tuple]:
    """Key -> the words a ``string(..., choices=...)`` call in sensor.py allows."""
    out = {}
    for node in ast.walk(ast.parse(SOURCE.read_text())):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "string"
                and node.args and isinstance(node.args[0], ast.Constant)):
            for kw in node.keywords:
                if kw.arg == "choices":
                    v = kw.value
                    out[node.args[0].value] = (getattr(sensor_mod, v.id) if isinstance(v, ast.Name)
                                               else ast.literal_eval(v))
    return out


def _parser_plain_keys() -> set[str]:
    """Every key name the parser reads: by literal, plus those read in loops by name (Tolerances' fields,
    TRAVEL_AXES, UNIT_KEYS)."""
    keys = set(_source_keys())
    assert SYNTHETIC <= keys, "the synthetic keys left out are no longer read: update SYNTHETIC"
    return (keys - SYNTHETIC) | {f.name for f in fields(Tolerances)} | set(TRAVEL_AXES) | set(sensor_mod.UNIT_KEYS)


def _read(data: dict):
    """(sensor, lookups, defaults): the sensor parse_sensor makes of ``data``, every (table, key) it looks up on the
    way (list entries' tables without their index), and the default it takes for each absent key."""
    seen, defaults = set(), {}
    raw, has = sensor_mod._Section.raw, sensor_mod._Section.has

    def table(sec):
        return re.sub(r"\[\d+\]", "", sec.where)

    def raw_spy(self, key, default=None, required=False):
        seen.add((table(self), key))
        if key not in self.data:
            defaults[(table(self), key)] = default
        return raw(self, key, default, required)

    def has_spy(self, key):
        seen.add((table(self), key))
        return has(self, key)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sensor_mod._Section, "raw", raw_spy)
        mp.setattr(sensor_mod._Section, "has", has_spy)
        sensor = parse_sensor(copy.deepcopy(data), "minimal")
    return sensor, {k for k in seen if k[0] != "stage.map"}, defaults


def _container(data: dict, scope: str, create: bool = False):
    node = data
    for part in scope.split(".") if scope else []:
        if part not in node:
            if not create:
                return None
            node[part] = {}
        node = node[part]
        if isinstance(node, list):
            node = node[0]
    return node


def _with(scope: str, key: str, value) -> dict:
    data = copy.deepcopy(MINIMAL)
    _container(data, scope, create=True)[key] = value
    return data


def _without(scope: str, key: str) -> dict:
    data = copy.deepcopy(MINIMAL)
    del _container(data, scope)[key]
    return data


def _parses(data: dict) -> str | None:
    """None when ``data`` parses, else the refusal."""
    try:
        parse_sensor(data, "probe")
    except InputError as exc:
        return str(exc)
    return None


def _same(a, b) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=0, atol=1e-12))


def _radial(s) -> bool:
    p = s.positions[0]
    return bool(np.allclose(s.axes[0], [p[0] / math.hypot(p[0], p[1]), p[1] / math.hypot(p[0], p[1]), 0.0]))


# where a minimal file's Sensor keeps each default (the ring's: its first element, the list's: the last element)
FIELDS = {
    ("", "name"): lambda s: s.name,
    ("", "description"): lambda s: s.description,
    ("magnet", "shape"): lambda s: s.to_dict()["magnet"]["shape"],
    ("magnet", "polarization"): lambda s: s.magnet.polarization,
    ("magnet", "offset"): lambda s: s.magnet.offset,
    ("magnet", "tilt"): lambda s: s.magnet.tilt,
    ("travel", "dx"): lambda s: {**DEFAULT_RANGES, **s.travel}["dx"],  # as fitgen.fitting.schedule takes them
    ("travel", "dy"): lambda s: {**DEFAULT_RANGES, **s.travel}["dy"],
    ("travel", "dz"): lambda s: {**DEFAULT_RANGES, **s.travel}["dz"],
    ("elements.ring", "z"): lambda s: s.positions[0, 2],
    ("elements.ring", "start"): lambda s: math.degrees(math.atan2(s.positions[0, 1], s.positions[0, 0])),
    ("elements.ring", "axis"): lambda s: "radial" if _radial(s) else "not radial",
    ("elements.ring", "elevation"): lambda s: math.degrees(math.asin(s.axes[0, 2])),
    ("elements.list", "gain"): lambda s: s.gains[-1],
    ("elements.list", "offset"): lambda s: s.offsets[-1],
    ("ambient", "field"): lambda s: s.ambient,
    ("stage", "map"): lambda s: s.stage_map,
    ("stage", "stiffening"): lambda s: s.stiffening,
    ("transfer", "kind"): lambda s: s.transfer,
    **{("transfer.raw", f.name): (lambda s, n=f.name: getattr(s.raw, n)) for f in fields(RawTransfer)},
    **{("transfer.gmr", f.name): (lambda s, n=f.name: getattr(s.gmr, n)) for f in fields(GmrTransfer)},
    **{("tolerances", f.name): (lambda s, n=f.name: getattr(s.tolerances, n)) for f in fields(Tolerances)},
}


# --- the tests -----------------------------------------------------------------------------------------------


def test_one_section_per_table_in_order():
    rows = _doc_rows()
    assert list(rows) == SCOPES, f"{DOC.name}: sections {list(rows)}, expected {SCOPES}"
    tables = {_table_name(r["key"]) for r in rows[""]} - {None}
    assert tables == set(SCOPES[1:]), (f"{DOC.name}: the top-level table names {sorted(tables)}, the sections are "
                                       f"{SCOPES[1:]}")
    for scope, table in rows.items():
        keys = [r["key"] for r in table]
        assert len(keys) == len(set(keys)), f"{DOC.name}: [{scope}] names a key twice: {keys}"


def test_every_key_the_parser_reads_is_documented_and_no_other():
    rows = _doc_rows()
    parser, doc = _parser_plain_keys(), {k for _, k in _doc_keys(rows)}
    assert parser == doc, (f"{DOC.name} against fitgen/physics/sensor.py: undocumented keys "
                           f"{sorted(parser - doc)}; documented keys the parser does not read {sorted(doc - parser)}")
    # table by table: what the parser looks up reading the required keys (it looks up every optional one too)
    _, seen, _ = _read(MINIMAL)
    looked_up = {k for _, k in seen}
    assert looked_up == parser, f"read by literal but not looked up, or the reverse: {sorted(parser ^ looked_up)}"
    doc_scoped = _doc_keys(rows)
    assert seen == doc_scoped, (f"{DOC.name}, (table, key): undocumented {sorted(seen - doc_scoped)}; documented but "
                                f"not read there {sorted(doc_scoped - seen)}")


def test_every_table_refuses_a_key_it_does_not_know():
    for scope in SCOPES:  # [unit] too: a misspelt posterior had been lost in silence
        why = _parses(_with(scope, "no_such_key", 1.0))
        assert why and "unknown key" in why and "no_such_key" in why, (scope, why)


def test_a_units_capture_temperature_is_a_number_of_degrees():
    assert _parses(_with("unit", "capture_degc", 21.5)) is None
    for bad, said in (("hot", "must be a finite number, got 'hot'"), (400.0, "must be <= 125, got 400")):
        assert f"'unit.capture_degc' {said}" in _parses(_with("unit", "capture_degc", bad))


def test_the_unit_keys_are_the_ones_fitgen_writes(tmp_path):
    from fitgen.physics.units import unit_beside

    doc = {r["key"] for r in _doc_rows()["unit"]}
    _, _, text, _ = unit_beside(load_sensor("paper"), 1, tmp_path / "d.csv")  # fitgen simulate --unit's
    written = set(tomllib.loads(text)["unit"])
    # fitgen identify's: unit_files' own provenance (prov = {...}) and what calibrate_cli hands it
    rec = ast.parse((ROOT / "fitgen" / "fitting" / "unitrecord.py").read_text())
    func = next(n for n in ast.walk(rec) if isinstance(n, ast.FunctionDef) and n.name == "unit_files")
    prov = next(n.value for n in ast.walk(func) if isinstance(n, ast.Assign)
                and any(isinstance(t, ast.Name) and t.id == "prov" for t in n.targets))
    written |= {k.value for k in prov.keys if isinstance(k, ast.Constant)}
    temp = next(n for n in ast.walk(rec) if isinstance(n, ast.FunctionDef) and n.name == "capture_temperature")
    written |= {k.value for d in ast.walk(temp) if isinstance(d, ast.Dict) for k in d.keys if isinstance(k, ast.Constant)}
    cli = ast.parse((ROOT / "fitgen" / "app" / "calibrate_cli.py").read_text())
    call = next(n for n in ast.walk(cli) if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
                and n.func.attr == "unit_files")
    written |= {k.value for k in call.args[2].keys if isinstance(k, ast.Constant)}
    captures = ast.parse((ROOT / "fitgen" / "app" / "captureinput.py").read_text())
    at_t0 = next(n for n in ast.walk(captures) if isinstance(n, ast.FunctionDef) and n.name == "at_t0")  # --temp-comp's
    written |= {k.value for d in ast.walk(at_t0) if isinstance(d, ast.Dict) for k in d.keys if isinstance(k, ast.Constant)}
    assert doc == written, (f"{DOC.name} [unit]: undocumented {sorted(written - doc)}; documented but never "
                            f"written {sorted(doc - written)}")


def test_every_stated_default_and_required_key_is_the_parsers():
    rows = _doc_rows()
    sensor, _, defaults = _read(MINIMAL)
    covered = set()
    for scope, table in rows.items():
        if scope == "unit":
            continue
        for row in table:
            key, cell, where = row["key"], row["default"], f"[{scope}] {row['key']}"
            name = _table_name(key)
            if name is not None:
                parent, _, last = name.rpartition(".")
                assert cell in ("required", "optional"), f"{DOC.name} {where}: default {cell!r}"
                why = _parses(_without(parent, last)) if last in (_container(MINIMAL, parent) or {}) else None
                if cell == "required":
                    assert why and f"missing key '{name}'" in why, f"{DOC.name} {where}: said required; {why}"
                else:
                    assert why is None, f"{DOC.name} {where}: said optional; {why}"
                continue
            if cell == "required":
                assert key in (_container(MINIMAL, scope) or {}), \
                    f"{DOC.name} {where}: said required, but a file without it (MINIMAL) parses"
                why = _parses(_without(scope, key))
                assert why and re.search(rf"missing key '([\w.\[\]]+\.)?{key}'", why), \
                    f"{DOC.name} {where}: said required, but without it: {why}"
                continue
            try:
                value = _literal(cell)
            except ValueError:
                pytest.fail(f"{DOC.name} {where}: default {cell!r} is neither 'required' nor a TOML value")
            if key in (_container(MINIMAL, scope) or {}):  # a key the minimal file holds: required, or MINIMAL is wrong
                assert _parses(_without(scope, key)), f"{where}: not required, so MINIMAL must leave it out"
                pytest.fail(f"{DOC.name} {where}: default {cell!r}, but the parser requires the key")
            found = False
            if (scope, key) in defaults:
                found = True
                assert _same(defaults[(scope, key)], value), \
                    f"{DOC.name} {where}: default {value!r}, the parser's {defaults[(scope, key)]!r}"
            if (scope, key) in FIELDS:
                found = True
                got = FIELDS[(scope, key)](sensor)
                assert _same(got, value), f"{DOC.name} {where}: default {value!r}, a minimal file's sensor has {got!r}"
                covered.add((scope, key))
            assert found, f"{DOC.name} {where}: no parser default to compare with (add it to FIELDS)"
    # these tables' defaults are compared with the fields of the Sensor a minimal file makes, not only the parser's
    for scope, keys in (("magnet", {"shape", "polarization", "offset", "tilt"}),
                        ("transfer.raw", {f.name for f in fields(RawTransfer)}),
                        ("transfer.gmr", {f.name for f in fields(GmrTransfer)}),
                        ("tolerances", {f.name for f in fields(Tolerances)})):
        missing = sorted(k for k in keys if (scope, k) not in covered)
        assert not missing, f"{DOC.name} [{scope}]: no default stated for {missing}"
    # [board]: the rest height the document gives from it
    m = sensor.magnet
    assert _same(m.rest_center, (0.0, 0.0, sensor.board_thickness + sensor.board_gap + m.height / 2))
    assert "at least one" in (_parses({**copy.deepcopy(MINIMAL), "elements": {}}) or "")


def _bound(text: str) -> float:
    a, _, b = text.partition("/")
    return float(a) / float(b) if b else float(a)


def test_every_simple_range_is_where_the_parser_draws_the_line():
    integers = {k for k, readers in _source_keys().items() if "integer" in readers}
    strings = {k for k, readers in _source_keys().items() if "string" in readers}
    num = r"-?\d+(?:\.\d+)?(?:/\d+(?:\.\d+)?)?"
    probed = 0
    for scope, table in _doc_rows().items():
        for row in table:
            key, rng, where = row["key"], row["range"], f"[{scope}] {row['key']}"
            if _table_name(key) or scope == "unit":
                continue
            ok, bad = [], []
            if rng == "> 0":
                ok, bad = [1e-3, 1.0], [0.0, -1.0]
            elif rng == ">= 0":
                ok, bad = [0.0, 1e-3], [-1e-9]
            elif rng == "not 0":
                ok, bad = [-1.0, 1.0], [0.0]
            elif m := re.fullmatch(rf"({num}) to ({num})", rng):
                lo, hi = _bound(m.group(1)), _bound(m.group(2))
                if key in integers:
                    ok, bad = [int(lo), int(hi)], [int(lo) - 1, int(hi) + 1]
                else:
                    eps = 1e-9 * max(1.0, abs(lo), abs(hi))
                    ok, bad = [lo, hi], [lo - eps, hi + eps]
            elif key in strings and re.fullmatch(r"`[^`]+`(, `[^`]+`)*", rng):
                ok, bad = re.findall(r"`([^`]+)`", rng), ["no-such-word"]
                assert set(ok) == set(_choices().get(key, ())), \
                    f"{DOC.name} {where}: {ok}, the parser's choices {_choices().get(key)}"
            else:
                continue
            probed += 1
            for v in ok:
                why = _parses(_with(scope, key, v))
                assert why is None, f"{DOC.name} {where}: {rng!r} allows {v!r}, the parser refuses it: {why}"
            for v in bad:
                assert _parses(_with(scope, key, v)), f"{DOC.name} {where}: {rng!r} excludes {v!r}, the parser takes it"
    assert probed >= 35, f"only {probed} ranges probed"


# --- the example -----------------------------------------------------------------------------------------------


def test_the_example_is_what_the_document_says(tmp_path):
    text = _example()
    data = tomllib.loads(text)
    sensor = parse_sensor(tomllib.loads(text), "example")
    path = tmp_path / "mine.toml"
    path.write_text(text)
    assert load_sensor(path).sha256 == sensor.sha256
    doc = DOC.read_text()
    count = re.search(r"\*\*(\d+) elements\*\*", doc)
    kind = re.search(r"\*\*`(raw|gmr)`\*\*\s+transfer", doc)
    assert count and kind, f"{DOC.name} no longer says the example's element count and transfer"
    assert sensor.n_elements == int(count.group(1))
    assert sensor.transfer == kind.group(1)
    # what the brief asks the example to show: a ring and a list entry, a travel and some tolerances
    rings, listed = data["elements"]["ring"], data["elements"]["list"]
    assert rings and listed and data["travel"] and data["tolerances"]
    assert sensor.travel == {a: tuple(v) for a, v in data["travel"].items()}
    for k, v in data["tolerances"].items():
        assert getattr(sensor.tolerances, k) == v
    # numbered ring entries first, then list entries
    n_ring = sum(r["count"] for r in rings)
    assert _same(sensor.positions[n_ring:], [e["position"] for e in listed])
    assert sensor.is_drawing


def test_a_unit_file_is_refused_as_a_drawing_and_an_element_on_the_axis_moves_along_x_and_y():
    from fitgen.physics.units import UnitSpace, draw_unit

    mine = parse_sensor(tomllib.loads(_example()), "example")
    unit, _ = draw_unit(mine, 1)
    with pytest.raises(InputError, match="built unit, not a drawing"):
        draw_unit(unit, 2)
    data = tomllib.loads(_example())
    data["elements"]["list"][0]["position"] = [0.0, 0.0, 0.0]
    centre = parse_sensor(data, "example")
    unit, theta = draw_unit(centre, 1)  # as the doc says: shifts along x and y with element_radius's spread
    space = UnitSpace.of(centre)
    k = centre.n_elements
    assert space.prior_sd[space.index(f"e{k}.azimuth")] == centre.tolerances.element_radius
    np.testing.assert_allclose(unit.positions[k - 1, :2], [theta[space.index(f"e{k}.radius")],
                                                          theta[space.index(f"e{k}.azimuth")]], atol=1e-15)


def test_a_drawing_written_with_a_units_keys_is_told_which_keys_make_it_one():
    from fitgen.physics.units import UnitSpace

    data = tomllib.loads(_example())
    assert UnitSpace.of(parse_sensor(copy.deepcopy(data), "example"))  # the document's own: a drawing
    k = sum(r["count"] for r in data["elements"].get("ring", [])) + 1  # the first list entry's element number
    data["elements"]["list"][0]["gain"] = 1.1
    data["ambient"] = {"field": [0.0, 0.0, 0.05]}
    mine = parse_sensor(data, "example")
    assert mine.unit_traits() == [f"element {k}'s gain 1.1", "ambient.field"]
    with pytest.raises(InputError) as err:
        UnitSpace.of(mine)
    msg = str(err.value)
    assert f"is a built unit, not a drawing (element {k}'s gain 1.1; ambient.field;" in msg
    assert "leave those keys out" in msg and "\n" not in msg


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    """(folder, {command's first words: completed process}) after the document's commands on its example."""
    folder = tmp_path_factory.mktemp("sensor-doc")
    (folder / "mine.toml").write_text(_example())
    out = {}
    for cmd in _commands():
        assert cmd[0] == "fitgen", cmd
        proc = run_cli(*cmd, cwd=folder)
        assert proc.returncode == 0, f"{' '.join(cmd)}: {proc.stderr}"
        out[" ".join(cmd)] = proc
    return folder, out


def _one(out: dict, *words: str, without: str | None = None):
    hits = [p for c, p in out.items() if all(w in c.split() for w in words) and not (without and without in c)]
    assert len(hits) == 1, f"{DOC.name}: expected one command with {words} (without {without}), got {len(hits)}"
    return hits[0]


def test_the_examples_commands_print_what_the_document_says(ran):
    folder, out = ran
    sensor = load_sensor(folder / "mine.toml")
    doc = re.sub(r"\s+", " ", DOC.read_text())
    slide = _one(out, "observe", "slide")
    assert slide.stdout.splitlines()[0] == f"sensor {sensor.name} ({sensor.n_elements} elements, " \
                                           f"{sensor.transfer}), scene slide"
    assert "The slide scene resolves dx, dy and dz everywhere in its box" in doc
    assert "NOT resolvable" not in slide.stdout
    for c in ("dx", "dy", "dz"):
        assert f"{c}: resolvable" in slide.stdout
    m = re.search(r"The full scene resolves dy, dz and thx, but not dx at rest nor thy at (\d+) of its (\d+) poses",
                  doc)
    assert m, f"{DOC.name} no longer says what the full scene resolves"
    full = _one(out, "observe", without="--scene").stdout
    for c in ("dy", "dz", "thx"):
        assert f"{c}: resolvable" in full
    assert re.search(r"^dx: NOT resolvable .* at 1 of \d+ poses \(bound \S+ mm at rest", full, re.M), full
    assert f"thy: NOT resolvable to 1 deg at {m.group(1)} of {m.group(2)} poses" in full, full
    # the readings' span on the paper-sim grid
    m = re.search(r"the readings lie between ([\d.]+) and ([\d.]+) mT", doc)
    assert m, f"{DOC.name} no longer gives the example's readings"
    with open(folder / "mine.csv", newline="") as f:
        v = np.array([[float(r[f"v{k}"]) for k in range(1, sensor.n_elements + 1)] for r in csv.DictReader(f)])
    assert (f"{v.min():.2f}", f"{v.max():.2f}") == m.groups()


def _present(node, parts: list[str], every: bool) -> bool:
    """Whether the TOML document ``node`` has the dotted key ``parts``: in every entry of an array of tables on the
    way (``every``), or in any."""
    if not parts:
        return True
    if isinstance(node, list):
        return bool(node) and (all if every else any)(_present(e, parts, every) for e in node)
    return isinstance(node, dict) and parts[0] in node and _present(node[parts[0]], parts[1:], every)


def test_a_unit_file_carries_what_the_document_says(ran):
    folder, _ = ran
    heading, body = next(s for s in _sections() if s[0].lower().startswith("what a unit file"))
    paths = re.findall(r"`([a-z_]+(?:\.[a-z_]+)+)`", body)
    assert len(paths) >= 6, f"{DOC.name} ({heading}) names {paths}"
    unit = tomllib.loads((folder / "unit1.unit.toml").read_text())
    drawing = tomllib.loads((folder / "mine.toml").read_text())
    for p in paths:
        assert _present(unit, p.split("."), True), f"{DOC.name}: a unit file carries {p}; unit1.unit.toml does not"
        assert not _present(drawing, p.split("."), False), \
            f"{DOC.name}: a drawing usually lacks {p}; the example has it"
    assert "unit" in unit and "unit" not in drawing
    assert not load_sensor(folder / "unit1.unit.toml").is_drawing


def test_the_schedule_keeps_within_the_travel(ran):
    from fitgen.physics.pose import REST_LIFT_MM

    folder, _ = ran
    travel = load_sensor(folder / "mine.toml").travel
    with open(folder / "schedule.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows
    for r in rows:
        for a, (lo, hi) in travel.items():
            x = float(r[a])
            assert lo - 1e-9 <= x <= hi + 1e-9 or (a == "dz" and x == REST_LIFT_MM), (a, x, (lo, hi))
