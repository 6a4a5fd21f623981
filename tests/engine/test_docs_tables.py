"""The tables in docs/ are what tools/docs_tables.py prints from bench_results/."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _generator():
    spec = importlib.util.spec_from_file_location("docs_tables", ROOT / "tools" / "docs_tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_generated_table_in_docs_matches_bench_results(capsys):
    generator = _generator()
    assert generator.REGION.search((ROOT / "docs" / "benchmarks.md").read_text())
    assert generator.main(["--check"]) == 0, capsys.readouterr().out


def test_a_table_that_drifted_from_its_json_is_found_and_rewritten(tmp_path):
    generator = _generator()
    original = (ROOT / "docs" / "benchmarks.md").read_text()
    learned = next(line for line in original.splitlines() if line.startswith("| learned |"))
    drifted = original.replace(learned, learned.replace("0.", "0.9", 1))
    page = tmp_path / "benchmarks.md"
    page.write_text(drifted)
    assert generator.main(["--check", str(page)]) == 1
    assert page.read_text() == drifted, "--check changes nothing"
    assert generator.main([str(page)]) == 0
    assert page.read_text() == original
    assert generator.main(["--check", str(page)]) == 0, "a second run changes nothing"


def test_a_table_whose_results_are_missing_is_an_error(tmp_path):
    generator = _generator()
    page = tmp_path / "page.md"
    page.write_text("<!-- generated from: python -m lab bench --table --report --domain all "
                    "--condition clean --count 30 --out bench_results/no_such_folder -->\n"
                    "<!-- end of generated table -->\n")
    with pytest.raises(RuntimeError, match="did not find all of its results"):
        generator.main(["--check", str(page)])
