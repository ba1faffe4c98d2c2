"""Scenario files: bad files give a ScenarioFileError naming the file (and the key), never a raw error."""
from __future__ import annotations

import pytest

from dobs_envs.cli import main
from dobs_envs.scenarios import ScenarioFileError, load_scenario
from dobs_envs.scenarios.io import MAX_ELEMENTS, example_path


def _ne2_text():
    return open(example_path("ne2"), encoding="utf-8").read()


def test_integer_too_large_for_float_names_the_key(tmp_path):
    p = tmp_path / "big.yaml"
    text = _ne2_text()
    start = text.index("\nA:")
    p.write_text(text[:start] + "\nx0_scale: " + str(10**400) + text[start:], encoding="utf-8")
    with pytest.raises(ScenarioFileError, match="too large for a float") as exc:
        load_scenario(p)
    assert str(p) in str(exc.value)


def test_non_utf8_file_names_the_file(tmp_path):
    p = tmp_path / "latin1.yaml"
    p.write_bytes("name: caf\xe9\n".encode("latin-1"))
    with pytest.raises(ScenarioFileError, match="not UTF-8") as exc:
        load_scenario(p)
    assert str(p) in str(exc.value)


def test_nan_in_A_is_reported_against_A(tmp_path):
    sc = load_scenario(example_path("ne2"))
    from dobs_envs.scenarios.io import scenario_to_dict, scenario_from_dict

    d = scenario_to_dict(sc)
    d.pop("K")
    d.pop("P", None)
    d["A"][0][0] = float("nan")
    with pytest.raises(ScenarioFileError) as exc:
        scenario_from_dict(d, source="mem")
    assert exc.value.key == "A" and "finite" in str(exc.value)


def test_alias_bomb_is_capped_before_expansion(tmp_path):
    lines = ["a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    for k in range(1, 9):
        lines.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k-1}"] * 10) + "]")
    lines.append("name: bomb\nA: *a8")
    p = tmp_path / "bomb.yaml"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    assert p.stat().st_size < 4096  # 10^9 values when expanded
    with pytest.raises(ScenarioFileError, match=f"more than {MAX_ELEMENTS}"):
        load_scenario(p)


def test_directory_named_like_a_scenario_file(tmp_path):
    d = tmp_path / "dir.yaml"
    d.mkdir()
    with pytest.raises(ScenarioFileError, match="is a directory"):
        load_scenario(d)


@pytest.mark.parametrize("argv", [["--t-end", "0"], ["--t-end", "-1"], ["--dt", "nan"], ["--t-end", "x"]])
def test_reproduce_rejects_nonpositive_times(argv, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", "ne2", "--out", str(tmp_path), *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and ("--t-end" in err or "--dt" in err)
