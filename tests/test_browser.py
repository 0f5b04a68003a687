"""The report in a real browser (headless Chromium): no element wider than its box, every
image loaded, no console error. Skipped, with the reason shown, when Chromium is absent
(.ci/run installs Debian's ``chromium`` when it can)."""

from pathlib import Path

import pytest
from browser import chromium, inspect

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(chromium() is None, reason="no chromium on PATH: browser checks not run "
                                "(apt-get install chromium; .ci/run does)")


def _check(found):
    assert found["loaded"], "the page never finished loading"
    assert not found["console"], f"console errors: {found['console']}"
    assert not found["images"], f"images that did not load: {found['images']}"
    assert not found["overflow"], "content wider than its box: " + "; ".join(found["overflow"][:8])
    assert found["page_width"] <= 1280, f"the page scrolls sideways ({found['page_width']} px)"


@pytest.mark.skipif(not (ROOT / "reports" / "example").is_dir(),
                    reason="reports/example is not here (the sdist leaves its 13 MB of figures out)")
def test_example_report_renders_without_overflow_broken_images_or_errors(tmp_path):
    _check(inspect(ROOT / "reports" / "example", tmp_path))


def test_a_new_report_renders_without_overflow_broken_images_or_errors(ea_fit, tmp_path):
    from skinfit.report import html as report

    report.write_report([ea_fit], tmp_path / "report", title="one fit")
    _check(inspect(tmp_path / "report", tmp_path / "probe"))


def test_browser_check_sees_a_cut_table_and_a_missing_image(tmp_path):
    """Negative control: an unbreakable wide cell in a fixed box, a missing figure, an error."""
    d = tmp_path / "bad"
    d.mkdir()
    (d / "index.html").write_text(
        '<!DOCTYPE html><html><head><meta charset="utf-8"><title>bad</title></head><body>'
        '<div style="width:200px;overflow:hidden"><table><tr><td style="white-space:nowrap">'
        + "cut " * 80 + '</td></tr></table></div><img src="figures/missing.png" alt="missing">'
        '<script>console.error("boom")</script></body></html>')
    found = inspect(d, tmp_path / "probe")
    assert found["images"] == ["figures/missing.png"]
    assert any(o.startswith("div") for o in found["overflow"])
    assert found["console"] == ["boom"]
