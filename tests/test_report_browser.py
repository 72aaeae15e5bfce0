"""The HTML experiment report, opened in headless Chromium: it must render.

No console errors, every image (plots and films, all data URIs) loaded, the Figure-2
table there beside the paper's numbers. Chromium and its driver are Debian packages
(.ci/services.sh installs them in CI); without them the test is skipped and says why.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from llcps.experiments.design import PAPER_SCENARIOS, Cell, Sequence
from llcps.report.build import build_report
from llcps.analysis.results import ResultsTable
from llcps.experiments.rows import ResultRow

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
#: Flags for a closed network: no first-run, no background fetches, nothing that phones home.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)

needs_chromium = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="headless Chromium and chromedriver are not installed (apt-get install chromium chromium-driver; "
    ".ci/services.sh does it as root)",
)


def paper_like_table(seeds: int = 3) -> ResultsTable:
    """Two models x two measures, 4 pretraining points, update and reset, over a few seeds."""
    rows = []
    for model in ("nn", "nb"):
        for measure in ("least-destructive", "most-changes"):
            for condition in ("update", "reset"):
                for seed in range(seeds):
                    seq = Sequence("paper", Cell(model, measure, 4, condition), seed)
                    for i, scenario in enumerate(PAPER_SCENARIOS):
                        trials = 12 + 3 * i + seed * (2 if condition == "update" else 3) + len(measure) % 5
                        rows.append(
                            ResultRow("paper", model, measure, 4, condition, seed, scenario, trials < 150, trials,
                                      0.2 * trials, 0.4 * trials, len(rows) + 1, seq.episode_branch(scenario))
                        )  # fmt: skip
    return ResultsTable(rows)


def real_film(path: Path) -> Path:
    """A short captioned GIF from the simulator (the pipeline the report's films use)."""
    from llcps.sim.gallery import DEMO_SCENE, DEMO_TRIALS
    from llcps.sim.render import GifRecorder
    from llcps.sim.trial import run_trial
    from llcps.sim.world import World

    with World.from_scene(DEMO_SCENE) as world:
        recorder = GifRecorder(world, every=60, width=160, height=120, camera=None, shadow=False)
        recorder.caption = ("trial 1 · explore · scenario1", "push(red_cube)")
        with recorder:
            run_trial(world, DEMO_TRIALS["push"])
        return recorder.save(path)


def open_in_chromium(page: Path, profile: Path, screenshot: Path | None = None, *, table_id: str = "figure2") -> dict[str, object]:
    """Load ``page`` in headless Chromium; return its console log, images and the table ``table_id`` (Figure 2)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    os.environ.setdefault("SE_OFFLINE", "true")  # never let Selenium Manager fetch a driver
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--window-size=1280,1600"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)), options=options)
    try:
        driver.get(page.as_uri())
        driver.execute_async_script(
            "const done = arguments[arguments.length - 1];"
            "Promise.all(Array.from(document.images).map(i => i.complete ? null : new Promise(r => { i.onload = i.onerror = r; })))"
            ".then(() => done(true));"
        )
        images = driver.execute_script(
            "return Array.from(document.images).map(i => ({alt: i.alt, width: i.naturalWidth, complete: i.complete, data: i.src.startsWith('data:')}))"
        )
        table = driver.find_element(By.ID, table_id)
        result = {
            "log": driver.get_log("browser"),
            "images": images,
            "header": [th.text for th in table.find_elements(By.TAG_NAME, "th")],
            "rows": len(table.find_elements(By.CSS_SELECTOR, "tbody tr")),
            "title": driver.title,
        }
        if screenshot is not None:
            driver.save_screenshot(str(screenshot))
        return result
    finally:
        driver.quit()


@pytest.mark.slow
@needs_chromium
def test_html_report_renders_in_headless_chromium(tmp_path: Path) -> None:
    pytest.importorskip("selenium", reason="selenium is a dev dependency: pip install -e '.[dev]'")
    films = {"scenario2": real_film(tmp_path / "scenario2.gif")}
    paths = build_report(paper_like_table(), tmp_path / "report", resamples=500, films=films, html=True)
    assert paths.report_html is not None
    text = paths.report_html.read_text(encoding="utf-8")
    assert "src=\"http" not in text and "href=\"http" not in text  # self-contained: nothing fetched
    shot = tmp_path / "page.png"
    seen = open_in_chromium(paths.report_html, tmp_path / "profile", screenshot=shot)
    errors = [entry for entry in seen["log"] if entry.get("level") == "SEVERE"]  # type: ignore[union-attr]
    assert errors == [], errors
    images = seen["images"]
    assert len(images) == len(paths.plots) + len(films)  # every plot and every film
    assert all(i["complete"] and i["width"] > 0 and i["data"] for i in images), images  # type: ignore[index]
    assert seen["title"] == "llcps experiment report"
    header = seen["header"]
    assert "scenario2 ours" in header and "scenario2 paper" in header and "scenario3 paper" in header
    assert seen["rows"] == 4  # 2 models x 2 measures
    assert shot.stat().st_size > 10_000


@pytest.mark.slow
@needs_chromium
def test_the_life_report_renders_in_headless_chromium(tmp_path: Path) -> None:
    """The life report: its two plots load, the metrics table is there, nothing fetched or failing."""
    pytest.importorskip("selenium", reason="selenium is a dev dependency: pip install -e '.[dev]'")
    from test_lives import hand_rows

    from llcps.analysis.lives import life_metrics
    from llcps.report.lives import write_life_report

    rows = hand_rows()
    paths = write_life_report(rows, life_metrics(rows), tmp_path / "life", life="hand", html=True)
    assert paths.html is not None
    text = paths.html.read_text(encoding="utf-8")
    assert "src=\"http" not in text and "href=\"http" not in text
    shot = tmp_path / "life.png"
    seen = open_in_chromium(paths.html, tmp_path / "profile", screenshot=shot, table_id="life-metrics")
    assert [e for e in seen["log"] if e.get("level") == "SEVERE"] == []  # type: ignore[union-attr]
    images = seen["images"]
    assert len(images) == 2 and all(i["complete"] and i["width"] > 0 and i["data"] for i in images), images  # type: ignore[index]
    assert seen["title"] == "llcps life report: hand"
    assert "FT first encounters" in seen["header"] and "forgetting" in seen["header"]  # type: ignore[operator]
    assert seen["rows"] == 2  # update and reset
    assert shot.stat().st_size > 10_000


@needs_chromium
def test_a_broken_page_is_caught(tmp_path: Path) -> None:
    """The checks can fail: a script error and a missing image are reported."""
    pytest.importorskip("selenium", reason="selenium is a dev dependency: pip install -e '.[dev]'")
    page = tmp_path / "broken.html"
    page.write_text(
        "<!doctype html><html><head><title>x</title></head><body>"
        '<table id="figure2"><thead><tr><th>a</th></tr></thead><tbody><tr><td>1</td></tr></tbody></table>'
        '<img alt="missing" src="data:image/png;base64,AAAA"><script>undefinedFunction();</script></body></html>'
    )
    seen = open_in_chromium(page, tmp_path / "profile")
    assert any(e.get("level") == "SEVERE" for e in seen["log"])  # type: ignore[union-attr]
    assert [i["width"] for i in seen["images"]] == [0]  # type: ignore[index]
