"""docs/validation.md and the README's headline figures are what the tools' results files
make (cadra.validation.figures): a figure is never copied by hand, and a page left behind
by a new run fails here (regenerate with ``python tools/make_validation_doc.py``)."""

import json
from pathlib import Path

import pytest

from cadra.validation import figures
from cadra.validation.results import FORMAT, load_results, record

ROOT = Path(__file__).resolve().parents[1]


def test_the_pages_are_current():
    assert figures.stale(ROOT) == [], "run: python tools/make_validation_doc.py"


def test_every_figure_names_a_known_section():
    assert {f.tool for f in figures.FIGURES} <= set(figures.SECTIONS)
    assert any(f.headline for f in figures.FIGURES)


def test_a_recorded_figure_reaches_both_pages(tmp_path):
    (tmp_path / "docs").mkdir()
    # the old block's text: a marker no figure's label contains ("old" is in "hold")
    (tmp_path / "README.md").write_text(f"# x\n\n{figures.README_BEGIN}\nOLD-BLOCK-TEXT\n"
                                        f"{figures.README_END}\n\nmore\n", encoding="utf-8")
    path = record("bench_cadra1", {"capsule_ref_rms_px": 0.00193769, "sigma_ratio_min": 0.9415,
                                   "sigma_ratio_max": [0.97, 0.99]}, tmp_path,
                  argv=["--quick"], seconds=12.3)
    data = json.loads(path.read_text())
    assert data["format"] == FORMAT and data["command"] == "python tools/bench_cadra1.py --quick"
    assert load_results(tmp_path)["bench_cadra1"]["figures"]["sigma_ratio_min"] == 0.9415
    assert figures.stale(tmp_path) == ["docs/validation.md", "README.md"]
    figures.update(tmp_path)
    assert figures.stale(tmp_path) == []
    page = (tmp_path / "docs" / "validation.md").read_text()
    assert "| capsule reference point error rms (px) | 0.001938 | < 0.02 |" in page
    assert "| reported sigma / actual error, highest | 0.97 / 0.99 | 0.8–1.25 |" in page
    assert "python tools/bench_cadra1.py --quick" in page
    readme = (tmp_path / "README.md").read_text()
    assert readme.startswith("# x\n") and readme.endswith("\n\nmore\n")
    assert "OLD-BLOCK-TEXT" not in readme
    assert "| capsule reference point error rms (px) | 0.001938 |" in readme
    assert "not run" in readme                        # a headline no run has made yet


def test_a_results_file_of_another_format_is_refused(tmp_path):
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "x.json").write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="not a tool results file"):
        load_results(tmp_path)
