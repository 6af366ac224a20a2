"""Drives calib's web app in headless Chromium (selenium + chromedriver), as a user would.

    python3 web_ui.py workflow URL DATA.csv SCREENSHOTS_DIR OUT.json
    python3 web_ui.py broken URL BROKEN.csv OUT.json
    python3 web_ui.py login URL TOKEN_FILE DATA.csv OUT.json
    python3 web_ui.py fmu URL MODEL.fmu RECORD.csv DROPPED.fmu OUT.json
    python3 web_ui.py experiments URL SWING.csv DRIVEN.csv SCREENSHOTS_DIR OUT.json
    python3 web_ui.py workbench URL DATA.csv RUNS_TABLE.png OUT.json
    python3 web_ui.py discovery URL RECORD.csv SCREENSHOT.png OUT.json   (web_discovery.py)

`workflow`: the seed's whole job on the Furuta record: the Model tab (furuta, its start
angle, a 40 s simulation), the Measurement tab (upload, plots), the Calibration tab (map the
two angles, free the two frictions, three methods x four starts, run, read the calibrated
values off the page), the Diagnosis tab (run it, read the verdict); a screenshot of each
tab. `broken`: upload a CSV that does not parse and read the message the page shows.
`login`: a coordinator with a token: the page asks for it, refuses a wrong one, and once
signed in simulates, uploads and draws the measurement's plots; what scripts can see of it.
`fmu`: an FMU dropped on the Model tab (DROPPED.fmu, a drop event carrying the file), then
the Reference FMU VanDerPol as the user's own model: chosen with the Model tab's file picker, its parameters and outputs listed, simulated and plotted; its record uploaded; mu
freed on the Calibration tab and calibrated; the calibrated value read off the page.
`experiments`: two Furuta records fitted together: the free swing uploaded on the Measurement
tab, the driven record added as a second experiment on the Calibration tab (its own upload,
window, start angle, and its torque column mapped to the model's armTorque input); the
calibrated values, the status and the plots' captions read off the page; screenshots of the
mapping and of the result. On the Model tab, the model simulated with its armTorque input
driven by the uploaded torque column: the captions of the plots, and whether the arm angle
differs from the undriven simulation.
`workbench`: a small Furuta campaign started on the page, the page reloaded while it runs
and after it finished (the tab, the form, the dataset, the progress plot, the runs and the
result read each time); the table of runs read and sorted, a picture of it; "use these
values" and "edit and re-run" with a narrower bound, and what the server keeps of both
campaigns.
Writes what it read as JSON to OUT.json; exits non-zero when a step fails.
"""

import base64
import json
import os
import shutil
import sys

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support import expected_conditions as EC
from selenium.webdriver.support.ui import Select, WebDriverWait

# The campaign of examples/furuta.toml, typed into the page.
THETA0 = "0.5235987755983"
SENSITIVITY_SAMPLES = "128"  # base samples of the sensitivity asked on the Calibration tab
LONG = 900  # seconds a campaign or a diagnosis may take on a loaded machine


def browser():
    options = webdriver.ChromeOptions()
    for binary in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(binary)
        if path:
            options.binary_location = path
            break
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--window-size=1366,900", "--force-device-scale-factor=1", "--lang=en-US"):
        options.add_argument(arg)
    driver_path = shutil.which("chromedriver")
    service = Service(executable_path=driver_path) if driver_path else Service()
    driver = webdriver.Chrome(options=options, service=service)
    driver.set_window_size(1366, 900)
    return driver


def wait(driver, seconds=60):
    return WebDriverWait(driver, seconds, poll_frequency=0.2)


def by_id(driver, id_):
    return driver.find_element(By.ID, id_)


def type_into(driver, id_, text):
    field = by_id(driver, id_)
    field.clear()
    field.send_keys(text)
    field.send_keys(Keys.TAB)  # fires `change`


def tab(driver, name):
    by_id(driver, f"tab-{name}").click()
    wait(driver).until(EC.visibility_of_element_located((By.ID, f"panel-{name}")))


def screenshot(driver, path):
    """The whole page, at a laptop's width."""
    height = driver.execute_script(
        "return Math.max(document.body.scrollHeight, document.documentElement.scrollHeight)")
    driver.set_window_size(1366, max(900, min(int(height) + 40, 6000)))
    driver.execute_script("window.scrollTo(0, 0)")
    driver.save_screenshot(path)
    driver.set_window_size(1366, 900)


def no_error(driver, id_):
    box = by_id(driver, id_)
    if box.is_displayed():
        raise SystemExit(f"{id_}: {box.text}")


def upload(driver, path, time_column):
    tab(driver, "measurement")
    type_into(driver, "measurement-time", time_column)
    by_id(driver, "measurement-file").send_keys(os.path.abspath(path))
    by_id(driver, "upload").click()


# The Calibration tab's fields for the campaign of examples/furuta.toml, by id.
FURUTA_FORM = {
    "measured-armJoint.phi": "arm_angle_rad",
    "measured-pendulumJoint.phi": "pendulum_angle_rad",
    "free-armFriction": True, "nominal-armFriction": 0.012, "min-armFriction": 1e-4,
    "max-armFriction": 0.9, "pscale-armFriction": "log10",
    "free-pendulumFriction": True, "nominal-pendulumFriction": 0.002,
    "min-pendulumFriction": 1e-4, "max-pendulumFriction": 0.9,
    "pscale-pendulumFriction": "log10",
    "method:nelder-mead": True, "method:powell": True, "method:differential-evolution": True,
    "campaign-name": "furuta", "window-start": 0, "window-stop": 40, "starts": 4,
    "max-evaluations": 2500, "seed": 1,
}


def campaign_form_holds(driver):
    """Whether the form holds every field of FURUTA_FORM."""
    state = form_state(driver)
    return all(state.get(k) == v for k, v in FURUTA_FORM.items())


def fill_campaign_form(driver):
    """Types FURUTA_FORM into the Calibration tab (boxes ticked, never toggled off); False,
    so that a wait calls it again until campaign_form_holds."""
    state = form_state(driver)
    for key, value in FURUTA_FORM.items():
        if state.get(key) == value:
            continue
        if key.startswith("method:"):
            driver.find_element(By.CSS_SELECTOR, f'input[name="method"][value="{key[7:]}"]').click()
        elif value is True:
            by_id(driver, key).click()
        elif key.startswith(("measured-", "pscale-")):
            Select(by_id(driver, key)).select_by_value(value)
        else:
            type_into(driver, key, str(value))
    return False



def workflow(url, data, shots, out):
    driver = browser()
    try:
        driver.get(url)
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        Select(by_id(driver, "model-select")).select_by_value("furuta")
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))

        # Model: the record's start angle, 40 s, both angles plotted.
        type_into(driver, "value-theta0", THETA0)
        type_into(driver, "model-stop", "40")
        by_id(driver, "simulate").click()
        wait(driver).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#model-plots figure")) >= 2
                           or by_id(d, "model-error").is_displayed())
        no_error(driver, "model-error")
        screenshot(driver, os.path.join(shots, "model.png"))

        # Measurement: upload the record, its columns plotted.
        upload(driver, data, "time_s")
        wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                           or by_id(d, "measurement-error").is_displayed())
        no_error(driver, "measurement-error")
        columns = [e.get_attribute("value") for e in
                   driver.find_elements(By.CSS_SELECTOR, 'input[name="measured-column"]')]
        wait(driver).until(lambda d: d.execute_script(
            "return [...document.querySelectorAll('#measurement-plots img')]"
            ".every(i => i.complete && i.naturalWidth > 0)"))
        screenshot(driver, os.path.join(shots, "measurement.png"))

        # Calibration: the campaign of examples/furuta.toml, filled in until the form holds
        # all of it (a field re-drawn while it was typed into is typed into again).
        tab(driver, "calibration")
        wait(driver).until(lambda d: campaign_form_holds(d) or fill_campaign_form(d))
        # Before calibrating: the sensitivity of this campaign.
        Select(by_id(driver, "sensitivity-method")).select_by_value("")
        type_into(driver, "sensitivity-samples", SENSITIVITY_SAMPLES)
        by_id(driver, "analyse").click()
        wait(driver, LONG).until(lambda d: by_id(d, "sensitivity-conclusion").is_displayed()
                                 or by_id(d, "sensitivity-error").is_displayed())
        no_error(driver, "sensitivity-error")
        sensitivity = {
            "conclusion": by_id(driver, "sensitivity-conclusion").text,
            "status": by_id(driver, "sensitivity-status").text,
            "rows": [[c.text for c in row.find_elements(By.CSS_SELECTOR, "th, td")]
                     for row in driver.find_elements(By.CSS_SELECTOR, "#sensitivity-table tbody tr")],
            "plots": [f.text for f in driver.find_elements(By.CSS_SELECTOR, "#sensitivity-plots figcaption")],
        }
        by_id(driver, "sensitivity").location_once_scrolled_into_view
        screenshot(driver, os.path.join(shots, "sensitivity.png"))

        by_id(driver, "start").click()
        live = set()

        def done(d):
            status = by_id(d, "calibration-status").text
            if "running" in status and d.find_elements(By.CSS_SELECTOR, "#progress-plot svg"):
                live.add(status)
            return by_id(d, "result").is_displayed() or by_id(d, "calibration-error").is_displayed()

        wait(driver, LONG).until(done)
        no_error(driver, "calibration-error")
        spec = json.loads(get_campaign(driver, campaign_id(driver))).get("campaign")
        calibrated = {}
        for row in driver.find_elements(By.CSS_SELECTOR, "#result-parameters tbody tr"):
            cell = row.find_element(By.CSS_SELECTOR, "td.calibrated")
            calibrated[row.get_attribute("data-parameter")] = {
                "value": cell.get_attribute("data-value"),
                "text": cell.text,
                "bound": row.find_element(By.CSS_SELECTOR, "td.flag").text,
            }
        plots = [f.text for f in driver.find_elements(By.CSS_SELECTOR, "#result-plots figcaption")]
        status = by_id(driver, "calibration-status").text
        progress_runs = driver.execute_script(
            "return document.querySelectorAll('#progress-plot svg path, #progress-plot svg polyline').length")
        toml_link = by_id(driver, "download-toml").get_attribute("href")
        listed = [r.text for r in driver.find_elements(By.CSS_SELECTOR, "#campaigns tbody tr")]
        screenshot(driver, os.path.join(shots, "calibration.png"))

        # After the calibration: which values the data pin down.
        by_id(driver, "profile").click()
        wait(driver, LONG).until(lambda d: by_id(d, "profile-conclusion").is_displayed()
                                 or by_id(d, "profile-error").is_displayed())
        no_error(driver, "profile-error")
        profiles = {
            "conclusion": by_id(driver, "profile-conclusion").text,
            "rows": {row.get_attribute("data-parameter"): {
                "low": row.find_element(By.CSS_SELECTOR, "td.profile").get_attribute("data-low"),
                "high": row.find_element(By.CSS_SELECTOR, "td.profile").get_attribute("data-high"),
                "flag": row.find_element(By.CSS_SELECTOR, "td.flag").text,
            } for row in driver.find_elements(By.CSS_SELECTOR, "#profile-table tbody tr")},
            "plots": [f.text for f in driver.find_elements(By.CSS_SELECTOR, "#profile-plots figcaption")],
        }
        by_id(driver, "profiles").location_once_scrolled_into_view
        screenshot(driver, os.path.join(shots, "profiles.png"))

        # Diagnosis of the finished campaign.
        tab(driver, "diagnosis")
        wait(driver).until(lambda d: Select(by_id(d, "diagnosis-campaign")).options)
        by_id(driver, "diagnose").click()
        wait(driver, LONG).until(lambda d: by_id(d, "verdict").is_displayed()
                                 or by_id(d, "diagnosis-error").is_displayed())
        no_error(driver, "diagnosis-error")
        verdict = by_id(driver, "verdict").text
        candidates = [r.text for r in driver.find_elements(By.CSS_SELECTOR, "#candidates tbody tr")]
        diagnosis_plots = [f.text for f in driver.find_elements(By.CSS_SELECTOR, "#diagnosis-plots figcaption")]
        screenshot(driver, os.path.join(shots, "diagnosis.png"))

        # Back to the Calibration tab by keyboard; reopen the campaign from the store's list.
        by_id(driver, "tab-diagnosis").send_keys(Keys.ARROW_LEFT)
        wait(driver).until(EC.visibility_of_element_located((By.ID, "panel-calibration")))
        driver.execute_script("document.getElementById('result-parameters').tBodies[0].replaceChildren()")
        driver.find_element(By.CSS_SELECTOR, "#campaigns tbody tr button").send_keys(Keys.ENTER)
        wait(driver).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#result-parameters td.calibrated"))
        reopened = {row.get_attribute("data-parameter"):
                    row.find_element(By.CSS_SELECTOR, "td.calibrated").get_attribute("data-value")
                    for row in driver.find_elements(By.CSS_SELECTOR, "#result-parameters tbody tr")}

        with open(out, "w") as f:
            json.dump({
                "columns": columns,
                "calibrated": calibrated,
                "spec": spec,
                "status": status,
                "live_statuses": len(live),
                "progress_plot_lines": progress_runs,
                "plots": plots,
                "toml_link": toml_link,
                "campaigns_listed": listed,
                "verdict": verdict,
                "candidates": candidates,
                "diagnosis_plots": diagnosis_plots,
                "reopened": reopened,
                "sensitivity": sensitivity,
                "profiles": profiles,
            }, f, indent=2)
    finally:
        driver.quit()


def broken(url, data, out):
    driver = browser()
    try:
        driver.get(url)
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        # To the Measurement tab by keyboard, as someone without a mouse would.
        by_id(driver, "tab-model").send_keys(Keys.ARROW_RIGHT)
        wait(driver).until(EC.visibility_of_element_located((By.ID, "panel-measurement")))
        focused = driver.switch_to.active_element.get_attribute("id")
        upload(driver, data, "time_s")
        wait(driver).until(lambda d: by_id(d, "measurement-error").is_displayed()
                           or "samples" in by_id(d, "measurement-status").text)
        with open(out, "w") as f:
            json.dump({
                "error": by_id(driver, "measurement-error").text,
                "status": by_id(driver, "measurement-status").text,
                "focused_after_arrow": focused,
            }, f, indent=2)
    finally:
        driver.quit()


def login(url, token_file, data, out):
    with open(token_file) as f:
        token = f.read().strip()
    driver = browser()
    try:
        driver.get(url)
        wait(driver).until(EC.visibility_of_element_located((By.ID, "login-token")))
        asked = {
            "tabs_hidden": not by_id(driver, "tab-model").is_displayed(),
            "models_before": len(driver.find_elements(By.CSS_SELECTOR, "#model-select option")),
        }
        type_into(driver, "login-token", "not-the-token")
        by_id(driver, "login-submit").click()
        wait(driver).until(lambda d: by_id(d, "login-error").is_displayed())
        wrong = by_id(driver, "login-error").text
        by_id(driver, "login-token").clear()
        by_id(driver, "login-token").send_keys(token)
        by_id(driver, "login-submit").click()
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        login_hidden = not by_id(driver, "login").is_displayed()
        type_into(driver, "model-stop", "2")
        by_id(driver, "simulate").click()
        wait(driver).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#model-plots figure")) >= 1
                           or by_id(d, "model-error").is_displayed())
        no_error(driver, "model-error")
        upload(driver, data, "time_s")
        wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                           or by_id(d, "measurement-error").is_displayed())
        no_error(driver, "measurement-error")
        # The plots are <img> elements: the browser fetches them with the session cookie.
        wait(driver).until(lambda d: d.execute_script(
            "const i = [...document.querySelectorAll('#measurement-plots img')];"
            "return i.length > 0 && i.every(x => x.complete && x.naturalWidth > 0)"))
        visible = driver.execute_script(
            "return document.cookie + JSON.stringify(sessionStorage) + JSON.stringify(localStorage)")
        with open(out, "w") as f:
            json.dump({
                **asked,
                "wrong": wrong,
                "login_hidden": login_hidden,
                "model_plots": len(driver.find_elements(By.CSS_SELECTOR, "#model-plots figure")),
                "measurement_status": by_id(driver, "measurement-status").text,
                "measurement_plots": len(driver.find_elements(By.CSS_SELECTOR, "#measurement-plots img")),
                "token_visible_to_scripts": token in visible,
                "script_storage": visible,
            }, f, indent=2)
    finally:
        driver.quit()


DROP = """
const [name, data] = arguments;
const bytes = Uint8Array.from(atob(data), (c) => c.charCodeAt(0));
const transfer = new DataTransfer();
transfer.items.add(new File([bytes], name, { type: "application/octet-stream" }));
const zone = document.getElementById("fmu-drop");
zone.dispatchEvent(new DragEvent("dragover", { dataTransfer: transfer, bubbles: true, cancelable: true }));
zone.dispatchEvent(new DragEvent("drop", { dataTransfer: transfer, bubbles: true, cancelable: true }));
"""


def fmu(url, model, record, dropped, out):
    driver = browser()
    try:
        driver.get(url)
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        # An FMU dropped on the Model tab, as a file dragged from the desktop arrives.
        with open(dropped, "rb") as f:
            data = base64.b64encode(f.read()).decode()
        driver.execute_script(DROP, os.path.basename(dropped), data)
        wait(driver).until(lambda d: "parameters" in by_id(d, "fmu-status").text
                           or by_id(d, "model-error").is_displayed())
        no_error(driver, "model-error")
        dropped_status = by_id(driver, "fmu-status").text
        dropped_chosen = Select(by_id(driver, "model-select")).first_selected_option.get_attribute("value")
        # Model: the FMU, through the file picker.
        by_id(driver, "fmu-file").send_keys(os.path.abspath(model))
        wait(driver).until(lambda d: "VanDerPol" in by_id(d, "fmu-status").text
                           or by_id(d, "model-error").is_displayed())
        wait(driver).until(lambda d: "parameters" in by_id(d, "fmu-status").text
                           or by_id(d, "model-error").is_displayed())
        no_error(driver, "model-error")
        status = by_id(driver, "fmu-status").text
        chosen = Select(by_id(driver, "model-select")).first_selected_option.get_attribute("value")
        parameters = [r.find_element(By.CSS_SELECTOR, "th").text
                      for r in driver.find_elements(By.CSS_SELECTOR, "#model-parameters tbody tr")]
        outputs = [i.get_attribute("value")
                   for i in driver.find_elements(By.CSS_SELECTOR, 'input[name="model-output"]')]
        type_into(driver, "value-mu", "1.7")
        type_into(driver, "model-stop", "20")
        type_into(driver, "model-step", "0.05")
        by_id(driver, "simulate").click()
        wait(driver).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#model-plots figure")) >= 2
                           or by_id(d, "model-error").is_displayed())
        no_error(driver, "model-error")
        simulated = by_id(driver, "model-status").text
        model_plots = [f.text for f in driver.find_elements(By.CSS_SELECTOR, "#model-plots figcaption")]
        # Back to the FMU's default mu, so that the campaign fixes nothing else.
        type_into(driver, "value-mu", "1")

        upload(driver, record, "time")
        wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                           or by_id(d, "measurement-error").is_displayed())
        no_error(driver, "measurement-error")

        # Calibration: the campaign of examples/vanderpol.toml.
        tab(driver, "calibration")
        for output in ("x0", "x1"):
            Select(by_id(driver, f"measured-{output}")).select_by_value(output)
        by_id(driver, "free-mu").click()
        type_into(driver, "nominal-mu", "1.0")
        type_into(driver, "min-mu", "0.2")
        type_into(driver, "max-mu", "3.0")
        type_into(driver, "campaign-name", "vanderpol")
        type_into(driver, "window-start", "0")
        type_into(driver, "window-stop", "20")
        type_into(driver, "starts", "2")
        type_into(driver, "max-evaluations", "200")
        type_into(driver, "seed", "0")
        by_id(driver, "start").click()
        wait(driver, LONG).until(lambda d: by_id(d, "result").is_displayed()
                                 or by_id(d, "calibration-error").is_displayed())
        no_error(driver, "calibration-error")
        calibrated = {}
        for row in driver.find_elements(By.CSS_SELECTOR, "#result-parameters tbody tr"):
            cell = row.find_element(By.CSS_SELECTOR, "td.calibrated")
            calibrated[row.get_attribute("data-parameter")] = cell.get_attribute("data-value")
        with open(out, "w") as f:
            json.dump({
                "dropped_status": dropped_status,
                "dropped_chosen": dropped_chosen,
                "fmu_status": status,
                "chosen": chosen,
                "parameters": parameters,
                "outputs": outputs,
                "simulated": simulated,
                "model_plots": model_plots,
                "calibrated": calibrated,
                "calibration_status": by_id(driver, "calibration-status").text,
            }, f, indent=2)
    finally:
        driver.quit()


def press(driver, id_):
    """Click a button, scrolled to the middle of the window (clear of the sticky header)."""
    button = by_id(driver, id_)
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", button)
    button.click()


def experiments(url, swing, driven, shots, out):
    driver = browser()
    try:
        driver.get(url)
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        Select(by_id(driver, "model-select")).select_by_value("furuta")
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        type_into(driver, "value-theta0", THETA0)

        upload(driver, swing, "time_s")
        wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                           or by_id(d, "measurement-error").is_displayed())
        no_error(driver, "measurement-error")

        tab(driver, "calibration")
        Select(by_id(driver, "measured-armJoint.phi")).select_by_value("arm_angle_rad")
        Select(by_id(driver, "measured-pendulumJoint.phi")).select_by_value("pendulum_angle_rad")
        # The free swing drives nothing: its record has no torque column.
        first_input = [o.get_attribute("value") for o in
                       Select(by_id(driver, "input-armTorque")).options]
        for name, nominal in (("armFriction", "0.012"), ("pendulumFriction", "0.002")):
            press(driver, f"free-{name}")
            type_into(driver, f"nominal-{name}", nominal)
            type_into(driver, f"min-{name}", "0")
            type_into(driver, f"max-{name}", "0.9")
        type_into(driver, "campaign-name", "pair")
        type_into(driver, "window-start", "0")
        type_into(driver, "window-stop", "10")
        type_into(driver, "starts", "2")
        type_into(driver, "max-evaluations", "150")
        type_into(driver, "seed", "1")

        # The driven record: a second experiment with its own upload, start angle and input.
        press(driver, "add-experiment")
        type_into(driver, "experiment-name", "swing")
        type_into(driver, "x0-name", "driven")
        type_into(driver, "x0-time", "time_s")
        by_id(driver, "x0-file").send_keys(os.path.abspath(driven))
        press(driver, "x0-upload")
        wait(driver).until(lambda d: "samples" in by_id(d, "x0-status").text
                           or by_id(d, "x0-error").is_displayed())
        no_error(driver, "x0-error")
        Select(by_id(driver, "x0-input-armTorque")).select_by_value("motor_torque_Nm")
        Select(by_id(driver, "x0-interp-armTorque")).select_by_value("linear")
        type_into(driver, "x0-window-start", "0")
        type_into(driver, "x0-window-stop", "10")
        press(driver, "x0-add-fixed")
        Select(by_id(driver, "x0-fixed-0-name")).select_by_value("theta0")
        type_into(driver, "x0-fixed-0-value", "0.2")
        by_id(driver, "experiments").location_once_scrolled_into_view
        screenshot(driver, os.path.join(shots, "experiments.png"))

        # The Model tab simulates the model driven by the uploaded torque column.
        tab(driver, "model")
        type_into(driver, "model-stop", "10")

        def simulated():
            driver.execute_script("document.getElementById('model-status').textContent = ''")
            press(driver, "simulate")
            wait(driver).until(lambda d: "simulated" in by_id(d, "model-status").text
                               or by_id(d, "model-error").is_displayed())
            no_error(driver, "model-error")
            return {f.find_element(By.CSS_SELECTOR, "figcaption").text:
                    f.find_element(By.CSS_SELECTOR, "svg").get_attribute("outerHTML")
                    for f in driver.find_elements(By.CSS_SELECTOR, "#model-plots figure")}

        undriven = simulated()
        drive = Select(by_id(driver, "drive-armTorque"))
        drive.select_by_visible_text("motor_torque_Nm (driven.csv)")
        driven_plots = simulated()
        arm = "armJoint.phi simulated over 10 s"
        def arm_plot(plots):
            return next(v for k, v in plots.items() if k.startswith(arm))
        model = {
            "undriven": list(undriven),
            "driven": list(driven_plots),
            "arm_differs": arm_plot(undriven) != arm_plot(driven_plots),
            # The second simulation keeps the first, dashed underneath.
            "overlaid_previous": "previous: " in arm_plot(driven_plots)
                                 and "previous: " not in arm_plot(undriven),
        }
        screenshot(driver, os.path.join(shots, "model-driven.png"))
        drive.select_by_index(0)
        tab(driver, "calibration")

        press(driver, "start")
        wait(driver, LONG).until(lambda d: by_id(d, "result").is_displayed()
                                 or by_id(d, "calibration-error").is_displayed())
        no_error(driver, "calibration-error")
        calibrated = {}
        for row in driver.find_elements(By.CSS_SELECTOR, "#result-parameters tbody tr"):
            cell = row.find_element(By.CSS_SELECTOR, "td.calibrated")
            calibrated[row.get_attribute("data-parameter")] = cell.get_attribute("data-value")
        groups = {}
        for section in driver.find_elements(By.CSS_SELECTOR, "#result-plots section.experiment-plots"):
            heading = section.find_element(By.CSS_SELECTOR, "h4").text
            groups[heading] = [f.text for f in section.find_elements(By.CSS_SELECTOR, "figcaption")]
        plots = [f.text for f in driver.find_elements(By.CSS_SELECTOR, "#result-plots figcaption")]
        status = by_id(driver, "calibration-status").text
        # The result alone: the calibrated values, then each experiment's plots.
        driver.set_window_size(1366, 6000)
        by_id(driver, "result").screenshot(os.path.join(shots, "experiments-result.png"))
        driver.set_window_size(1366, 900)
        with open(out, "w") as f:
            json.dump({
                "first_input_choices": first_input,
                "model": model,
                "calibrated": calibrated,
                "groups": groups,
                "plots": plots,
                "status": status,
            }, f, indent=2)
    finally:
        driver.quit()


def form_state(driver):
    """Every field of the Model and Calibration tabs that a campaign's spec sets, by id:
    numbers as numbers, boxes as booleans."""
    return driver.execute_script("""
        const out = {};
        for (const f of document.querySelectorAll(
            '#panel-model input, #panel-model select, #panel-calibration input, #panel-calibration select')) {
          if (!f.id || f.type === 'file' || f.closest('#sensitivity')) continue;
          out[f.id] = f.type === 'checkbox' ? f.checked
            : f.type === 'number' ? (f.value === '' ? null : Number(f.value)) : f.value;
        }
        for (const m of document.querySelectorAll('input[name="method"]')) out['method:' + m.value] = m.checked;
        return out;""")


def page_state(driver):
    """What a reload must find again: the tab, the URL, the form, the dataset, the status,
    the progress plot, the runs and the result."""
    selected = driver.find_element(By.CSS_SELECTOR, '[role="tab"][aria-selected="true"]').get_attribute("id")
    return {
        "tab": selected,
        "hash": driver.execute_script("return location.hash"),
        "form": form_state(driver),
        "dataset": by_id(driver, "measurement-status").text,
        "columns": [e.get_attribute("value") for e in
                    driver.find_elements(By.CSS_SELECTOR, 'input[name="measured-column"]')],
        "progress_plots": len(driver.find_elements(By.CSS_SELECTOR, "#progress-plot svg")),
        "runs": runs_table(driver),
        "calibrated": {row.get_attribute("data-parameter"):
                       row.find_element(By.CSS_SELECTOR, "td.calibrated").get_attribute("data-value")
                       for row in driver.find_elements(By.CSS_SELECTOR, "#result-parameters tbody tr")},
        "result_shown": by_id(driver, "result").is_displayed(),
        "summary": by_id(driver, "result-summary").text,
    }


def runs_table(driver):
    """The table of runs as shown, row by row: label, method, start, evaluations, rounds,
    objective (its exact value) and each parameter's exact value. Read in one script, so a
    table redrawn by the campaign's progress is read whole, before or after."""
    rows = driver.execute_script("""
        return [...document.querySelectorAll('#runs-table tbody tr')].map((row) => {
          const cells = [...row.querySelectorAll('th, td')];
          const text = (i) => cells[i].textContent.trim();
          return {
            label: text(0), method: text(1), start: Number(text(2)),
            evaluations: Number(text(3)), rounds: Number(text(4)),
            iterations: text(5), termination: text(6),
            objective: cells[7].getAttribute('data-value'),
            at_best: text(8) === 'at the best',
            parameters: Object.fromEntries([...row.querySelectorAll('td[data-parameter]')]
              .map((c) => [c.getAttribute('data-parameter'), c.getAttribute('data-value')])),
          };
        });
    """)
    return rows


def get_campaign(driver, id_):
    """GetCampaign over the page's own origin, as the page calls it."""
    return driver.execute_async_script("""
        const done = arguments[arguments.length - 1];
        fetch('/api/v1/GetCampaign', {method: 'POST', headers: {'Content-Type': 'application/json'},
              body: JSON.stringify({id: arguments[0]})})
          .then(r => r.text()).then(done, e => done(String(e)));""", id_)


def sort_by(driver, key):
    """Choose the heading of the runs table's column `key`, clear of the sticky header."""
    button = driver.find_element(By.CSS_SELECTOR, f'#runs-table th[data-key="{key}"] button')
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", button)
    button.click()


def campaign_id(driver):
    hash_ = driver.execute_script("return location.hash")
    parts = hash_.split("/")
    return parts[parts.index("campaign") + 1] if "campaign" in parts else ""


def workbench(url, data, shot, out):
    """Reloads mid-campaign and after it, the runs table, edit and re-run, use the values."""
    driver = browser()
    driver.set_script_timeout(60)
    try:
        driver.get(url)
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        Select(by_id(driver, "model-select")).select_by_value("furuta")
        wait(driver).until(lambda d: d.find_elements(By.ID, "value-theta0"))
        type_into(driver, "value-theta0", THETA0)
        type_into(driver, "model-stop", "40")
        upload(driver, data, "time_s")
        wait(driver).until(lambda d: "samples" in by_id(d, "measurement-status").text
                           or by_id(d, "measurement-error").is_displayed())
        no_error(driver, "measurement-error")

        tab(driver, "calibration")
        Select(by_id(driver, "measured-armJoint.phi")).select_by_value("arm_angle_rad")
        Select(by_id(driver, "measured-pendulumJoint.phi")).select_by_value("pendulum_angle_rad")
        for name, nominal in (("armFriction", "0.012"), ("pendulumFriction", "0.002")):
            press(driver, f"free-{name}")
            type_into(driver, f"nominal-{name}", nominal)
            type_into(driver, f"min-{name}", "0.0001")
            type_into(driver, f"max-{name}", "0.9")
            Select(by_id(driver, f"pscale-{name}")).select_by_value("log10")
        driver.find_element(By.CSS_SELECTOR, 'input[name="method"][value="powell"]').click()
        # Differential evolution too: thousands of evaluations, so that the campaign still
        # runs when the page is reloaded, however fast the machine.
        driver.find_element(By.CSS_SELECTOR, 'input[name="method"][value="differential-evolution"]').click()
        type_into(driver, "campaign-name", "bench")
        type_into(driver, "window-start", "0")
        type_into(driver, "window-stop", "40")
        type_into(driver, "starts", "2")
        type_into(driver, "max-evaluations", "2500")
        type_into(driver, "seed", "1")
        submitted = form_state(driver)

        # Started, then reloaded while it runs: the same tab, form, dataset, and the
        # progress kept by the server. The page is reloaded as soon as the server has a
        # first point of progress (the nominal point's, a few milliseconds in), not once
        # the page has drawn it: however fast the machine, thousands of evaluations remain.
        press(driver, "start")
        wait(driver, LONG).until(lambda d: campaign_id(d) or by_id(d, "calibration-error").is_displayed())
        no_error(driver, "calibration-error")
        first = campaign_id(driver)
        progressed = []
        wait(driver, LONG).until(lambda d: progressed.append(json.loads(get_campaign(d, first)))
                                 or progressed[-1]["history"])
        before_reload = progressed[-1]
        mid = {"running_when_reloaded": before_reload["phase"] == "CAMPAIGN_PHASE_RUNNING",
               "history_before": len(before_reload["history"]),
               "evaluations_before": before_reload["evaluations"]}
        driver.refresh()
        wait(driver, LONG).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#progress-plot svg")
                                 and "bench" in by_id(d, "calibration-status").text)
        mid["after"] = page_state(driver)
        state_after = json.loads(get_campaign(driver, first))
        mid["history_after"] = len(state_after["history"])
        mid["evaluations_after"] = state_after["evaluations"]

        # Finished, then reloaded again: the same again, with the result.
        wait(driver, LONG).until(lambda d: by_id(d, "result").is_displayed()
                                 or by_id(d, "calibration-error").is_displayed())
        no_error(driver, "calibration-error")
        finished = page_state(driver)
        driver.refresh()
        wait(driver, LONG).until(lambda d: by_id(d, "result").is_displayed()
                                 and d.find_elements(By.CSS_SELECTOR, "#progress-plot svg")
                                 and d.find_elements(By.CSS_SELECTOR, "#runs-table tbody tr"))
        reloaded = page_state(driver)
        state = json.loads(get_campaign(driver, first))

        # The table of runs, sorted by a column's heading.
        sort_by(driver, "evaluations")
        by_evaluations = [r["evaluations"] for r in runs_table(driver)]
        sort_by(driver, "evaluations")
        by_evaluations_down = [r["evaluations"] for r in runs_table(driver)]
        sort_state = driver.find_element(By.CSS_SELECTOR, '#runs-table th[data-key="evaluations"]').get_attribute("aria-sort")
        sort_by(driver, "objective")
        by_objective = [float(r["objective"]) for r in runs_table(driver)]
        table = by_id(driver, "runs")
        driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", table)
        table.screenshot(shot)

        # Use these values: the calibrated values become the Model tab's.
        press(driver, "use-values")
        wait(driver).until(EC.visibility_of_element_located((By.ID, "panel-model")))
        model_values = {n: by_id(driver, f"value-{n}").get_attribute("value")
                        for n in ("armFriction", "pendulumFriction")}
        model_tab_hash = driver.execute_script("return location.hash")

        # Edit and re-run: the form holds the spec; a narrower bound makes a new campaign.
        tab(driver, "calibration")
        press(driver, "edit-rerun")
        wait(driver).until(lambda d: "holds the spec" in by_id(d, "calibration-status").text)
        type_into(driver, "max-armFriction", "0.5")
        press(driver, "start")
        wait(driver, LONG).until(lambda d: campaign_id(d) not in ("", first))
        second = campaign_id(driver)
        wait(driver, LONG).until(lambda d: (by_id(d, "result").is_displayed()
                                            and "finished" in by_id(d, "calibration-status").text)
                                 or by_id(d, "calibration-error").is_displayed())
        no_error(driver, "calibration-error")
        rerun = json.loads(get_campaign(driver, second))
        first_again = json.loads(get_campaign(driver, first))

        with open(out, "w") as f:
            json.dump({
                "submitted_form": submitted,
                "first": first,
                "mid": mid,
                "finished": finished,
                "reloaded": reloaded,
                "state": {k: state[k] for k in ("phase", "evaluations", "simulated", "from_store",
                                                "result_json", "campaign", "history", "runs")},
                "by_evaluations": by_evaluations,
                "by_evaluations_down": by_evaluations_down,
                "sort_state": sort_state,
                "by_objective": by_objective,
                "model_values": model_values,
                "model_tab_hash": model_tab_hash,
                "second": second,
                "rerun": {k: rerun[k] for k in ("phase", "campaign", "result_json")},
                "first_again": {k: first_again[k] for k in ("phase", "campaign")},
            }, f, indent=2)
    finally:
        driver.quit()


if __name__ == "__main__":
    mode, args = sys.argv[1], sys.argv[2:]
    if mode == "workflow":
        workflow(*args)
    elif mode == "broken":
        broken(*args)
    elif mode == "login":
        login(*args)
    elif mode == "fmu":
        fmu(*args)
    elif mode == "experiments":
        experiments(*args)
    elif mode == "workbench":
        workbench(*args)
    elif mode == "discovery":
        from web_discovery import discovery  # noqa: E402  (the sibling script, which imports this one)
        discovery(*args)
    else:
        raise SystemExit(f"unknown mode {mode}")
