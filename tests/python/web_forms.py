"""Drives calib's web app in headless Chromium: forms that say what will happen, and
campaigns compared side by side (helpers shared with web_ui.py).

    python3 web_forms.py forms URL DATA.csv BROKEN.csv OUT.json
    python3 web_forms.py compare URL DATA.csv SHOT.png OUT.json

`forms`: the Model tab's stop time for each model; DATA.csv uploaded without a time
column typed (the columns offered, the time column guessed); the outputs mapped on the
Calibration tab; BROKEN.csv uploaded (the error, and what stays of the good dataset and its
mappings); no method ticked and Start pressed (the message next to the methods, the error
box, the status line, whether a campaign started); a window past the end of the data typed
(the message next to the window's stop before any Start); the window put right (the
messages left).
`compare`: two campaigns on DATA.csv (one parameter free, then two), run to their end;
both ticked in the list and compared: the table's header, objectives and parameters read
off the page, beside each campaign's result.json as GetCampaign answers it; the plots'
rows; a screenshot of the comparison in SHOT.png.
Writes what it read as JSON to OUT.json; exits non-zero when a step fails.
"""

import json
import os
import sys

from selenium.common.exceptions import StaleElementReferenceException
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select

from web_ui import LONG, browser, by_id, no_error, press, tab, type_into, wait


def problems(driver):
    """Every problem shown next to a field: {element id: text}."""
    return driver.execute_script(
        "return Object.fromEntries([...document.querySelectorAll('.problem')]"
        ".map(p => [p.id.replace(/^problem-/, ''), p.textContent]))")


def campaigns_listed(driver):
    press(driver, "refresh-campaigns")
    return driver.execute_script(
        "return (async () => ((await (await fetch('/api/v1/ListCampaigns', {method: 'POST', "
        "headers: {'Content-Type': 'application/json'}, body: '{}'})).json()).campaigns || []).length)()")


def open_page(driver, url):
    driver.get(url)
    wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))


def upload_file(driver, path, time_column=""):
    tab(driver, "measurement")
    type_into(driver, "measurement-time", time_column)
    by_id(driver, "measurement-file").send_keys(os.path.abspath(path))
    press(driver, "upload")


def map_outputs(driver):
    tab(driver, "calibration")
    Select(by_id(driver, "measured-armJoint.phi")).select_by_value("arm_angle_rad")
    Select(by_id(driver, "measured-pendulumJoint.phi")).select_by_value("pendulum_angle_rad")


def forms(url, data, broken, out):
    driver = browser()
    report = {}
    try:
        open_page(driver, url)
        stops = {}
        models = [o.get_attribute("value") for o in
                  Select(by_id(driver, "model-select")).options]
        for name in models:
            Select(by_id(driver, "model-select")).select_by_value(name)
            wait(driver).until(lambda d: d.find_element(By.ID, "model-description").text.startswith(name + " "))
            stops[name] = by_id(driver, "model-stop").get_attribute("value")
        report["stop_times"] = stops
        Select(by_id(driver, "model-select")).select_by_value("furuta")
        wait(driver).until(lambda d: d.find_element(By.ID, "model-description").text.startswith("furuta "))

        # No time column typed: the file's columns offered, its time column guessed.
        upload_file(driver, data)
        wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                           or by_id(d, "measurement-error").is_displayed())
        no_error(driver, "measurement-error")
        choice = Select(by_id(driver, "measurement-time-column"))
        report["time_choice_shown"] = by_id(driver, "measurement-time-choice").is_displayed()
        report["time_offered"] = [o.get_attribute("value") for o in choice.options]
        report["time_chosen"] = choice.first_selected_option.get_attribute("value")
        report["time_note"] = by_id(driver, "measurement-time-note").text
        report["status"] = by_id(driver, "measurement-status").text

        map_outputs(driver)
        for name in ("armFriction", "pendulumFriction"):
            press(driver, f"free-{name}")

        # A file that does not parse: the good dataset and its mappings stay.
        upload_file(driver, broken, "time_s")
        wait(driver).until(lambda d: by_id(d, "measurement-error").is_displayed())
        report["broken_error"] = by_id(driver, "measurement-error").text
        report["status_after_broken"] = by_id(driver, "measurement-status").text
        report["columns_after_broken"] = [e.get_attribute("value") for e in driver.find_elements(
            By.CSS_SELECTOR, 'input[name="measured-column"]')]
        tab(driver, "calibration")
        report["context_after_broken"] = by_id(driver, "calibration-context").text
        report["mapping_after_broken"] = {
            o: [Select(by_id(driver, f"measured-{o}")).first_selected_option.get_attribute("value"),
                by_id(driver, f"fit-{o}").is_selected()]
            for o in ("armJoint.phi", "pendulumJoint.phi", "armJoint.w")}

        # No method: the message next to the methods, nothing started.
        for box in driver.find_elements(By.CSS_SELECTOR, 'input[name="method"]'):
            if box.is_selected():
                driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", box)
                box.click()
        type_into(driver, "max-evaluations", "40")
        press(driver, "start")
        wait(driver).until(lambda d: by_id(d, "calibration-error").is_displayed())
        wait(driver).until(lambda d: "methods" in problems(d))
        report["no_method_problems"] = problems(driver)
        report["no_method_error"] = by_id(driver, "calibration-error").text
        report["no_method_status"] = by_id(driver, "calibration-status").text
        report["no_method_next_to"] = driver.execute_script(
            "const p = document.getElementById('problem-methods');"
            "return p.previousElementSibling && p.previousElementSibling.id")
        report["started_without_method"] = campaigns_listed(driver)

        # A method, and a window past the data's end: said before any Start.
        method = driver.find_element(By.CSS_SELECTOR, 'input[name="method"][value="nelder-mead"]')
        driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", method)
        method.click()
        type_into(driver, "window-stop", "50")
        wait(driver).until(lambda d: "window-stop" in problems(d))
        report["late_window_problems"] = problems(driver)
        report["late_window_invalid"] = by_id(driver, "window-stop").get_attribute("aria-invalid")
        report["late_window_status"] = by_id(driver, "calibration-status").text
        report["started_with_late_window"] = campaigns_listed(driver)

        # Put right: no message left.
        type_into(driver, "window-stop", "40")
        wait(driver).until(lambda d: not problems(d))
        report["problems_after_fix"] = problems(driver)
    finally:
        driver.quit()
    with open(out, "w") as f:
        json.dump(report, f, indent=1)


def run_campaign(driver, name, free, evaluations):
    tab(driver, "calibration")
    type_into(driver, "campaign-name", name)
    for p in ("armFriction", "pendulumFriction"):
        box = by_id(driver, f"free-{p}")
        if box.is_selected() != (p in free):
            press(driver, f"free-{p}")
    type_into(driver, "max-evaluations", str(evaluations))
    press(driver, "start")
    wait(driver, LONG).until(lambda d: by_id(d, "calibration-status").text.startswith(f"{name}: finished")
                             or by_id(d, "calibration-error").is_displayed())
    no_error(driver, "calibration-error")
    wait(driver).until(lambda d: not by_id(d, "result").get_attribute("hidden"))


def tick_every_compare_box(driver):
    """Tick every campaign's compare box; true once all are ticked. The list is redrawn
    when a campaign's state changes (ticks kept), so a box found may be gone by the click:
    then look again."""
    try:
        for box in driver.find_elements(By.CSS_SELECTOR, 'input[name="compare"]'):
            if not box.is_selected():
                driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", box)
                box.click()
        boxes = driver.find_elements(By.CSS_SELECTOR, 'input[name="compare"]')
        return len(boxes) >= 2 and all(b.is_selected() for b in boxes)
    except StaleElementReferenceException:
        return False


def compare(url, data, shot, out):
    driver = browser()
    report = {}
    try:
        open_page(driver, url)
        Select(by_id(driver, "model-select")).select_by_value("furuta")
        wait(driver).until(lambda d: d.find_element(By.ID, "model-description").text.startswith("furuta "))
        type_into(driver, "value-theta0", "0.5235987755983")
        upload_file(driver, data)
        wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                           or by_id(d, "measurement-error").is_displayed())
        no_error(driver, "measurement-error")
        map_outputs(driver)
        run_campaign(driver, "arm-only", ["armFriction"], 60)
        run_campaign(driver, "both", ["armFriction", "pendulumFriction"], 120)

        press(driver, "refresh-campaigns")
        wait(driver).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, 'input[name="compare"]')) >= 2)
        wait(driver).until(tick_every_compare_box)
        press(driver, "compare")
        wait(driver).until(lambda d: by_id(d, "comparison").is_displayed())
        no_error(driver, "compare-error")
        wait(driver).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#comparison-plots .compare-row"))
        wait(driver).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#comparison-overlays .overlay-row svg")) >= 2)
        read = driver.execute_script("""return (async () => {
            const heads = [...document.querySelectorAll('#comparison-table thead th[data-campaign]')];
            const ids = heads.map(h => h.dataset.campaign);
            const cell = (sel) => [...document.querySelectorAll(sel)];
            const results = {};
            for (const id of ids) {
              const s = await (await fetch('/api/v1/GetCampaign', {method: 'POST',
                headers: {'Content-Type': 'application/json'}, body: JSON.stringify({id})})).json();
              results[id] = JSON.parse(s.result_json);
            }
            return {
              headers: heads.map(h => h.textContent),
              ids,
              objectives: Object.fromEntries(cell('td.objective').map(c => [c.dataset.campaign, c.dataset.value])),
              parameters: cell('td.parameter').map(c => ({campaign: c.dataset.campaign, parameter: c.dataset.parameter,
                value: c.dataset.value, low: c.dataset.low, high: c.dataset.high, text: c.textContent})),
              not_calibrated: cell('#comparison-table td').filter(c => c.textContent === 'not calibrated').length,
              rows: cell('#comparison-table tbody th').map(h => h.textContent),
              overlays: cell('#comparison-overlays .overlay-row').map(r => ({output: r.dataset.output,
                legend: [...r.querySelectorAll('svg text')].map(t => t.textContent).join('|')})),
              plot_rows: cell('#comparison-plots .compare-row').map(r => ({plot: r.dataset.plot,
                figures: r.querySelectorAll('figure svg').length,
                captions: [...r.querySelectorAll('figcaption')].map(f => f.textContent)})),
              results: Object.fromEntries(Object.entries(results).map(([id, r]) => [id, {
                name: r.campaign, objective: String(r.best.objective),
                parameters: Object.fromEntries(Object.entries(r.best.parameters).map(([k, v]) => [k, String(v)])),
                spread: r.spread.parameters}])),
            };
        })();""")
        report.update(read)
        # The sticky header would cover the section's top in an element screenshot.
        driver.execute_script("document.querySelector('header').style.position = 'static';"
                              "document.getElementById('comparison').scrollIntoView()")
        height = driver.execute_script("return document.getElementById('comparison').scrollHeight")
        driver.set_window_size(1366, max(900, min(int(height) + 200, 4000)))
        by_id(driver, "comparison").screenshot(shot)
    finally:
        driver.quit()
    with open(out, "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    mode, args = sys.argv[1], sys.argv[2:]
    if mode == "forms":
        forms(*args)
    elif mode == "compare":
        compare(*args)
    else:
        raise SystemExit(f"unknown mode {mode}")
