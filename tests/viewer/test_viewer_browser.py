"""`hcgym view` in a real browser: Debian's headless Chromium drives the pages served over real run
and evaluation folders, and every number checked comes from the files, read independently here."""

from __future__ import annotations

import json

import pyarrow.parquet as pq
import pytest
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

from tests.viewer.conftest import ARTIFACTS

pytestmark = pytest.mark.ray


def show(driver, served, fragment: str, path: str | None = None):
    """Open `#fragment` and wait until the app has rendered that page (a new render, not the last one)."""
    before = driver.execute_script("return document.body && document.body.dataset.renders || '0'")
    if driver.current_url.startswith(served.url):
        # the same hash fires no hashchange: dispatch one so the page re-renders either way
        driver.execute_script("if (location.hash === '#' + arguments[0]) window.dispatchEvent(new HashChangeEvent('hashchange'));"
                              "else location.hash = arguments[0];", fragment)
    else:
        driver.get(served.url + "#" + fragment)
        before = "0"
    expected = path or fragment.split("?")[0]
    WebDriverWait(driver, 60).until(lambda d: d.execute_script(
        "return document.body.dataset.ready === arguments[0] && document.body.dataset.renders !== arguments[1]",
        expected, before))
    errors = driver.find_elements(By.ID, "page-error")
    assert not errors, f"#{fragment}: the page reported {errors[0].text!r}"


def wait_render(driver, before: str):
    WebDriverWait(driver, 60).until(lambda d: d.execute_script("return document.body.dataset.renders") != before)


def renders(driver) -> str:
    return driver.execute_script("return document.body.dataset.renders")


def severe_console_messages(driver) -> list[str]:
    return [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def source_id(served, path) -> str:
    return next(s.id for s in served.app.sources.values() if s.path == path.resolve())


def test_every_page_loads_without_console_errors_and_is_captured(served, browser, trained_run, gold_run, eval_dirs):
    run, gold, ev = source_id(served, trained_run), source_id(served, gold_run), source_id(served, eval_dirs[0])
    first_eval_row = pq.read_table(eval_dirs[0] / "trajectories.parquet").column("row_id")[0].as_py()
    pages = {
        "runs": ("/runs", None),
        "episodes": (f"/episodes?source={run}", "/episodes"),
        "episode": (f"/episode?source={gold}&file=0&row=1", "/episode"),
        "evaluations": ("/evals", None),
        "eval-episode": (f"/episode?source={ev}&row_id={first_eval_row}", "/episode"),
    }
    browser.get_log("browser")  # drop anything logged before
    for name, (fragment, path) in pages.items():
        show(browser, served, fragment, path)
        assert browser.find_element(By.ID, "app").text.strip(), f"{name}: empty page"
        assert severe_console_messages(browser) == [], f"{name}: console errors"
        browser.save_screenshot(str(ARTIFACTS / f"{name}.png"))
        assert (ARTIFACTS / f"{name}.png").stat().st_size > 10_000


def test_charts_plot_the_runs_numbers_with_smoothing_and_log_scale(served, browser, trained_run):
    from learner.metrics import read_metrics

    rows = [r for r in read_metrics(trained_run) if isinstance(r.get("kl_teacher"), (int, float))]
    assert len(rows) == 3
    show(browser, served, "/runs")
    label = f"{trained_run.name}: kl_teacher"

    def points():
        line = browser.find_element(By.CSS_SELECTOR, f'polyline[data-label="{label}"]')
        return [tuple(map(float, p.split(","))) for p in line.get_attribute("points").split()]

    raw = points()
    assert len(raw) == len(rows)
    # Pixel height orders the points exactly as the metric values do (higher value = smaller y).
    by_value = sorted(range(len(rows)), key=lambda i: rows[i]["kl_teacher"])
    by_pixel = sorted(range(len(rows)), key=lambda i: -raw[i][1])
    assert by_value == by_pixel
    assert [p[0] for p in raw] == sorted(p[0] for p in raw)

    before = renders(browser)
    browser.execute_script("const s = document.getElementById('smoothing'); s.value = '0.9';"
                           "s.dispatchEvent(new Event('change'))")
    wait_render(browser, before)
    smoothed = points()
    assert smoothed[0] == raw[0] and smoothed[1:] != raw[1:], "debiased EMA keeps the first point and moves the rest"
    before = renders(browser)
    browser.find_element(By.ID, "log-scale").click()
    wait_render(browser, before)
    assert browser.find_element(By.ID, "log-scale").is_selected() and len(points()) == len(rows)
    for reset in ("const s = document.getElementById('smoothing'); s.value = '0'; s.dispatchEvent(new Event('change'))",
                  "document.getElementById('log-scale').click()"):
        before = renders(browser)
        browser.execute_script(reset)
        wait_render(browser, before)


def test_a_point_opens_the_episodes_of_its_step(served, browser, trained_run):
    show(browser, served, "/runs")
    panel = browser.find_element(By.CSS_SELECTOR, '[data-panel="Accuracy"] svg')
    before = renders(browser)
    # click the right edge of the plot: the last step
    browser.execute_script("""const svg = arguments[0], box = svg.getBoundingClientRect();
        svg.dispatchEvent(new MouseEvent('click', {clientX: box.right - 12, clientY: box.top + 40, bubbles: true}));""", panel)
    wait_render(browser, before)
    assert "step=3" in browser.current_url and "part=train" in browser.current_url
    table = pq.read_table(trained_run / "trajectories" / "step_000003.parquet", columns=["sample_id"])
    count = browser.find_element(By.ID, "episode-count").text
    assert count.startswith(f"{table.num_rows} of "), count


def test_episode_page_shows_the_parquet_record(served, browser, gold_run):
    from envs import registry
    from learner.metrics import read_samples

    samples, _ = read_samples(gold_run / "trajectories" / "step_000001.parquet")
    tasks = registry.get_tasks("ward", None)
    gold = source_id(served, gold_run)
    checked = 0
    for row, sample in enumerate(samples):
        record = sample.episode
        calls = [c for t in record.turns for c in t.tool_calls]
        show(browser, served, f"/episode?source={gold}&file=0&row={row}", "/episode")
        shown = browser.find_elements(By.CSS_SELECTOR, ".call")
        assert [e.get_attribute("data-tool") for e in shown] == [c.name for c in calls]
        for element, call in zip(shown, calls):
            assert json.loads(element.find_element(By.CSS_SELECTOR, "pre.args").text) == call.arguments
        assert browser.find_element(By.ID, "submitted").text == (record.submitted_answer or "–")
        assert browser.find_element(By.ID, "gold").text == {t.id: t for t in tasks}[sample.task_id].correct_answer
        components = {e.get_attribute("data-component"): float(e.text)
                      for e in browser.find_elements(By.CSS_SELECTOR, "[data-component]")}
        assert components["total"] == pytest.approx(sample.reward_components["total"], abs=1e-3)
        checked += len(calls)
    assert checked >= 3, "the gold replays made too few tool calls to check"


def test_ttopd_episode_shows_the_hint_and_per_turn_kl(served, browser, trained_run):
    table = pq.read_table(trained_run / "trajectories" / "step_000001.parquet")
    row = next(i for i, h in enumerate(table.column("teacher_hint").to_pylist()) if h in ("reinforcing", "corrective"))
    sample = table.slice(row, 1).to_pylist()[0]
    show(browser, served, f"/episode?source={source_id(served, trained_run)}&file=0&row={row}", "/episode")
    hint = browser.find_element(By.ID, "hint").text
    assert sample["teacher_hint"] in hint and "Privileged" in hint
    turns = json.loads(sample["turns"])
    expected = []
    for span in turns:
        diffs = [sample["sampling_logprobs"][p] - sample["teacher_logprobs"][p]
                 for p in range(span["start"], span["end"]) if sample["loss_mask"][p]]
        expected.append(sum(diffs) / len(diffs))
    shown = [float(e.get_attribute("data-kl")) for e in browser.find_elements(By.CSS_SELECTOR, "[data-kl]")]
    assert shown == pytest.approx(expected, rel=1e-6, abs=1e-9)


def test_filters_select_what_the_parquet_files_hold(served, browser, trained_run):
    run = source_id(served, trained_run)
    validation = [pq.read_table(p, columns=["correct"]) for p in sorted((trained_run / "validation").glob("*.parquet"))]
    train = [pq.read_table(p, columns=["correct", "reward"]) for p in sorted((trained_run / "trajectories").glob("*.parquet"))]
    total = sum(t.num_rows for t in validation + train)
    show(browser, served, f"/episodes?source={run}", "/episodes")
    assert browser.find_element(By.ID, "episode-count").text.startswith(f"{total} of {total}")
    before = renders(browser)
    Select(browser.find_element(By.ID, "f-part")).select_by_value("validation")
    wait_render(browser, before)
    n_val = sum(t.num_rows for t in validation)
    assert browser.find_element(By.ID, "episode-count").text.startswith(f"{n_val} of {total}")
    assert {e.text for e in browser.find_elements(By.CSS_SELECTOR, "#episodes td:first-child")} == {"validation"}
    show(browser, served, f"/episodes?source={run}&part=train&reward_min=0.3", "/episodes")
    expected = sum(sum(1 for r in t.column("reward").to_pylist() if r >= 0.3) for t in train)
    assert browser.find_element(By.ID, "episode-count").text.startswith(f"{expected} of {total}")


def test_evaluation_page_shows_the_reports_numbers_and_the_comparison(served, browser, eval_dirs):
    from evals.compare import compare_dirs
    from evals.report import summarise_results

    show(browser, served, "/evals")
    for folder in eval_dirs:
        summary = summarise_results(folder, n_resamples=2_000)
        ward = next(b for b in summary["benchmarks"] if b["benchmark"] == "ward")
        primary = next(m for m in ward["metrics"] if m["metric"] == ward["primary"])
        cell = browser.find_element(By.CSS_SELECTOR, f'[data-eval="{source_id(served, folder)}"] tr[data-benchmark="ward"] td[data-value]')
        assert float(cell.get_attribute("data-value")) == pytest.approx(primary["estimate"])
        assert f"[{primary['low']:.3f}, {primary['high']:.3f}]" in cell.text
    comparison, _ = compare_dirs(eval_dirs[0], eval_dirs[1], n_resamples=2_000)
    row = browser.find_element(By.CSS_SELECTOR, '#compare tr[data-benchmark="ward"]').text
    difference = comparison["benchmarks"][0]["difference"]
    assert f"{difference['estimate']:.3f} [{difference['low']:.3f}, {difference['high']:.3f}]" in row
    # each number links to its episodes
    before = renders(browser)
    browser.find_element(By.CSS_SELECTOR,
                         f'[data-eval="{source_id(served, eval_dirs[0])}"] tr[data-benchmark="ward"] td[data-value] a').click()
    wait_render(browser, before)
    rows = pq.read_table(eval_dirs[0] / "results.parquet", columns=["benchmark"]).num_rows
    assert browser.find_element(By.ID, "episode-count").text.startswith(f"{rows} of {rows}")
